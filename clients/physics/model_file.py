"""Model files for the clients: where built-ins live, and what a file describes.

The simulators and the bridge read a robot file exactly as the server does:
through :mod:`controller_server.models.description`, the one reading of MJCF
and URDF shared by server and clients (the only server module a client
imports: it knows no session and no wire). So the simulated robot, its
contacts and its standing pose are the ones the server controls. Built-in
files are found by the ``controller_server`` package's location.
"""

from __future__ import annotations

import importlib.util
import json
import os
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from clients.physics.backend import ContactPoint
from controller_server.models.description import (
    DescriptionError,
    FileReader,
    RobotDescription,
    describe,
    gather_files,
    resolve_file,
    ros_package_path,
    srdf_paths,
)
from protocol.messages import ContactSpec

__all__ = [
    "DescriptionError",
    "RobotDescription",
    "body_names",
    "builtin_model_names",
    "builtin_model_path",
    "contact_points",
    "describe_model",
    "hello_model",
    "local_reader",
    "model_format",
    "resolve_model_path",
]


def _builtin_model_dir() -> Path:
    spec = importlib.util.find_spec("controller_server")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError("the controller_server package is not installed")
    locations = [Path(location) for location in spec.submodule_search_locations]
    # An editable install spans two directories: the compiled core's in site-packages (first)
    # and the clone's, with the sources and their data.
    return next(
        (where / "models" / "data" for where in locations if (where / "models" / "data").is_dir()),
        locations[0] / "models" / "data",
    )


def builtin_model_names() -> list[str]:
    """Names of the built-in models, sorted."""
    return sorted(path.stem for path in _builtin_model_dir().glob("*.xml"))


def builtin_model_path(name: str) -> Path:
    """Path of a built-in MJCF model, e.g. ``thesis_humanoid``."""
    path = _builtin_model_dir() / f"{name}.xml"
    if not path.is_file():
        raise FileNotFoundError(
            f"no built-in model {name!r}; built in: {', '.join(builtin_model_names())} "
            "(or give the path of an .xml or .urdf file)"
        )
    return path


def resolve_model_path(model: str) -> Path:
    """A built-in name or a file path (one with a suffix, e.g. ``robot.xml``).

    Raises:
        FileNotFoundError: No such file, a directory, or no built-in of that
            name; the message says which, and lists the built-ins (or the
            directory's model files).
    """
    path = Path(model)
    if path.is_dir():
        found = sorted(p.name for p in path.iterdir() if p.suffix.lower() in (".xml", ".urdf"))
        hint = f"; in it: {', '.join(found[:6])}{', …' if len(found) > 6 else ''}" if found else ""
        raise FileNotFoundError(
            f"model {model!r} is a directory: give the robot's .xml (MJCF, a scene with "
            f"includes is fine) or .urdf file{hint}"
        )
    if not path.suffix:
        return builtin_model_path(model)
    if not path.is_file():
        raise FileNotFoundError(
            f"model file {model!r} does not exist (relative paths start from {Path.cwd()})"
        )
    return path


def model_format(path: Path) -> str:
    """``urdf`` for a ``.urdf`` file, else ``mjcf``."""
    return "urdf" if path.suffix.lower() == ".urdf" else "mjcf"


def local_reader(
    path: Path, srdf: Path | None = None, *, opened: dict[Path, int | None] | None = None
) -> FileReader:
    """Reads the files a model names, from the client's disk.

    Paths are relative to the model's directory; ``package://`` URIs are found
    through ``ROS_PACKAGE_PATH``, then the model's ancestors, as ROS tools find
    them; ``file://`` URIs are absolute paths (see
    :func:`~controller_server.models.description.resolve_file`).

    Args:
        path: The model file.
        srdf: An SRDF served in place of the first of the URDF's
            :func:`~controller_server.models.description.srdf_paths`.
        opened: Filled with every file tried and its modification time (ns;
            ``None``: missing), so a cache can tell when one changed.

    Raises:
        DescriptionError: ``srdf`` given for a model without a ``<robot name>``.
    """
    directory = path.parent
    search_path = ros_package_path()
    packages: dict[str, Path | None] = {}
    served: dict[str, Path] = {}
    if srdf is not None:
        names = srdf_paths(path.read_bytes())
        if not names:
            raise DescriptionError(
                f"--srdf {srdf}: {path.name} has no <robot name>, which names a URDF's SRDF"
            )
        served[names[0]] = srdf

    def read(name: str) -> bytes:
        if name in served:
            file = served[name]
        else:
            file = resolve_file(name, directory, search_path=search_path, packages=packages)
        if opened is not None:
            opened[file] = _modified_ns(file)
        return file.read_bytes()

    return read


