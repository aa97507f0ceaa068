"""Model errors name files as the client knows them, never by a server path (issue 32, 9).

A client names a model in the server's model directories, or sends one as text
with its files. When the model is broken (an include or mesh missing, a mesh or
texture that does not decode, a URDF that does not parse), the error's detail
names the file by its path relative to the model directory, or as the sent model
names it: never the model directory's absolute path, a temporary directory or the
server's working directory. Each case runs through :func:`load_robot_model` and
through a real ``poise serve --model-dir``, started in a working directory that
holds the model directory, under the temporary directory.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import pytest

import controller_server
from clients.server_process import ServerProcess
from controller_server.errors import ModelError, ServerFault, wire_code
from controller_server.files import without_server_paths
from controller_server.models import load_robot_model
from controller_server.models import robot_model as robot_model_module
from controller_server.models.description import DescriptionError
from protocol import ErrorCode
from protocol.messages import Error, Hello
from tests.controller_server.test_hello_limits import box_stl, urdf_with_foot_meshes
from tests.e2e.test_server_safety import Peer

MODELS = Path(__file__).resolve().parents[1] / "models"
VENDOR = MODELS / "vendor_humanoid"
VENDOR_ROBOT = (VENDOR / "robot.xml").read_text()
GARBAGE = bytes(range(256)) * 4
"""Not an STL nor a PNG: MuJoCo's decoders refuse it."""
BAD_PNG = b"\x89PNG\r\n\x1a\n" + GARBAGE
"""A PNG signature and garbage after it."""


@dataclass(frozen=True)
class Case:
    """A broken model: how a client asks for it, and the name its error must give.

    Attributes:
        model: Path in the model directory (``None``: sent as text).
        names: What the detail must name: the file as the client knows it.
        text: For a sent model, its text.
        assets: For a sent model, its files.
        model_format: For a sent model, ``mjcf`` or ``urdf``.
    """

    model: str | None
    names: str
    text: str | None = None
    assets: dict[str, bytes] = field(default_factory=dict)
    model_format: str = "mjcf"

    def hello_fields(self) -> dict:
        if self.model is not None:
            return {"model": self.model}
        return {
            "model_text": self.text,
            "model_assets": self.assets,
            "model_format": self.model_format,
        }


def with_texture(robot_xml: str, file: str) -> str:
    """The vendor robot with a 2D texture read from ``file`` on a material."""
    return robot_xml.replace(
        '<mesh name="foot" file="foot.stl"/>',
        f'<mesh name="foot" file="foot.stl"/><texture name="grid" type="2d" file="{file}"/>'
        '<material name="gridded" texture="grid"/>',
    )


