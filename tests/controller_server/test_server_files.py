"""Which server files a client may name: refusals all look alike, allowed files load.

A client must not learn whether a server path exists, nor read what a file
holds, through the model or clip it names: every refused name gets the same
detail (the name aside), with no server path in it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pinocchio as pin
import pytest
from hypothesis import given
from hypothesis import strategies as st

import controller_server
from controller_server import files
from controller_server.errors import InvalidParams, ModelError, ServerFault, wire_code
from controller_server.features.motion_clip import CLIP_FILES, load_motion_clip
from controller_server.files import display_name, set_model_directories
from controller_server.models import (
    BUILTIN_MODELS,
    DEFAULT_MODEL_CACHE_SIZE,
    MODEL_FILES,
    RobotModel,
    load_robot_model,
    set_model_cache_size,
)
from protocol.errors import ErrorCode
from tests.controller_server.test_model_loading import TINY_MJCF, TINY_URDF

SECRET = "planted-secret-5f1c9"
INSTALL_DIR = str(Path(controller_server.__file__).resolve().parent)


@pytest.fixture(scope="module")
def thesis() -> RobotModel:
    return load_robot_model("thesis_humanoid")


def clip_document(robot: RobotModel) -> dict:
    neutral = pin.neutral(robot.model)[7:].tolist()
    return {
        "name": "still",
        "joint_names": [joint.name for joint in robot.joints],
        "time_s": [0.0, 0.1, 0.2],
        "joint_position": [neutral, neutral, neutral],
    }


@pytest.fixture
def layout(tmp_path: Path, allow_model_dir, thesis) -> dict[str, Path]:
    """An allowed directory with a model and a clip; beside it, files it must not reach.

    ``allowed/``: ``tiny.xml``, ``still.json``, ``sub/tiny.xml``, a directory
    ``folder.xml/`` and ``folder.json/``, a FIFO ``fifo.xml``, symlinks
    ``escape.*`` to the outside files, ``inside.*`` to the allowed ones and a
    loop ``loop.xml``. ``outside/``: ``robot.xml``, ``clip.json`` (same
    content as the allowed ones) and ``secret.xml``.
    """
    allowed, outside = tmp_path / "allowed", tmp_path / "outside"
    (allowed / "sub").mkdir(parents=True)
    outside.mkdir()
    clip_text = json.dumps(clip_document(thesis))
    for directory in (allowed, allowed / "sub"):
        (directory / "tiny.xml").write_text(TINY_MJCF)
    (allowed / "still.json").write_text(clip_text)
    (outside / "robot.xml").write_text(TINY_MJCF)
    (outside / "clip.json").write_text(clip_text)
    (outside / "secret.xml").write_text(SECRET)
    (allowed / "folder.xml").mkdir()
    (allowed / "folder.json").mkdir()
    os.mkfifo(allowed / "fifo.xml")
    (allowed / "escape.xml").symlink_to(outside / "robot.xml")
    (allowed / "escape.json").symlink_to(outside / "clip.json")
    (allowed / "inside.xml").symlink_to(allowed / "tiny.xml")
    (allowed / "inside.json").symlink_to(allowed / "still.json")
    (allowed / "loop.xml").symlink_to(allowed / "loop.xml")
    allow_model_dir(allowed)
    return {"allowed": allowed, "outside": outside}


def refused_names(layout: dict[str, Path], suffix: str) -> list[str]:
    """Names that must all be refused, whatever the reason."""
    allowed, outside = layout["allowed"], layout["outside"]
    outside_file = outside / ("robot.xml" if suffix == ".xml" else "clip.json")
    return [
        "/etc/passwd",
        "/etc/shadow",
        "/proc/1/environ",
        "/proc/self/environ",
        "/etc",
        str(allowed / f"missing{suffix}"),
        f"missing{suffix}",
        "n" * 300,
        "n" * 5000,
        "",
        "nul\0byte",
        f"../outside/{outside_file.name}",  # escapes through `..`
        str(allowed / ".." / "outside" / outside_file.name),
        str(outside_file),  # exists, outside
        str(outside / "secret.xml"),
        f"escape{suffix}",  # symlink inside, pointing out
        str(allowed / f"escape{suffix}"),
        f"folder{suffix}",  # a directory
        "fifo.xml",  # not a regular file
        "loop.xml",  # symlink loop
        "sub",
        ".",
        INSTALL_DIR + "/models/data/thesis_humanoid.xml",  # a built-in by path
    ]


def assert_refusals_look_alike(errors: dict[str, ServerFault]) -> None:
    """One detail for every name, with no server path besides the name the client sent."""
    templates = {
        name: error.detail.replace(display_name(name), "NAME") for name, error in errors.items()
    }
    assert len(set(templates.values())) == 1, templates
    template = next(iter(templates.values()))
    assert template.startswith("NAME is not a built-in")
    assert "/" not in template
    for name, error in errors.items():
        assert INSTALL_DIR not in error.detail.replace(display_name(name), "")
        assert SECRET not in error.detail


def test_refused_model_names_are_model_not_found_with_one_message(layout):
    errors = {}
    for name in refused_names(layout, ".xml"):
        with pytest.raises(ModelError) as info:
            load_robot_model(name)
        assert (wire_code(info.value), info.value.field) == (ErrorCode.MODEL_NOT_FOUND, "model"), (
            name
        )
        errors[name] = info.value
    assert_refusals_look_alike(errors)


def test_refused_clip_names_are_invalid_params_with_one_message(layout, thesis):
    errors = {}
    for name in refused_names(layout, ".json"):
        with pytest.raises(InvalidParams) as info:
            load_motion_clip(name, thesis)
        assert (wire_code(info.value), info.value.field) == (
            ErrorCode.INVALID_PARAMS,
            "params.clip",
        )
        errors[name] = info.value
    assert_refusals_look_alike(errors)


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files whatever their mode")
def test_unreadable_file_is_refused_like_a_missing_one(layout):
    path = layout["allowed"] / "locked.xml"
    path.write_text(TINY_MJCF)
    path.chmod(0)
    errors = {}
    for name in ("locked.xml", "missing.xml"):
        with pytest.raises(ModelError) as info:
            load_robot_model(name)
        errors[name] = info.value
    assert_refusals_look_alike(errors)


def test_names_are_shown_cut_to_100_characters(layout):
    with pytest.raises(ModelError) as info:
        load_robot_model("n" * 300)
    assert "n" * 100 + "…'" in info.value.detail
    assert "n" * 101 not in info.value.detail


def test_without_model_directories_only_builtins_load(tmp_path, allow_model_dir):
    allow_model_dir()
    assert files.model_directories() == ()
    (tmp_path / "tiny.xml").write_text(TINY_MJCF)
    with pytest.raises(ModelError) as info:
        load_robot_model(str(tmp_path / "tiny.xml"))
    assert wire_code(info.value) == ErrorCode.MODEL_NOT_FOUND
    assert load_robot_model("dino_biped").name == "dino_biped"


def test_model_in_an_allowed_directory_loads_by_path_and_by_name(layout):
    allowed = layout["allowed"]
    by_text = load_robot_model(model_text=TINY_MJCF)
    for name in ("tiny.xml", str(allowed / "tiny.xml"), "sub/tiny.xml", "sub/../tiny.xml"):
        robot = load_robot_model(name)
        assert robot.name == "tiny", name
        assert robot.model_hash == by_text.model_hash
    # A symlink is followed, then checked: one to a file inside is fine, named by the link.
    assert load_robot_model("inside.xml").name == "inside"


def test_allowed_directory_reached_through_a_symlink(tmp_path, layout, allow_model_dir):
    link = tmp_path / "link_to_allowed"
    link.symlink_to(layout["allowed"])
    allow_model_dir(link)
    assert files.model_directories() == (layout["allowed"].resolve(),)
    assert load_robot_model(str(link / "tiny.xml")).name == "tiny"
    assert load_robot_model(str(layout["allowed"] / "tiny.xml")).name == "tiny"


def test_urdf_file_is_read_as_urdf(layout):
    from tests.controller_server.test_model_loading import URDF_FOOT

    (layout["allowed"] / "tiny.urdf").write_text(TINY_URDF)
    robot = load_robot_model("tiny.urdf", contacts=[URDF_FOOT])
    assert robot.name == "tiny" and [joint.name for joint in robot.joints] == ["hip", "slide"]


def test_clip_in_an_allowed_directory_loads_by_path_and_by_name(layout, thesis):
    allowed = layout["allowed"]
    for name in ("still.json", str(allowed / "still.json"), allowed / "still.json", "inside.json"):
        clip = load_motion_clip(name, thesis)
        assert clip.name == "still" and clip.num_frames == 3
    assert load_motion_clip("stand_sway", thesis).num_frames == 101


def test_set_model_directories_checks_its_arguments(tmp_path, allow_model_dir):
    with pytest.raises(NotADirectoryError):
        set_model_directories([tmp_path / "missing"])
    (tmp_path / "file").write_text("")
    with pytest.raises(NotADirectoryError):
        set_model_directories([tmp_path / "file"])
    with pytest.raises(ValueError, match="max_file_bytes"):
        set_model_directories([tmp_path], max_file_bytes=0)
    allow_model_dir(tmp_path, tmp_path, str(tmp_path))
    assert files.model_directories() == (tmp_path.resolve(),)


# --- file contents ---------------------------------------------------------------------------


def test_clip_joint_names_are_not_echoed(layout, thesis):
    expected = [joint.name for joint in thesis.joints]
    cases = {
        "first": ([SECRET, *expected[1:]], 0),
        "middle": ([*expected[:5], SECRET, *expected[6:]], 5),
        "missing": (expected[:-1], len(expected) - 1),
    }
    for name, (joint_names, index) in cases.items():
        document = {**clip_document(thesis), "joint_names": joint_names}
        (layout["allowed"] / f"{name}.json").write_text(json.dumps(document))
        with pytest.raises(InvalidParams) as info:
            load_motion_clip(f"{name}.json", thesis)
        detail = info.value.detail
        assert SECRET not in detail
        assert f"index {index}" in detail and repr(expected[index]) in detail, detail
        assert "joint_names" in detail and str(layout["allowed"]) not in detail
    document = {**clip_document(thesis), "joint_names": [*expected, SECRET]}
    (layout["allowed"] / "extra.json").write_text(json.dumps(document))
    with pytest.raises(InvalidParams) as info:
        load_motion_clip("extra.json", thesis)
    assert SECRET not in info.value.detail


@pytest.mark.parametrize(
    "text",
    [SECRET, f'{{"{SECRET}": 1', f'["{SECRET}"]', f'{{"joint_names": "{SECRET}"}}', "[" * 100_000],
    ids=["not_json", "truncated", "list", "no_times", "deep"],
)
def test_bad_clip_content_is_not_echoed(layout, thesis, text):
    (layout["allowed"] / "bad.json").write_text(text)
    with pytest.raises(InvalidParams) as info:
        load_motion_clip("bad.json", thesis)
    assert info.value.field == "params.clip"
    assert SECRET not in info.value.detail
    assert str(layout["allowed"]) not in info.value.detail


@pytest.mark.parametrize(
    ("file_name", "text"),
    [
        ("broken.urdf", "<robot><link/></robot>"),
        ("broken.xml", "<notmujoco/>"),
        ("empty.xml", "<mujoco><worldbody/></mujoco>"),
    ],
)
def test_parser_errors_name_the_model_not_a_server_path(layout, file_name, text):
    (layout["allowed"] / file_name).write_text(text)
    with pytest.raises(ModelError) as info:
        load_robot_model(file_name)
    assert wire_code(info.value) == ErrorCode.MODEL_INVALID
    detail = info.value.detail
    assert "/" not in detail and "poise-model" not in detail and "From file" not in detail
    if file_name.endswith(".urdf"):
        assert "'broken'" in detail


def test_parser_errors_for_client_text_name_no_server_path():
    for text, fmt in (("<robot><link/></robot>", "urdf"), ("<notmujoco/>", "mjcf")):
        with pytest.raises(ModelError) as info:
            load_robot_model(model_text=text, model_format=fmt)
        assert "/" not in info.value.detail and "poise-model" not in info.value.detail


# --- limits ----------------------------------------------------------------------------------


def test_files_over_the_size_cap_are_limit_exceeded(layout, allow_model_dir, thesis):
    allow_model_dir(layout["allowed"], max_file_bytes=100)
    for load, name, field in (
        (load_robot_model, "tiny.xml", "model"),
        (lambda n: load_motion_clip(n, thesis), "still.json", "params.clip"),
    ):
        with pytest.raises(ServerFault) as info:
            load(name)
        assert (wire_code(info.value), info.value.field) == (ErrorCode.LIMIT_EXCEEDED, field)
        assert "100 bytes" in info.value.detail
    # Refused names stay refused (not a size error that would confirm they exist).
    with pytest.raises(ModelError):
        load_robot_model(str(layout["outside"] / "robot.xml"))
    allow_model_dir(layout["allowed"], max_file_bytes=len(TINY_MJCF))
    assert load_robot_model("tiny.xml").name == "tiny"


@pytest.fixture
def cache_of_two():
    set_model_cache_size(2)
    yield
    set_model_cache_size(DEFAULT_MODEL_CACHE_SIZE)


def test_model_cache_keeps_recent_models_and_evicts_the_oldest(cache_of_two):
    a, b, c = (TINY_MJCF + f"<!-- {i} -->" for i in range(3))
    robot_a = load_robot_model(model_text=a)
    robot_b = load_robot_model(model_text=b)
    assert load_robot_model(model_text=a) is robot_a  # a is now the most recent
    load_robot_model(model_text=c)  # evicts b
    assert load_robot_model(model_text=a) is robot_a
    new_b = load_robot_model(model_text=b)
    assert new_b is not robot_b and new_b.model_hash == robot_b.model_hash


def test_builtin_models_are_cached():
    for name in BUILTIN_MODELS:
        assert load_robot_model(name) is load_robot_model(name)


def test_model_cache_size_must_be_positive():
    with pytest.raises(ValueError, match="size"):
        set_model_cache_size(0)


@given(st.text(max_size=2000))
def test_any_non_builtin_name_gets_the_same_refusal(name):
    """With no model directories, every name but a built-in is refused the same way."""
    assert files.model_directories() == ()
    for kind, error_type in ((MODEL_FILES, ModelError), (CLIP_FILES, InvalidParams)):
        if name in kind.builtin:
            continue
        with pytest.raises(error_type) as info:
            kind.resolve(name)
        assert info.value.detail == kind.refusal(name).detail
        assert info.value.detail.startswith(display_name(name) + " is not a built-in")


def test_module_exports():
    for name in files.__all__:
        assert hasattr(files, name)