def _modified_ns(path: Path) -> int | None:
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return None


@dataclass(frozen=True)
class _Described:
    description: RobotDescription
    opened: dict[Path, int | None]


_DESCRIBED: OrderedDict[tuple[object, ...], _Described] = OrderedDict()
_DESCRIBED_KEPT = 16
_DESCRIBED_LOCK = threading.Lock()


def describe_model(
    model: str,
    *,
    contacts: list[ContactSpec] | None = None,
    keyframe: str | None = None,
    srdf: str | Path | None = None,
) -> RobotDescription:
    """What Poise reads from a built-in or a model file.

    Cached per file, contacts, keyframe, SRDF and ``ROS_PACKAGE_PATH``, while
    no file read for it (the model, its includes, meshes, SRDF) has changed.

    Args:
        model: A built-in name or a model file.
        contacts: Contacts to use instead of the found ones.
        keyframe: Keyframe of the standing pose (a URDF's: its SRDF's ``group_state``).
        srdf: An SRDF file for a URDF, instead of the one beside it.

    Raises:
        FileNotFoundError: No such file or built-in.
        DescriptionError: The file cannot be used as written (one line saying what to do).
    """
    path = resolve_model_path(model).resolve()
    srdf_path = None if srdf is None else _srdf_file(srdf, path)
    contacts_json = None if contacts is None else json.dumps([c.model_dump() for c in contacts])
    key = (path, contacts_json, keyframe, srdf_path, os.environ.get("ROS_PACKAGE_PATH", ""))
    with _DESCRIBED_LOCK:
        cached = _DESCRIBED.get(key)
        if cached is not None:
            _DESCRIBED.move_to_end(key)
    if cached is not None and all(_modified_ns(f) == t for f, t in cached.opened.items()):
        return cached.description
    opened: dict[Path, int | None] = {path: _modified_ns(path)}
    description = describe(
        path.read_bytes(),
        model_format(path),
        read=local_reader(path, srdf_path, opened=opened),
        name=path.stem,
        contacts=None
        if contacts_json is None
        else [ContactSpec.model_validate(c) for c in json.loads(contacts_json)],
        keyframe=keyframe,
    )
    with _DESCRIBED_LOCK:
        _DESCRIBED[key] = _Described(description, opened)
        _DESCRIBED.move_to_end(key)
        while len(_DESCRIBED) > _DESCRIBED_KEPT:
            _DESCRIBED.popitem(last=False)
    return description


def _srdf_file(srdf: str | Path, model: Path) -> Path:
    path = Path(srdf).expanduser()
    if not path.is_file():
        raise FileNotFoundError(
            f"SRDF file {str(srdf)!r} does not exist (relative paths start from {Path.cwd()})"
        )
    if model_format(model) != "urdf":
        raise DescriptionError(f"--srdf {srdf}: an SRDF goes with a URDF, not {model.name}")
    return path.resolve()


def hello_model(model: str, *, srdf: str | Path | None = None) -> dict[str, Any]:
    """The ``hello`` fields naming ``model``: a built-in by name, a file by its text and files.

    A server reads files only from its own model directories, and may run on
    another machine; the simulator has the files, so it sends what it
    simulates: the main file's text and every file it names (includes,
    meshes, a URDF's SRDF), by the names the file gives them.

    Args:
        model: A built-in name or a model file.
        srdf: An SRDF file for a URDF, sent as the one beside it.

    Raises:
        FileNotFoundError: ``srdf`` does not exist.
        DescriptionError: The model names a file that cannot be read.
    """
    path = Path(model)
    if not (path.suffix and path.is_file()):
        return {"model": model}
    srdf_path = None if srdf is None else _srdf_file(srdf, path)
    text = path.read_bytes()
    fields: dict[str, Any] = {"model_text": text.decode(), "model_format": model_format(path)}
    assets = gather_files(text, model_format(path), local_reader(path, srdf_path))
    if assets:
        fields["model_assets"] = assets
    return fields


def body_names(model: str) -> list[str]:
    """Names of the robot's bodies (what a push may name), root first."""
    return [body.name for body in describe_model(model).bodies]


def contact_points(description: RobotDescription) -> list[ContactPoint]:
    """Every contact point of the description, in contact order, in its contact's frame."""
    return [
        ContactPoint(contact.name, contact.frame, tuple(float(c) for c in point))
        for contact in description.contacts
        for point in contact.points_in_frame
    ]