def write_models(directory: Path) -> dict[str, Case]:
    """Broken models under ``directory`` (the model directory), by case id."""
    robot = directory / "robot"
    shutil.copytree(VENDOR, robot)
    scene = (VENDOR / "scene.xml").read_text()
    robot_xml = (VENDOR / "robot.xml").read_text()
    (robot / "missing_include.xml").write_text(
        scene.replace('file="robot.xml"', 'file="parts/robot_v2.xml"')
    )
    (robot / "missing_mesh.xml").write_text(
        robot_xml.replace('file="foot.stl"', 'file="foot_v2.stl"')
    )
    (robot / "assets" / "garbage.stl").write_bytes(GARBAGE)
    (robot / "corrupt_mesh.xml").write_text(
        robot_xml.replace('file="foot.stl"', 'file="garbage.stl"')
    )
    (robot / "includes_corrupt_mesh.xml").write_text(
        scene.replace('file="robot.xml"', 'file="corrupt_mesh.xml"')
    )
    (robot / "textures").mkdir()
    (robot / "textures" / "bad.png").write_bytes(BAD_PNG)
    (robot / "corrupt_texture.xml").write_text(with_texture(robot_xml, "textures/bad.png"))
    # The model's author wrote an absolute path: the client sees it relative.
    absolute = robot / "parts" / "nope.xml"
    (robot / "absolute_include.xml").write_text(
        scene.replace('file="robot.xml"', f'file="{absolute}"')
    )
    # A mesh that is a symlink out of the model directories.
    outside = directory.parent / "outside"
    outside.mkdir()
    (outside / "foot.stl").write_bytes(box_stl((0.2, 0.1, 0.05)))
    (robot / "assets" / "linked.stl").symlink_to(outside / "foot.stl")
    (robot / "linked_mesh.xml").write_text(
        robot_xml.replace('file="foot.stl"', 'file="linked.stl"')
    )
    urdf = directory / "urdf"
    (urdf / "meshes").mkdir(parents=True)
    (urdf / "meshes" / "garbage.stl").write_bytes(GARBAGE)
    (urdf / "missing_mesh.urdf").write_text(urdf_with_foot_meshes("meshes/foot.stl"))
    (urdf / "corrupt_mesh.urdf").write_text(urdf_with_foot_meshes("meshes/garbage.stl"))
    two_roots = (MODELS / "urdf_humanoid" / "robot.urdf").read_text()
    (urdf / "broken.urdf").write_text(two_roots.replace("</robot>", '<link name="x"/></robot>'))
    (urdf / "truncated.urdf").write_text(two_roots[: len(two_roots) // 2])
    foot = (VENDOR / "assets" / "foot.stl").read_bytes()
    return {
        "missing include": Case("robot/missing_include.xml", "'parts/robot_v2.xml'"),
        "missing mesh": Case("robot/missing_mesh.xml", "'assets/foot_v2.stl'"),
        "corrupt mesh": Case("robot/corrupt_mesh.xml", "'assets/garbage.stl'"),
        "corrupt mesh, included": Case("robot/includes_corrupt_mesh.xml", "'assets/garbage.stl'"),
        "corrupt texture": Case("robot/corrupt_texture.xml", "'textures/bad.png'"),
        "absolute include": Case("robot/absolute_include.xml", "'robot/parts/nope.xml'"),
        "mesh linked outside": Case("robot/linked_mesh.xml", "'assets/linked.stl'"),
        "unparsable urdf": Case("urdf/broken.urdf", "'broken'"),
        "truncated urdf": Case("urdf/truncated.urdf", "not valid XML"),
        "urdf mesh missing": Case("urdf/missing_mesh.urdf", "'meshes/foot.stl'"),
        "urdf mesh corrupt": Case("urdf/corrupt_mesh.urdf", "'meshes/garbage.stl'"),
        "sent, include missing": Case(
            None, "'parts/robot_v2.xml'", text=scene.replace("robot.xml", "parts/robot_v2.xml")
        ),
        "sent, corrupt mesh": Case(
            None,
            "'assets/garbage.stl'",
            text=robot_xml.replace('file="foot.stl"', 'file="garbage.stl"'),
            assets={"assets/garbage.stl": GARBAGE},
        ),
        "sent, corrupt texture": Case(
            None,
            "'textures/bad.png'",
            text=with_texture(robot_xml, "textures/bad.png"),
            assets={"assets/foot.stl": foot, "textures/bad.png": BAD_PNG},
        ),
        "sent, urdf mesh corrupt": Case(
            None,
            "'meshes/garbage.stl'",
            text=urdf_with_foot_meshes("meshes/garbage.stl"),
            assets={"meshes/garbage.stl": GARBAGE},
            model_format="urdf",
        ),
    }


def _case_ids() -> list[str]:
    with tempfile.TemporaryDirectory() as scratch:
        (Path(scratch) / "models").mkdir()
        return list(write_models(Path(scratch) / "models"))


CASE_IDS = _case_ids()


def server_paths(*directories: Path) -> list[str]:
    """Strings no detail may hold: the directories, resolved too, and the temporary directory."""
    found = {"/tmp", tempfile.gettempdir(), str(Path(tempfile.gettempdir()).resolve())}
    for directory in directories:
        found |= {str(directory), str(directory.resolve())}
    return sorted(found)


def assert_names_only_the_clients_file(detail: str, case: Case, forbidden: list[str]) -> None:
    for path in forbidden:
        assert path not in detail, detail
    assert case.names in detail, detail


@pytest.fixture
def server_layout(tmp_path, allow_model_dir, monkeypatch) -> tuple[Path, dict[str, Case]]:
    """A working directory under the temporary one, holding the model directory."""
    models = tmp_path / "models"
    models.mkdir()
    cases = write_models(models)
    allow_model_dir(models)
    monkeypatch.chdir(tmp_path)
    return models, cases


@pytest.mark.parametrize("case_id", CASE_IDS)
def test_a_broken_models_error_names_no_server_path(server_layout, case_id):
    models, cases = server_layout
    case = cases[case_id]
    with pytest.raises(ServerFault) as info:
        load_robot_model(**case.hello_fields())
    assert wire_code(info.value) in (ErrorCode.MODEL_NOT_FOUND, ErrorCode.MODEL_INVALID)
    detail = info.value.detail
    assert_names_only_the_clients_file(detail, case, server_paths(models, Path.cwd()))
    assert str(info.value) == f"{info.value.field}: {detail}"


def test_every_model_error_goes_through_the_rewrite(server_layout, monkeypatch):
    """MuJoCo's own messages quote absolute paths: the loader rewrites whatever it raises."""
    models, _ = server_layout
    cwd, temp = Path.cwd(), Path(tempfile.gettempdir())
    message = (
        f"Error opening file '{models}/robot/meshes/foot.stl'; also {cwd}/scratch.xml, "
        f"{temp}/poise-assets-x1y2/0123abcd and {models}"
    )

    def failing(*args, **kwargs):
        raise DescriptionError(message)

    monkeypatch.setattr(robot_model_module, "describe", failing)
    # Text no other test loads, so that no cached model answers instead.
    (models / "robot" / "fresh.xml").write_text(f"<!-- {models} -->\n{VENDOR_ROBOT}")
    with pytest.raises(ModelError) as info:
        load_robot_model("robot/fresh.xml")
    detail = info.value.detail
    for path in server_paths(models, cwd):
        assert path not in detail, detail
    assert "'robot/meshes/foot.stl'" in detail
    assert "<temp dir>/poise-assets-x1y2/0123abcd" in detail
    assert detail.endswith(" and <model dir>")


def test_the_rewrite_keeps_what_is_not_a_server_directory(tmp_path, allow_model_dir):
    models = tmp_path / "models"
    models.mkdir()
    allow_model_dir(models)
    install = str(Path(controller_server.__file__).resolve().parent.parent)
    assert without_server_paths(f"'{models}/a/b.stl'") == "'a/b.stl'"
    beside = without_server_paths(f"{models}x/a.stl")  # not inside the model directory
    assert beside.endswith("/modelsx/a.stl") and str(models) not in beside
    in_install = without_server_paths(f"{install}/controller_server/x.py")
    assert in_install.endswith(">/controller_server/x.py") and install not in in_install
    for kept in ("/tmpfiles/a.stl", "/srv/tmp/a.stl", "meshes/foot.stl", "package://p/a.stl"):
        assert without_server_paths(kept) == kept
    home = os.path.expanduser("~")
    if home not in ("/", "") and not tempfile.gettempdir().startswith(home):
        assert without_server_paths(f"{home}/robots/a.xml") == "~/robots/a.xml"


# --- through a real server ---------------------------------------------------------------


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """``poise serve --model-dir models`` started in ``cwd``, which holds ``models``."""
    cwd = tmp_path_factory.mktemp("server_cwd")
    models = cwd / "models"
    models.mkdir()
    cases = write_models(models)
    with contextlib.chdir(cwd):
        process = ServerProcess(extra_args=["--workers", "1", "--model-dir", str(models)]).start()
    try:
        yield process, models, cwd, cases
    finally:
        process.stop()


@pytest.mark.e2e
def test_a_server_names_no_server_path_in_broken_model_errors(served):
    process, models, cwd, cases = served
    forbidden = server_paths(models, cwd)
    with Peer(process.endpoint) as peer:
        for case_id, case in cases.items():
            reply = peer.ask(Hello(controller="tracking", **case.hello_fields()))
            assert isinstance(reply, Error), (case_id, reply)
            assert reply.code in (ErrorCode.MODEL_NOT_FOUND, ErrorCode.MODEL_INVALID), (
                case_id,
                reply,
            )
            assert_names_only_the_clients_file(reply.detail, case, forbidden)
            assert not re.search(r"poise_asset_\d", reply.detail), reply.detail
