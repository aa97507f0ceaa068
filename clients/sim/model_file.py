"""Model files for simulator backends: where built-ins live, where the feet touch.

The simulator reads the same MJCF the server loads. It finds the built-in
files by the ``controller_server`` package's location without importing it
(a client talks to the server only through the protocol), and takes the
foot contact points from the ``*_sole`` box sites exactly as the server does
by default: the four corners of each site's x–y rectangle.
"""

from __future__ import annotations

import importlib.util
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from clients.sim.backend import ContactPoint

__all__ = [
    "body_names",
    "builtin_model_names",
    "builtin_model_path",
    "hello_model",
    "resolve_model_path",
    "sole_contact_points",
]


def _builtin_model_dir() -> Path:
    spec = importlib.util.find_spec("controller_server")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError("the controller_server package is not installed")
    return Path(next(iter(spec.submodule_search_locations))) / "models" / "data"


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
        FileNotFoundError: No such file, or no built-in of that name; the
            message says which, and lists the built-ins.
    """
    path = Path(model)
    if not path.suffix:
        return builtin_model_path(model)
    if not path.is_file():
        raise FileNotFoundError(
            f"model file {model!r} does not exist (relative paths start from {Path.cwd()})"
        )
    return path


def hello_model(model: str) -> dict[str, Any]:
    """The ``hello`` fields naming ``model``: a built-in by name, a file by its text.

    A server reads files only from its own model directories, and may run on
    another machine; the simulator has the file, so it sends what it simulates.
    """
    path = Path(model)
    if not (path.suffix and path.is_file()):
        return {"model": model}
    return {
        "model_text": path.read_text(),
        "model_format": "urdf" if path.suffix == ".urdf" else "mjcf",
    }


def body_names(path: Path) -> list[str]:
    """Names of the MJCF bodies (what a push may name), in document order."""
    worldbody = ET.parse(path).getroot().find("worldbody")
    if worldbody is None:
        return []
    return [name for body in worldbody.iter("body") if (name := body.get("name"))]


def sole_contact_points(path: Path) -> list[ContactPoint]:
    """Corners of every ``*_sole`` box site, contacts named ``<side>_foot`` (server order)."""
    points = []
    for site in ET.parse(path).getroot().iter("site"):
        name = site.get("name", "")
        if not name.endswith("_sole") or site.get("type") != "box":
            continue
        half_x, half_y = (float(s) for s in site.get("size", "0 0 0").split()[:2])
        contact = name.removesuffix("_sole") + "_foot"
        for sx in (1, -1):
            for sy in (1, -1):
                points.append(ContactPoint(contact, name, (sx * half_x, sy * half_y, 0.0)))
    return points
