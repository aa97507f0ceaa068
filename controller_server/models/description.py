"""A robot as its vendor's file describes it: one reading shared by the server and the simulators.

MJCF goes through MuJoCo's own compiler, which resolves what vendors write:
robot files ``<include>``-ed by a ``scene.xml``, ``<default>`` classes,
both free-joint spellings, meshes, ``autolimits``, extra root bodies
(cameras, mocap targets, props). The Pinocchio model is then built from the
*compiled* MuJoCo model, body by body, so the server's dynamics are the
simulator's to the last inertia. URDF is read by Pinocchio's parser.

:func:`describe` never opens a file: every ``<include>``, asset, URDF mesh
and SRDF goes through a ``read`` callable (the server's confines reads to its
model directories, a client-sent model reads only the files it sent), and
MuJoCo compiles from memory, so it cannot open a file the caller did not hand
over. The readers find what a name stands for with :func:`resolve_file`
(``package://`` URIs as ROS tools find them, :func:`find_package`).

From the model, a :class:`RobotDescription` finds:

* **Contacts.** ``*_sole`` box sites if the file has them (the corners of the
  site's x–y rectangle, as the built-in robots); otherwise the feet are found
  from the collision geometry: at the standing pose, the bodies whose
  collision geoms reach within :data:`FOOT_HEIGHT_TOLERANCE_M` of the lowest
  point are the feet (a foot's descendants are part of it), and each foot's
  sole is the rectangle, aligned with the foot's heading, around its
  collision points within :data:`SOLE_HEIGHT_TOLERANCE_M` of its lowest one.
  A contact may instead be named (a frame without points): its sole is found
  the same way from that frame's body and its descendants. A URDF collision
  mesh that cannot be read is left out (one warning for all of them), unless
  a sole is looked for on its link (a :func:`foot_candidates` link, or a
  named foot): then it is an error, not a silent choice of other feet.
* **Torque limits** from every place a file states them: MJCF actuator
  ``forcerange``, a motor's ``ctrlrange`` × gain, × |gear|, and the joint's
  ``actuatorfrcrange`` (defaults classes included, being compiled); URDF
  ``<limit effort>``.
* **Actuator kinds** per joint (``motor``, ``position``, ``velocity``,
  ``general``, or ``none``), so that a simulator can convert
  position-actuated models to torque motors instead of misusing them.
* **The standing pose**: a keyframe by name (MJCF ``<key>``; a URDF's SRDF
  ``group_state``), or the file's reference pose, lifted or lowered so that
  the lowest contact point is at z = 0.
* **Disabled collision pairs** from a URDF's SRDF (``disable_collisions``).
"""

from __future__ import annotations

import math
import os
import posixpath
import re
import struct
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import mujoco
import numpy as np
import pinocchio as pin

from protocol.errors import did_you_mean
from protocol.messages import (
    MAX_CONTACT_POINTS,
    MAX_CONTACTS,
    MAX_POINTS_PER_CONTACT,
    ContactSpec,
)

__all__ = [
    "FOOT_CANDIDATE_HEIGHT_FRACTION",
    "FOOT_HEIGHT_TOLERANCE_M",
    "MAX_ASSET_BYTES",
    "MAX_BODIES",
    "MAX_DOF",
    "MAX_IMAGE_PIXELS",
    "MAX_PACKAGE_SEARCH_DEPTH",
    "MAX_XML_DEPTH",
    "MAX_XML_ELEMENTS",
    "SOLE_HEIGHT_TOLERANCE_M",
    "DescriptionError",
    "DescriptionLimitError",
    "FileReader",
    "FoundContact",
    "FrameNotFoundError",
    "RobotDescription",
    "compile_mjcf",
    "describe",
    "expand_mjcf",
    "find_package",
    "foot_candidates",
    "gather_files",
    "resolve_file",
    "ros_package_path",
    "srdf_paths",
    "subtree",
]

FOOT_HEIGHT_TOLERANCE_M = 0.02
"""A body whose collision geometry reaches this close to the lowest point (standing) is a foot."""
SOLE_HEIGHT_TOLERANCE_M = 0.005
"""A foot's collision points this close to its lowest point span its sole."""
FOOT_CANDIDATE_HEIGHT_FRACTION = 0.15
"""A URDF link whose frame (standing) is this far up the robot's height, or lower, may be a foot.

Measured from the lowest link frame, as a fraction of the span between the
lowest and the highest link frame: ankles, feet, soles and toes, not knees
nor hands hanging by the thighs. A collision mesh of such a link that cannot
be read is an error when the feet are found from the collision geometry."""
MAX_INCLUDE_DEPTH = 16
"""Deepest chain of includes followed."""
MAX_PACKAGE_SEARCH_DEPTH = 8
"""Deepest directory below a ``ROS_PACKAGE_PATH`` entry searched for a package."""

# Caps on what reading a model may cost, so that a file sent by a client cannot
# hold a server worker for long (issue 32). Each is several times what real
# robots need; the numbers measured are in docs/serving.md.
MAX_XML_DEPTH = 128
"""Deepest nesting of elements in a model's XML, includes inlined (a humanoid MJCF: ~20)."""
MAX_XML_ELEMENTS = 20_000
"""Elements of a model's XML, includes inlined, those inside ``<replicate>``,
``<composite>`` and ``<flexcomp>`` counted as often as they repeat (a vendor
humanoid MJCF: a few hundred to 2,000)."""
MAX_BODIES = 500
"""Bodies of a compiled MJCF (robot, props and world), links of a URDF."""
MAX_DOF = 200
"""Degrees of freedom of a model (``nv``, a free base's 6 included): Talos has 38, a
humanoid with two dexterous hands about 90. Loading took 0.6 s at 198 and 13–19 s at
398, a ``prioritized`` tick 24 ms and 0.4–0.9 s (docs/serving.md)."""
MAX_ASSET_BYTES = 64 * 1024 * 1024
"""Bytes of the files a model's meshes, textures, height fields and skins read, a file
counted each time it is named (MuJoCo compiles each naming): ~3 s of compiling."""
MAX_IMAGE_PIXELS = 64 * 1024 * 1024
"""Pixels of a model's textures and height fields together (PNG files' and built-in
ones): a small PNG file may decode into gigabytes."""

FileReader = Callable[[str], bytes]
"""Reads a file named by a model, by the name the model gives it.

MJCF: a path relative to the main file's directory (POSIX), ``meshdir`` and
includes resolved. URDF: a mesh's ``filename`` exactly as written (a
``package://`` or ``file://`` URI, or a path relative to the URDF's
directory) and the SRDF's :func:`srdf_paths`. The reader resolves it
(:func:`resolve_file`)."""

_ASSET_DIRECTORY = {
    "mesh": "meshdir",
    "skin": "meshdir",
    "hfield": "meshdir",
    "texture": "texturedir",
}
_FREE = int(mujoco.mjtJoint.mjJNT_FREE)
_BALL = int(mujoco.mjtJoint.mjJNT_BALL)
_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
_TRN_JOINT = int(mujoco.mjtTrn.mjTRN_JOINT)
_GAIN_FIXED = int(mujoco.mjtGain.mjGAIN_FIXED)
_BIAS_NONE = int(mujoco.mjtBias.mjBIAS_NONE)
_BIAS_AFFINE = int(mujoco.mjtBias.mjBIAS_AFFINE)
_GEOM = mujoco.mjtGeom
_UNIT_AXES = {(1.0, 0.0, 0.0): "X", (0.0, 1.0, 0.0): "Y", (0.0, 0.0, 1.0): "Z"}


class DescriptionError(ValueError):
    """The model cannot be used as written; the message says what to change, on one line.

    Attributes:
        field: What to change: ``model`` (the file), ``contacts`` or ``keyframe``.
    """

    def __init__(self, message: str, *, field: str = "model"):
        super().__init__(message)
        self.field = field


class DescriptionLimitError(DescriptionError):
    """The model exceeds a cap on what reading or serving it may cost (the ``MAX_*`` constants)."""


class FrameNotFoundError(DescriptionError):
    """A contact names a frame the model does not have."""

    def __init__(self, frame: str, available: list[str]):
        self.frame = frame
        self.available = available
        hint = did_you_mean(frame, available)
        super().__init__(
            f"no frame {frame!r} in the model; {hint}frames: {', '.join(available)}",
            field="contacts",
        )


def gather_files(text: bytes | str, fmt: str, read: FileReader | None) -> dict[str, bytes]:
    """Every file the model names, read now, by the name :func:`describe` will ask for.

    MJCF: includes (recursively) and assets, by their path relative to the main
    file's directory; a file that cannot be read is an error. URDF: the
    collision meshes that can be read, keyed by their ``filename`` exactly as
    written (the others are left out by :func:`describe`, with a warning or an
    error), and the SRDF if one is found (:func:`srdf_paths`).

    Raises:
        DescriptionError: An MJCF names a file that cannot be read, or is not XML.
    """
    files: dict[str, bytes] = {}

    def recording(path: str) -> bytes:
        if read is None:
            raise KeyError("no file was given with the model")
        files[path] = read(path)
        return files[path]

    if fmt == "urdf":
        root = _parse_xml(text, "the URDF")
        for collision in root.iter("collision"):
            for mesh in collision.iter("mesh"):
                filename = mesh.get("filename", "")
                if filename in files:
                    continue
                try:
                    recording(filename)
                except (OSError, KeyError, ValueError):
                    continue
        _find_srdf(root, recording)
    else:
        expand_mjcf(text, recording if read is not None else None)
    return files


# -- where a named file is: paths, package:// and file:// URIs -------------------------


def ros_package_path() -> tuple[Path, ...]:
    """The directories of ``ROS_PACKAGE_PATH`` (``:``-separated; empty entries skipped)."""
    value = os.environ.get("ROS_PACKAGE_PATH", "")
    return tuple(Path(entry).expanduser() for entry in value.split(os.pathsep) if entry)


def _manifest_name(directory: Path) -> str | None:
    """The package a directory is (its ``package.xml``'s ``<name>``, else its own name).

    ``None``: no ``package.xml``, not a package.
    """
    manifest = directory / "package.xml"
    try:
        if not manifest.is_file():
            return None
        name = (ET.fromstring(manifest.read_bytes()).findtext("name") or "").strip()
    except (OSError, ET.ParseError):
        name = ""
    return name or directory.name


def _is_package(directory: Path, package: str) -> bool:
    name = _manifest_name(directory)
    return name is not None and package in (name, directory.name)


def _inside(path: Path, roots: Sequence[Path] | None) -> bool:
    if roots is None:
        return True
    try:
        resolved = path.resolve()
    except (OSError, RuntimeError):
        return False
    return any(resolved.is_relative_to(root) for root in roots)


def find_package(
    package: str,
    search_path: Sequence[Path],
    start: Path | None = None,
    *,
    within: Sequence[Path] | None = None,
) -> Path | None:
    """The directory of a ROS package, found the way ROS tools find it.

    First each directory of ``search_path`` (``ROS_PACKAGE_PATH``) in order:
    the directory itself if it is the package (named ``package``, or holding
    a ``package.xml`` that names it), else the packages below it, shallowest
    first, up to :data:`MAX_PACKAGE_SEARCH_DEPTH` deep — a directory holding a
    ``package.xml`` is a package, named by its ``<name>`` (or the directory's
    name), and is not searched further; hidden directories and those marked
    ``CATKIN_IGNORE``, ``COLCON_IGNORE`` or ``AMENT_IGNORE`` are skipped. Then
    the ancestors of ``start`` (the URDF's directory), nearest first: one named
    ``package`` or whose ``package.xml`` names it (example-robot-data's layout:
    ``example-robot-data/robots/talos_data/robots/talos.urdf`` names its
    meshes ``package://example-robot-data/robots/talos_data/meshes/…``).

    Args:
        package: The package's name.
        search_path: Directories searched first (:func:`ros_package_path`).
        start: The directory whose ancestors are tried next (``None``: none).
        within: Only directories inside these (resolved) are considered
            (``None``: anywhere); the server passes its model directories.

    Returns:
        The package's directory, or ``None``.
    """
    if not package or package in (".", "..") or "/" in package or "\\" in package:
        return None
    for entry in search_path:
        if not entry.is_dir():
            continue
        if entry.name == package or _is_package(entry, package):
            if _inside(entry, within):
                return entry
            continue
        level = [entry]
        for _ in range(MAX_PACKAGE_SEARCH_DEPTH):
            deeper = []
            for directory in level:
                try:
                    children = sorted(
                        child
                        for child in directory.iterdir()
                        if child.is_dir() and not child.name.startswith(".")
                    )
                except OSError:
                    continue
                for child in children:
                    if _manifest_name(child) is not None:
                        if _is_package(child, package) and _inside(child, within):
                            return child
                    elif not any((child / m).exists() for m in _IGNORE_MARKERS):
                        deeper.append(child)
            level = deeper
    if start is not None:
        for directory in (start, *start.parents):
            if not _inside(directory, within):
                break
            if directory.name == package or _is_package(directory, package):
                return directory
    return None


_IGNORE_MARKERS = ("CATKIN_IGNORE", "COLCON_IGNORE", "AMENT_IGNORE")


def resolve_file(
    name: str,
    directory: Path,
    *,
    search_path: Sequence[Path] = (),
    within: Sequence[Path] | None = None,
    file_uris: bool = True,
    packages: dict[str, Path | None] | None = None,
) -> Path:
    """The path a file named by a model stands for.

    ``package://PKG/rest`` is ``rest`` in the package's directory
    (:func:`find_package`: ``search_path``, then the ancestors of
    ``directory``); ``file:///abs/path`` is ``/abs/path`` (if ``file_uris``);
    anything else is a path relative to ``directory`` (or absolute).

    Args:
        name: As the model writes it.
        directory: The model's directory.
        search_path: ``ROS_PACKAGE_PATH``'s directories.
        within: Packages only inside these directories (see :func:`find_package`).
        file_uris: Whether ``file://`` URIs are read (the server reads none).
        packages: Packages found so far, by name (filled in; saves searching again).

    Raises:
        DescriptionError: A package that cannot be found (the message names it
            and says to set ``ROS_PACKAGE_PATH``), a ``file://`` URI not read,
            another URI scheme.
    """
    scheme, separator, rest = name.partition("://")
    if not separator:
        return directory / name
    if scheme == "file" and file_uris:
        return Path(rest)
    if scheme != "package":
        raise DescriptionError(
            f"{scheme}:// URIs are not read here: name the file by a path relative to the "
            "model's directory or by a package:// URI"
        )
    package, _, inner = rest.partition("/")
    known = packages if packages is not None else {}
    if package not in known:
        known[package] = find_package(package, search_path, directory, within=within)
    found = known[package]
    if found is None:
        searched = os.pathsep.join(str(p) for p in search_path) or "unset"
        raise DescriptionError(
            f"package {package!r} is not in ROS_PACKAGE_PATH ({searched}) nor an ancestor of "
            f"{str(directory)!r}"
        )
    return found / inner


# -- MJCF through MuJoCo's compiler ------------------------------------------------------


def expand_mjcf(text: bytes | str, read: FileReader | None) -> tuple[str, dict[str, bytes]]:
    """One MJCF document with every include inlined and every file handed over in memory.

    ``<include file>`` is replaced by the included ``<mujoco>``'s children (paths
    relative to the main file's directory, as MuJoCo resolves them). Every
    attribute naming a file (``file``, a cube texture's ``fileright`` …) is
    read through ``read`` — meshes, skins and height fields under
    ``meshdir``, textures under ``texturedir`` (or ``assetdir``) — and
    replaced by a key of the returned assets, so MuJoCo compiles from memory.

    Args:
        text: The main MJCF file.
        read: Reads a file named relative to the main file's directory;
            ``None``: the model may name no file.

    Returns:
        The expanded XML and the assets by key.

    Raises:
        DescriptionError: Not XML, not ``<mujoco>``, an include cycle or chain
            deeper than :data:`MAX_INCLUDE_DEPTH`, a plugin, or a file that
            cannot be read.
    """
    xml, assets, _ = _expand_mjcf(text, read)
    return xml, assets


def _expand_mjcf(
    text: bytes | str, read: FileReader | None
) -> tuple[str, dict[str, bytes], dict[str, str]]:
    """:func:`expand_mjcf`, and the path each asset key stands for (for MuJoCo's messages)."""
    root = _parse_xml(text, "the model")
    if root.tag != "mujoco":
        raise DescriptionError(f"an MJCF file's root element is <mujoco>, not <{root.tag}>")
    _inline_includes(root, read, depth=0, chain=(), level=1, elements=[_count_elements(root)])
    if root.find(".//plugin") is not None or root.find(".//extension") is not None:
        raise DescriptionError("MuJoCo plugins (<extension>, <plugin>) are not supported")
    if root.find(".//attach") is not None or root.find("./asset/model") is not None:
        # MuJoCo would resolve the files an attached model names itself, from disk.
        raise DescriptionError(
            "MJCF <attach> and <model> assets are not supported: <include> the file instead"
        )
    directories = {"meshdir": "", "texturedir": ""}
    strip_paths = False
    for compiler in root.iter("compiler"):
        if "assetdir" in compiler.attrib:
            directories = dict.fromkeys(directories, compiler.attrib.pop("assetdir"))
        for key in directories:
            if key in compiler.attrib:
                directories[key] = compiler.attrib.pop(key)
        strip_paths = compiler.get("strippath", str(strip_paths).lower()) == "true"
        compiler.attrib.pop("strippath", None)
    _name_unnamed_assets(root)
    assets: dict[str, bytes] = {}
    keys: dict[str, str] = {}
    cost = _Cost()
    for element, times in _elements_with_repeats(root):
        cost.count(element, times)
        for attribute, value in list(element.attrib.items()):
            if not attribute.startswith("file"):
                continue
            name = posixpath.basename(value) if strip_paths else value
            directory = directories.get(_ASSET_DIRECTORY.get(element.tag, ""), "")
            path = posixpath.normpath(posixpath.join(directory, name))
            if path not in keys:
                # A generated name, never the file's: nothing of it reaches MuJoCo's parser,
                # and every name in the XML is a key of the assets (MuJoCo reads a file
                # missing from them from its working directory).
                keys[path] = f"poise_asset_{len(keys)}{_safe_suffix(path)}"
                assets[keys[path]] = _read(read, path, f"<{element.tag} {attribute}>")
            element.set(attribute, keys[path])
            cost.add_file(path, assets[keys[path]], times)
    paths = {key: path for path, key in keys.items()}
    return ET.tostring(root, encoding="unicode"), assets, paths


def _mujoco_message(exc: ValueError, paths: dict[str, str]) -> str:
    """MuJoCo's message on one line, each asset key replaced by the path the model names.

    MuJoCo names a file it cannot decode by its key, a name the client never wrote.
    """
    detail = " ".join(str(exc).split())
    if not paths:
        return detail
    keys = "|".join(re.escape(key) for key in sorted(paths, key=len, reverse=True))
    return re.sub(rf"(?<![\w.])(?:{keys})(?![\w.])", lambda key: paths[key[0]], detail)


def _safe_suffix(path: str) -> str:
    """A file's suffix, lowercase, if it is letters and digits (MuJoCo picks a decoder by it)."""
    suffix = PurePosixPath(path.replace("\\", "/")).suffix.lower()
    return suffix if re.fullmatch(r"\.[a-z0-9]{1,10}", suffix) else ""


def _count_elements(root: ET.Element) -> int:
    return sum(1 for _ in root.iter())


def _xml_depth(root: ET.Element) -> int:
    """Levels of elements under and including ``root`` (without recursion)."""
    depth, level = 0, [root]
    while level:
        depth += 1
        level = [child for element in level for child in element]
    return depth


def _repeats(element: ET.Element) -> int:
    """How many times MuJoCo makes what an element holds (``<replicate count>`` and the like)."""
    if element.tag not in ("replicate", "composite", "flexcomp"):
        return 1
    times = 1
    for word in element.get("count", "1").split():
        try:
            value = float(word)
        except ValueError:
            continue  # MuJoCo's to refuse
        times *= max(1, math.ceil(value)) if math.isfinite(value) else MAX_XML_ELEMENTS + 1
    return times


def _elements_with_repeats(root: ET.Element) -> list[tuple[ET.Element, int]]:
    """Every element (document order) and how many copies of it MuJoCo will make.

    Raises:
        DescriptionLimitError: More than :data:`MAX_XML_ELEMENTS` copies in all.
    """
    found: list[tuple[ET.Element, int]] = []
    total = 0
    stack = [(root, 1)]
    while stack:
        element, times = stack.pop()
        total += times
        if total > MAX_XML_ELEMENTS:
            raise DescriptionLimitError(
                f"the model has more than {MAX_XML_ELEMENTS} XML elements, those inside "
                "<replicate>, <composite> and <flexcomp> counted as often as they repeat"
            )
        found.append((element, times))
        inner = times * _repeats(element)
        stack.extend((child, inner) for child in reversed(element))
    return found


class _Cost:
    """Bytes of files and pixels of images a model makes MuJoCo compile, within the caps."""

    def __init__(self) -> None:
        self.file_bytes = 0
        self.pixels = 0

    def count(self, element: ET.Element, times: int) -> None:
        """Count an element's built-in image (a texture's ``width``, a height field's ``nrow``)."""
        if element.tag == "texture" and not any(a.startswith("file") for a in element.attrib):
            faces = 6 if element.get("type") in ("cube", "skybox") else 1
            pixels = faces * _number(element, "width") * _number(element, "height")
            self._add_pixels(pixels * times, element.tag)
        elif element.tag == "hfield" and "file" not in element.attrib:
            self._add_pixels(_number(element, "nrow") * _number(element, "ncol") * times, "hfield")

    def add_file(self, path: str, data: bytes, times: int) -> None:
        """Count a file named ``times`` times: its bytes, and its pixels if it is a PNG image."""
        self.file_bytes += len(data) * times
        if self.file_bytes > MAX_ASSET_BYTES:
            raise DescriptionLimitError(
                f"the model's meshes, textures, height fields and skins read more than "
                f"{MAX_ASSET_BYTES // (1024 * 1024)} MiB of files, each counted as often as it "
                f"is named (at {path[:100]!r})"
            )
        if data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR" and len(data) >= 24:
            width, height = struct.unpack(">II", data[16:24])
            self._add_pixels(width * height * times, f"the image {path[:100]!r}")

    def _add_pixels(self, pixels: int, what: str) -> None:
        self.pixels += pixels
        if self.pixels > MAX_IMAGE_PIXELS:
            raise DescriptionLimitError(
                f"the model's textures and height fields have more than {MAX_IMAGE_PIXELS} "
                f"pixels together (at {what})"
            )


def _number(element: ET.Element, attribute: str) -> int:
    """A whole-number attribute, 0 if missing or not a finite number (MuJoCo's to refuse)."""
    try:
        value = float(element.get(attribute, "0"))
    except ValueError:
        return 0
    return max(0, math.ceil(value)) if math.isfinite(value) else MAX_IMAGE_PIXELS + 1


def _name_unnamed_assets(root: ET.Element) -> None:
    """Name each unnamed file asset as MuJoCo would, before its ``file`` becomes a key.

    MuJoCo names a ``<mesh>``, ``<hfield>``, ``<skin>`` or ``<texture>`` that
    has a ``file`` and no ``name`` after the file: its base name (after the
    last ``/`` or backslash) without its last extension, whatever ``meshdir``
    says (``file="meshes/pelvis.STL"`` is ``pelvis``; ``foot.Part.stl`` is
    ``foot.Part``; ``.stl`` stays unnamed). Geoms refer to it by that name.
    """
    for asset in root.iter("asset"):
        for element in asset:
            file = element.get("file")
            if element.tag not in _ASSET_DIRECTORY or file is None or "name" in element.attrib:
                continue
            base = file.replace("\\", "/").rsplit("/", 1)[-1]
            name = base.rsplit(".", 1)[0] if "." in base else base
            if name:
                element.set("name", name)


def _parse_xml(text: bytes | str, what: str) -> ET.Element:
    """The XML's root element.

    Raises:
        DescriptionError: Not XML.
        DescriptionLimitError: Nested deeper than :data:`MAX_XML_DEPTH`, or more than
            :data:`MAX_XML_ELEMENTS` elements.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise DescriptionError(f"{what} is not valid XML: {exc}") from None
    if _count_elements(root) > MAX_XML_ELEMENTS:
        raise DescriptionLimitError(f"{what} has more than {MAX_XML_ELEMENTS} XML elements")
    if _xml_depth(root) > MAX_XML_DEPTH:
        raise DescriptionLimitError(f"{what} nests XML elements more than {MAX_XML_DEPTH} deep")
    return root


def _read(read: FileReader | None, path: str, what: str) -> bytes:
    if read is None:
        raise DescriptionError(
            f"{what} names the file {path!r}, and no file was given with the model "
            "(send it in `model_assets`, or load the model from a file)"
        )
    try:
        return read(path)
    except DescriptionError as exc:
        raise DescriptionError(f"{what} names {path!r}: {exc}") from None
    except (OSError, KeyError, ValueError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        tried = getattr(exc, "filename", None)
        if tried is not None and str(tried) != path:
            reason = f"{reason} (tried {str(tried)!r})"
        raise DescriptionError(f"{what} names {path!r}, which cannot be read: {reason}") from None


def _read_or_say_why(read: FileReader | None, path: str) -> bytes:
    """``read(path)``; a file that cannot be read raises why, with the path tried.

    Raises:
        DescriptionError: Why the file cannot be read (no reader, the reader's
            refusal, the system's error and the file tried).
    """
    if read is None:
        raise DescriptionError("no file was given with the model")
    try:
        return read(path)
    except DescriptionError:
        raise
    except OSError as exc:
        reason = exc.strerror or str(exc)
        tried = f" (tried {str(exc.filename)!r})" if exc.filename is not None else ""
        raise DescriptionError(f"{reason}{tried}") from None
    except (KeyError, ValueError) as exc:
        raise DescriptionError(str(exc)) from None


def _inline_includes(
    element: ET.Element,
    read: FileReader | None,
    depth: int,
    chain: tuple[str, ...],
    level: int,
    elements: list[int],
) -> None:
    """Replace each ``<include>`` under ``element`` (at nesting ``level``) by the file's children.

    ``elements`` holds the count of elements so far, includes inlined: the same file
    included many times (and including others) grows the document by each copy.

    Raises:
        DescriptionError: As :func:`expand_mjcf`.
        DescriptionLimitError: The inlined document would nest deeper than
            :data:`MAX_XML_DEPTH` or hold more than :data:`MAX_XML_ELEMENTS` elements.
    """
    for index, child in enumerate(list(element)):
        if child.tag != "include":
            _inline_includes(child, read, depth, chain, level + 1, elements)
            continue
        path = posixpath.normpath(child.get("file", ""))
        if path in chain or depth >= MAX_INCLUDE_DEPTH:
            raise DescriptionError(f"<include> chain {' → '.join((*chain, path))} does not end")
        included = _parse_xml(_read(read, path, "<include file>"), f"included file {path!r}")
        if included.tag != "mujoco":
            raise DescriptionError(f"included file {path!r} must have a <mujoco> root element")
        elements[0] += _count_elements(included)
        if elements[0] > MAX_XML_ELEMENTS:
            raise DescriptionLimitError(
                f"the model has more than {MAX_XML_ELEMENTS} XML elements, its includes inlined"
            )
        if level + _xml_depth(included) - 1 > MAX_XML_DEPTH:
            raise DescriptionLimitError(
                f"the model nests XML elements more than {MAX_XML_DEPTH} deep, its includes "
                f"inlined (at {path!r})"
            )
        # The included root's children take the <include>'s place, one level below element.
        _inline_includes(included, read, depth + 1, (*chain, path), level, elements)
        element.remove(child)
        for offset, grandchild in enumerate(list(included)):
            element.insert(index + offset, grandchild)
        # The inserted children were expanded above; the loop goes on with the originals.


def compile_mjcf(
    text: bytes | str, read: FileReader | None
) -> tuple[mujoco.MjSpec, mujoco.MjModel]:
    """The MJCF, includes and assets resolved (:func:`expand_mjcf`), parsed and compiled by MuJoCo.

    Returns:
        The spec (for a simulator's edits before its own compile) and the model.

    Raises:
        DescriptionError: :func:`expand_mjcf`'s, or MuJoCo's message on one line.
    """
    xml, assets, paths = _expand_mjcf(text, read)
    try:
        spec = mujoco.MjSpec.from_string(xml, assets=assets)
        return spec, spec.compile()
    except ValueError as exc:
        detail = _mujoco_message(exc, paths)
        raise DescriptionError(f"MuJoCo could not compile the model: {detail}") from None


# -- the description ---------------------------------------------------------------------


@dataclass(frozen=True)
class FoundContact:
    """A support: a frame of the model and the corners of its sole in that frame (m).

    Attributes:
        name: Contact name on the wire, e.g. ``left_foot``.
        frame: The frame the points are in (a body's or a site's).
        points_in_frame: ``(k, 3)`` sole corners in the frame (m).
        friction_coefficient: Coulomb μ.
        reason: Why this contact, for a person (``poise inspect``).
    """

    name: str
    frame: str
    points_in_frame: np.ndarray
    friction_coefficient: float = 0.8
    reason: str = ""


@dataclass(frozen=True)
class Body:
    """A rigid body of the robot: its Pinocchio frame, parent body and collision points.

    Attributes:
        name: Body (MJCF) or link (URDF) name; its Pinocchio frame's name.
        parent: Index of the parent body in :attr:`RobotDescription.bodies` (−1: the root).
        frame_id: Pinocchio frame of the body.
        collision_points: ``(k, 3)`` points of its collision geometry in the
            body frame (m): box and mesh vertices, cylinder rims, ellipsoid
            extremes along their axes, and the centres of spheres and of
            capsules' end spheres.
        collision_radii: ``(k,)`` radius around each point (m): a sphere's or
            capsule's radius, 0 for a vertex. The lowest point of a round
            shape is its centre less its radius along the world's z.
    """

    name: str
    parent: int
    frame_id: int
    collision_points: np.ndarray
    collision_radii: np.ndarray

    @classmethod
    def with_shapes(cls, name: str, parent: int, frame_id: int, shapes: list[np.ndarray]) -> Body:
        """A body whose collision geometry is ``(k, 4)`` blocks of points and radii."""
        stacked = np.vstack(shapes) if shapes else np.zeros((0, 4))
        return cls(name, parent, frame_id, stacked[:, :3], stacked[:, 3])


@dataclass(frozen=True)
class RobotDescription:
    """What Poise reads from a robot file (see the module docstring).

    Attributes:
        name: Model name.
        format: ``"mjcf"`` or ``"urdf"``.
        model: Pinocchio model, joint 1 the free-flyer root with an identity placement.
        bodies: The robot's bodies (root first, parents before children).
        contacts: Supports in ``contact_flags`` order.
        torque_limit: ``(nv − 6,)`` symmetric limits (N·m, N; ``inf``: none stated).
        actuator_kind: Joint name → ``motor``, ``position``, ``velocity``,
            ``general`` (MJCF), ``effort`` (URDF) or ``none``.
        ball_swing_limit: Ball joint name → largest swing (rad; π where unlimited).
        standing_configuration: Pinocchio ``q`` of the standing pose, soles at z = 0.
        keyframes: Names of the file's keyframes.
        keyframe: The keyframe the standing pose comes from (``None``: the file's pose).
        contacts_source: Where the contacts come from: ``given``, ``sole sites``
            or ``collision geometry``.
        warnings: What a user should know (unactuated joints, converted actuators …).
        disabled_collision_pairs: Pairs of body names whose collisions a simulator
            must not simulate (an SRDF's ``disable_collisions``), each pair sorted.
    """

    name: str
    format: str
    model: pin.Model
    bodies: tuple[Body, ...]
    contacts: tuple[FoundContact, ...]
    torque_limit: np.ndarray
    actuator_kind: dict[str, str]
    ball_swing_limit: dict[str, float]
    standing_configuration: np.ndarray
    keyframes: tuple[str, ...]
    keyframe: str | None
    contacts_source: str
    warnings: tuple[str, ...] = field(default=())
    disabled_collision_pairs: tuple[tuple[str, str], ...] = field(default=())

    @property
    def joint_names(self) -> list[str]:
        """Actuated joints in wire (Pinocchio) order."""
        return list(self.model.names[2:])

    @property
    def total_mass(self) -> float:
        """Total mass (kg)."""
        return float(sum(inertia.mass for inertia in self.model.inertias))


@dataclass
class _Draft:
    """What a format's reader gives :func:`describe` to finish."""

    model: pin.Model
    bodies: list[Body]
    torque_limit: np.ndarray
    actuator_kind: dict[str, str]
    ball_swing_limit: dict[str, float]
    configuration: np.ndarray
    keyframes: dict[str, np.ndarray]
    sole_sites: list[FoundContact]
    warnings: list[str]
    unreadable_meshes: list[_UnreadableMesh] = field(default_factory=list)
    disabled_collision_pairs: tuple[tuple[str, str], ...] = ()


def describe(
    text: bytes | str,
    fmt: str = "mjcf",
    *,
    read: FileReader | None = None,
    name: str = "robot",
    contacts: Sequence[ContactSpec] | None = None,
    keyframe: str | None = None,
) -> RobotDescription:
    """Read a robot file (see the module docstring).

    Args:
        text: The main MJCF or URDF file.
        fmt: ``"mjcf"`` or ``"urdf"``.
        read: Reads the files the model names (includes, meshes), relative to
            the main file's directory.
        name: Model name.
        contacts: Contacts to use instead of the found ones; one without
            points gets its sole found from its frame's body.
        keyframe: Keyframe whose pose is the standing pose (MJCF ``<key>``; URDF:
            its SRDF's ``group_state``).

    Raises:
        DescriptionError: What to change, on one line.
    """
    draft = _read_urdf(text, read, name) if fmt == "urdf" else _read_mjcf(text, read)
    model = draft.model
    model.name = name
    if keyframe is not None:
        if keyframe not in draft.keyframes:
            known = ", ".join(draft.keyframes) or "none"
            where = (
                " (a URDF's keyframes are its SRDF's group_states: "
                f"{' or '.join(srdf_paths(text)) or 'NAME.srdf'} beside it, or --srdf FILE)"
                if fmt == "urdf"
                else ""
            )
            raise DescriptionError(
                f"no keyframe {keyframe!r} in the model; keyframes: {known}{where}",
                field="keyframe",
            )
        draft.configuration = draft.keyframes[keyframe].copy()
    q = draft.configuration
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    if draft.unreadable_meshes:
        _check_unreadable_meshes(draft, data, contacts, model)
    if contacts is not None:
        found = [_named_contact(spec, model, data, draft.bodies) for spec in contacts]
        source = "given"
    elif draft.sole_sites:
        found, source = draft.sole_sites, "sole sites"
    else:
        found, source = _find_feet(model, data, draft.bodies), "collision geometry"
    if not found:
        raise DescriptionError("no contacts: name the feet (`contacts`)", field="contacts")
    _check_contacts(found, source)
    draft.warnings += [
        f"contact {c.name!r} touches at {len(c.points_in_frame)} point(s) in the standing pose, "
        "too few to balance on alone: give its points, or a keyframe with the foot flat"
        for c in found
        if source == "collision geometry" and len(c.points_in_frame) < 3
    ]
    lowest = min(
        float(_to_world(data.oMf[model.getFrameId(c.frame)], c.points_in_frame)[:, 2].min())
        for c in found
    )
    q[2] -= lowest
    q.setflags(write=False)
    draft.torque_limit.setflags(write=False)
    return RobotDescription(
        name=name,
        format=fmt,
        model=model,
        bodies=tuple(draft.bodies),
        contacts=tuple(found),
        torque_limit=draft.torque_limit,
        actuator_kind=draft.actuator_kind,
        ball_swing_limit=draft.ball_swing_limit,
        standing_configuration=q,
        keyframes=tuple(draft.keyframes),
        keyframe=keyframe,
        contacts_source=source,
        warnings=tuple(draft.warnings),
        disabled_collision_pairs=draft.disabled_collision_pairs,
    )


def _check_contacts(found: Sequence[FoundContact], source: str) -> None:
    """Refuse more contacts or points than a session may have (``protocol.messages``' caps).

    Raises:
        DescriptionLimitError: Over :data:`~protocol.messages.MAX_CONTACTS`,
            :data:`~protocol.messages.MAX_POINTS_PER_CONTACT` or
            :data:`~protocol.messages.MAX_CONTACT_POINTS`.
    """
    where = f"(contacts from the {source})" if source != "given" else ""
    if len(found) > MAX_CONTACTS:
        raise DescriptionLimitError(
            f"{len(found)} contacts {where}; at most {MAX_CONTACTS}: name the feet (`contacts`)",
            field="contacts",
        )
    for contact in found:
        if len(contact.points_in_frame) > MAX_POINTS_PER_CONTACT:
            raise DescriptionLimitError(
                f"contact {contact.name[:100]!r} has {len(contact.points_in_frame)} points; at "
                f"most {MAX_POINTS_PER_CONTACT}",
                field="contacts",
            )
    total = sum(len(contact.points_in_frame) for contact in found)
    if total > MAX_CONTACT_POINTS:
        raise DescriptionLimitError(
            f"the contacts have {total} points together {where}; at most {MAX_CONTACT_POINTS}",
            field="contacts",
        )


def foot_candidates(model: pin.Model, data: pin.Data, bodies: Sequence[Body]) -> list[str]:
    """The bodies that may be feet, whatever their collision geometry: the lowest frames.

    A body whose frame, at the pose of ``data``, is within
    :data:`FOOT_CANDIDATE_HEIGHT_FRACTION` of the span between the lowest and
    the highest body frame above the lowest one: ankles, feet, soles, toes.
    """
    heights = np.array([data.oMf[b.frame_id].translation[2] for b in bodies])
    limit = heights.min() + FOOT_CANDIDATE_HEIGHT_FRACTION * (heights.max() - heights.min())
    return [b.name for b, z in zip(bodies, heights, strict=True) if z <= limit + 1e-9]


def _check_unreadable_meshes(
    draft: _Draft, data: pin.Data, contacts: Sequence[ContactSpec] | None, model: pin.Model
) -> None:
    """Refuse an unreadable collision mesh where a sole is looked for; summarise the others.

    Where a sole is looked for: on a :func:`foot_candidates` body when the feet
    are found from the collision geometry, and on a named contact's body and
    its descendants when its points are not given.

    Raises:
        DescriptionError: The first unreadable mesh where a sole is looked for:
            its file, why (the path tried), and what to do.
    """
    bodies = draft.bodies
    if contacts is None:
        looked_at = set(foot_candidates(model, data, bodies)) if not draft.sole_sites else set()
        why = "a foot candidate: one of the lowest links standing"
    else:
        looked_at = set()
        for spec in contacts:
            if spec.points_in_frame is None and model.existFrame(spec.frame):
                top = _body_of_frame(model, bodies, model.getFrameId(spec.frame))
                if top is not None:
                    looked_at |= {bodies[i].name for i in subtree(bodies, top)}
        why = "part of a named foot"
    for mesh in draft.unreadable_meshes:
        if mesh.link in looked_at:
            scheme, _, rest = mesh.filename.partition("://")
            todo = (
                f"set ROS_PACKAGE_PATH to a directory that holds package {rest.split('/')[0]!r}"
                if scheme == "package" and rest
                else "make the file readable"
            )
            raise DescriptionError(
                f"the collision mesh {mesh.filename!r} of link {mesh.link!r} ({why}) cannot be "
                f"read: {mesh.reason}; {todo}, or name feet whose meshes can be read "
                "(--contacts) or give their points (`contacts` with `points_in_frame`)"
            )
    first = draft.unreadable_meshes[0]
    count = len({mesh.filename for mesh in draft.unreadable_meshes})
    draft.warnings.append(
        f"{count} collision mesh file(s) cannot be read and are left out, e.g. "
        f"{first.filename!r} of link {first.link!r}: {first.reason}"
    )


def _read_mjcf(text: bytes | str, read: FileReader | None) -> _Draft:
    _, mj = compile_mjcf(text, read)
    _check_size(mj.nbody, mj.nv, "bodies")
    root = _robot_root(mj)
    builder = _PinocchioFromMujoco(mj, root)
    model = builder.model
    torque_limit, kinds, warnings = _mjcf_actuation(mj, model, builder.joints)
    return _Draft(
        model=model,
        bodies=builder.bodies,
        torque_limit=torque_limit,
        actuator_kind=kinds,
        ball_swing_limit={
            mj.joint(j).name: float(mj.jnt_range[j, 1]) if mj.jnt_limited[j] else np.pi
            for j in builder.joints
            if mj.jnt_type[j] == _BALL
        },
        configuration=builder.configuration(mj.qpos0),
        keyframes={
            mj.key(k).name or f"key{k}": builder.configuration(mj.key_qpos[k])
            for k in range(mj.nkey)
        },
        sole_sites=builder.sole_sites(),
        warnings=warnings,
    )


def _check_size(bodies: int, dofs: int, what: str) -> None:
    """Refuse a model of more than :data:`MAX_BODIES` bodies or :data:`MAX_DOF` DoF.

    Raises:
        DescriptionLimitError: Over either cap.
    """
    if bodies > MAX_BODIES:
        raise DescriptionLimitError(f"the model has {bodies} {what}; at most {MAX_BODIES}")
    if dofs > MAX_DOF:
        raise DescriptionLimitError(
            f"the model has {dofs} degrees of freedom (nv, the free base's 6 included); at "
            f"most {MAX_DOF}"
        )


def _robot_root(mj: mujoco.MjModel) -> int:
    """The body under the world that is the robot: the one with a free joint, else the most DoFs.

    Raises:
        DescriptionError: No body has a joint, or several have free joints.
    """
    roots = [b for b in range(1, mj.nbody) if mj.body_parentid[b] == 0]
    free = [b for b in roots if any(mj.jnt_type[j] == _FREE for j in _body_joints(mj, b))]
    if len(free) > 1:
        names = ", ".join(mj.body(b).name or f"body{b}" for b in free)
        raise DescriptionError(
            f"several bodies have a free joint ({names}); Poise controls one robot per model"
        )
    if free:
        return free[0]
    dofs = {
        b: int(sum(mj.body_dofnum[d] for d in range(mj.nbody) if mj.body_rootid[d] == b))
        for b in roots
    }
    if not dofs or max(dofs.values()) == 0:
        raise DescriptionError("the model has no body with joints under <worldbody>")
    return max(dofs, key=lambda b: dofs[b])


def _body_joints(mj: mujoco.MjModel, body: int) -> range:
    start = int(mj.body_jntadr[body])
    return range(start, start + int(mj.body_jntnum[body])) if start >= 0 else range(0)


def _se3(position: np.ndarray, quaternion_wxyz: np.ndarray) -> pin.SE3:
    w, x, y, z = quaternion_wxyz
    return pin.SE3(pin.Quaternion(w, x, y, z).normalized().matrix(), np.array(position, float))


class _PinocchioFromMujoco:
    """Builds a Pinocchio model from a compiled MuJoCo model, body by body.

    A MuJoCo joint at anchor ``p`` of its body (axis in the body frame) moves
    the body by ``T(p) · motion · T(−p)``; several joints of one body chain in
    document order. Each becomes a Pinocchio joint placed at ``T(p)``
    (relative to the previous joint of the chain: ``T(−p_prev) T(p)``), and
    the body — inertia, frame, sites — hangs from the last one at ``T(−p)``.
    Bodies without joints are welded to their parent's joint.

    Frames are looked up by name, and MuJoCo keeps bodies, joints and sites
    in separate namespaces (a free joint ``root`` on a body ``root``): a
    body's frame takes its name, a site's or a joint's only where no body
    (nor, for a joint, a site) has it.
    """

    def __init__(self, mj: mujoco.MjModel, root: int):
        self.mj = mj
        self.model = pin.Model()
        self.joints: list[int] = []  # MuJoCo joint ids in Pinocchio order (free root excluded)
        self.bodies: list[Body] = []
        self._body_index: dict[int, int] = {}
        self._placement: dict[int, tuple[int, pin.SE3]] = {}  # body → (pin joint, body in joint)
        self._site_frames: list[tuple[int, int]] = []  # (site id, frame id)
        self.root = root
        self._body_names = {mj.body(b).name for b in range(mj.nbody)}
        self._taken = self._body_names | {mj.site(s).name for s in range(mj.nsite)}
        gravity = mj.opt.gravity
        self.model.gravity = pin.Motion(np.array(gravity, float), np.zeros(3))
        free = [j for j in _body_joints(mj, root) if mj.jnt_type[j] == _FREE]
        self.root_pose = _se3(mj.body_pos[root], mj.body_quat[root])
        self._free_qpos = int(mj.jnt_qposadr[free[0]]) if free else None
        joint_name = mj.joint(free[0]).name if free and mj.joint(free[0]).name else "root_joint"
        joint = self.model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), joint_name)
        self._add_joint_frame(joint)
        self._add_body(root, joint, pin.SE3.Identity(), skip_free=True)
        for body in range(root + 1, mj.nbody):
            if mj.body_rootid[body] == root:
                parent_joint, parent_in_joint = self._placement[int(mj.body_parentid[body])]
                offset = _se3(mj.body_pos[body], mj.body_quat[body])
                self._add_body(body, parent_joint, parent_in_joint * offset, skip_free=False)

    def _add_joint_frame(self, joint: int) -> None:
        if self.model.names[joint] not in self._taken:
            self.model.addJointFrame(joint, 0)

    def _add_body(self, body: int, joint: int, body_in_joint: pin.SE3, *, skip_free: bool) -> None:
        mj, model = self.mj, self.model
        anchor = np.zeros(3)
        for j in _body_joints(mj, body):
            kind = int(mj.jnt_type[j])
            if kind == _FREE:
                if skip_free:
                    continue
                raise DescriptionError(f"free joint {mj.joint(j).name!r} is not on the root body")
            placement = (
                body_in_joint * pin.SE3(np.eye(3), -anchor) * pin.SE3(np.eye(3), mj.jnt_pos[j])
            )
            name = mj.joint(j).name
            if not name:
                raise DescriptionError(
                    f"a joint of body {mj.body(body).name!r} has no name; name every joint"
                )
            joint = model.addJoint(joint, _joint_model(kind, mj.jnt_axis[j]), placement, name)
            self._add_joint_frame(joint)
            v = model.joints[joint].idx_v
            model.armature[v : v + model.joints[joint].nv] = mj.dof_armature[
                mj.jnt_dofadr[j] : mj.jnt_dofadr[j] + model.joints[joint].nv
            ]
            if kind in (_HINGE, _SLIDE):
                limited = bool(mj.jnt_limited[j])
                q = model.joints[joint].idx_q
                model.lowerPositionLimit[q] = mj.jnt_range[j, 0] if limited else -np.inf
                model.upperPositionLimit[q] = mj.jnt_range[j, 1] if limited else np.inf
            self.joints.append(j)
            anchor = np.array(mj.jnt_pos[j], float)
            body_in_joint = pin.SE3.Identity()
        body_in_joint = body_in_joint * pin.SE3(np.eye(3), -anchor)
        rotation = pin.Quaternion(*mj.body_iquat[body]).normalized().matrix()
        inertia = pin.Inertia(
            float(mj.body_mass[body]),
            np.array(mj.body_ipos[body], float),
            rotation @ np.diag(mj.body_inertia[body]) @ rotation.T,
        )
        model.appendBodyToJoint(joint, inertia, body_in_joint)
        name = mj.body(body).name or f"body{body}"
        parent = self._body_index.get(int(mj.body_parentid[body]), -1)
        parent_frame = self.bodies[parent].frame_id if parent >= 0 else 0
        frame = model.addBodyFrame(name, joint, body_in_joint, parent_frame)
        for site in map(int, np.flatnonzero(mj.site_bodyid == body)):
            site_name = mj.site(site).name
            if site_name and site_name not in self._body_names:
                placement = body_in_joint * _se3(mj.site_pos[site], mj.site_quat[site])
                frame_id = model.addFrame(
                    pin.Frame(mj.site(site).name, joint, frame, placement, pin.OP_FRAME)
                )
                self._site_frames.append((site, frame_id))
        self._placement[body] = (joint, body_in_joint)
        self._body_index[body] = len(self.bodies)
        self.bodies.append(Body.with_shapes(name, parent, frame, _geom_shapes(mj, body)))

    def configuration(self, qpos: np.ndarray) -> np.ndarray:
        """Pinocchio ``q`` from a MuJoCo ``qpos`` (base from the free joint, or the body's pose)."""
        mj, model = self.mj, self.model
        q = np.zeros(model.nq)
        if self._free_qpos is None:
            q[:3] = self.root_pose.translation
            q[3:7] = pin.Quaternion(self.root_pose.rotation).coeffs()
        else:
            a = self._free_qpos
            q[:3] = qpos[a : a + 3]
            w, x, y, z = qpos[a + 3 : a + 7]
            q[3:7] = (x, y, z, w)
        for pin_joint, j in enumerate(self.joints, start=2):
            idx, a = model.joints[pin_joint].idx_q, int(mj.jnt_qposadr[j])
            if mj.jnt_type[j] == _BALL:
                w, x, y, z = qpos[a : a + 4]
                q[idx : idx + 4] = (x, y, z, w)
            else:
                q[idx] = qpos[a]
        for start in [
            3,
            *(model.joints[i].idx_q for i in range(2, model.njoints) if model.joints[i].nq == 4),
        ]:
            q[start : start + 4] /= np.linalg.norm(q[start : start + 4])
        return q

    def sole_sites(self) -> list[FoundContact]:
        """Contacts from ``*_sole`` box sites: the four corners of their x–y rectangle."""
        mj = self.mj
        found = []
        for site, _ in self._site_frames:
            name = mj.site(site).name
            if name.endswith("_sole") and mj.site_type[site] == _GEOM.mjGEOM_BOX:
                half_x, half_y = mj.site_size[site, :2]
                corners = [(sx * half_x, sy * half_y, 0.0) for sx in (1, -1) for sy in (1, -1)]
                found.append(
                    FoundContact(
                        name.removesuffix("_sole") + "_foot",
                        name,
                        np.array(corners),
                        reason=f"the corners of the box site {name!r}",
                    )
                )
        return found


def _joint_model(kind: int, axis: np.ndarray) -> pin.JointModel:
    if kind == _BALL:
        return pin.JointModelSpherical()
    unit = tuple(float(round(a, 12)) for a in axis)
    letter = _UNIT_AXES.get(unit)
    if kind == _HINGE:
        return (
            getattr(pin, f"JointModelR{letter}")()
            if letter
            else pin.JointModelRevoluteUnaligned(np.array(axis, float))
        )
    return (
        getattr(pin, f"JointModelP{letter}")()
        if letter
        else pin.JointModelPrismaticUnaligned(np.array(axis, float))
    )


def _geom_shapes(mj: mujoco.MjModel, body: int) -> list[np.ndarray]:
    """Points and radii (``(k, 4)`` each) of a body's colliding geoms, in the body frame."""
    shapes = []
    for geom in map(int, np.flatnonzero(mj.geom_bodyid == body)):
        if not (mj.geom_contype[geom] or mj.geom_conaffinity[geom]):
            continue
        local = _shape_points(int(mj.geom_type[geom]), mj.geom_size[geom], _mesh_vertices(mj, geom))
        if local is not None:
            shapes.append(_placed(local, _se3(mj.geom_pos[geom], mj.geom_quat[geom])))
    return shapes


def _placed(shape: np.ndarray, placement: pin.SE3) -> np.ndarray:
    """``(k, 4)`` points and radii in a shape's frame → in the frame it is placed in."""
    return np.column_stack([_to_world(placement, shape[:, :3]), shape[:, 3]])


def _mesh_vertices(mj: mujoco.MjModel, geom: int) -> np.ndarray | None:
    mesh = int(mj.geom_dataid[geom])
    if mj.geom_type[geom] != _GEOM.mjGEOM_MESH or mesh < 0:
        return None
    start, count = int(mj.mesh_vertadr[mesh]), int(mj.mesh_vertnum[mesh])
    return np.array(mj.mesh_vert[start : start + count], float)


def _shape_points(kind: int, size: np.ndarray, vertices: np.ndarray | None) -> np.ndarray | None:
    """A primitive as ``(k, 4)`` points and radii in its frame (``None``: a plane, a height field).

    Boxes and meshes: their vertices; cylinders: 16 points on each rim;
    ellipsoids: their extremes along their axes; spheres: the centre with the
    radius; capsules: both end spheres.
    """
    rim = np.array(
        [(np.cos(a), np.sin(a), 0.0) for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)]
    )
    if kind == _GEOM.mjGEOM_BOX:
        signs = np.array([(sx, sy, sz) for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)])
        points = signs * size
    elif kind == _GEOM.mjGEOM_ELLIPSOID:
        points = np.vstack([np.eye(3), -np.eye(3)]) * size[:3]
    elif kind == _GEOM.mjGEOM_CYLINDER:
        points = np.vstack([rim * size[0] + (0, 0, h) for h in (size[1], -size[1])])
    elif kind == _GEOM.mjGEOM_MESH and vertices is not None:
        points = vertices
    elif kind == _GEOM.mjGEOM_SPHERE:
        return np.array([[0.0, 0.0, 0.0, size[0]]])
    elif kind == _GEOM.mjGEOM_CAPSULE:
        return np.array([[0.0, 0.0, size[1], size[0]], [0.0, 0.0, -size[1], size[0]]])
    else:
        return None
    return np.column_stack([points, np.zeros(len(points))])


def _mjcf_actuation(
    mj: mujoco.MjModel, model: pin.Model, joints: list[int]
) -> tuple[np.ndarray, dict[str, str], list[str]]:
    """Torque limits per DoF, actuator kind per joint, and warnings (see the module docstring)."""
    limit = np.zeros(model.nv)
    actuated = np.zeros(model.nv, dtype=bool)
    pin_joint = {j: model.getJointId(mj.joint(j).name) for j in joints}
    kinds: dict[str, str] = {mj.joint(j).name: "none" for j in joints}
    for actuator in range(mj.nu):
        j = int(mj.actuator_trnid[actuator, 0])
        if mj.actuator_trntype[actuator] != _TRN_JOINT or j not in pin_joint:
            continue
        kind = _actuator_kind(mj, actuator)
        name = mj.joint(j).name
        kinds[name] = kind if kinds[name] in ("none", kind) else "general"
        bound = np.inf
        if mj.actuator_forcelimited[actuator]:
            bound = float(np.abs(mj.actuator_forcerange[actuator]).max())
        if kind == "motor" and mj.actuator_ctrllimited[actuator]:
            gain = abs(float(mj.actuator_gainprm[actuator, 0]))
            bound = min(bound, gain * float(np.abs(mj.actuator_ctrlrange[actuator]).max()))
        joint = model.joints[pin_joint[j]]
        gear = np.abs(mj.actuator_gear[actuator, : joint.nv])
        dofs = slice(joint.idx_v, joint.idx_v + joint.nv)
        limit[dofs] += np.where(gear > 0, bound * gear, 0.0)
        actuated[dofs] |= gear > 0
    limit[~actuated] = np.inf
    for j, pin_id in pin_joint.items():
        if mj.jnt_actfrclimited[j]:
            joint = model.joints[pin_id]
            dofs = slice(joint.idx_v, joint.idx_v + joint.nv)
            limit[dofs] = np.minimum(limit[dofs], np.abs(mj.jnt_actfrcrange[j]).max())
    warnings = [f"joint {name!r} has no actuator" for name, kind in kinds.items() if kind == "none"]
    return limit[6:], kinds, warnings


def _actuator_kind(mj: mujoco.MjModel, actuator: int) -> str:
    """``motor`` (gain · ctrl), ``position`` (−kp q bias), ``velocity`` (−kv q̇), ``general``."""
    gain_type, bias_type = int(mj.actuator_gaintype[actuator]), int(mj.actuator_biastype[actuator])
    bias = mj.actuator_biasprm[actuator]
    if gain_type != _GAIN_FIXED or mj.actuator_dyntype[actuator] != 0:
        return "general"
    if bias_type == _BIAS_NONE:
        return "motor"
    if bias_type == _BIAS_AFFINE and bias[0] == 0 and bias[1] < 0:
        return "position"
    if bias_type == _BIAS_AFFINE and bias[0] == 0 and bias[1] == 0 and bias[2] < 0:
        return "velocity"
    return "general"


# -- URDF through Pinocchio --------------------------------------------------------------


def _read_urdf(text: bytes | str, read: FileReader | None, name: str) -> _Draft:
    root = _parse_xml(text, "the URDF")
    if root.tag != "robot":
        raise DescriptionError(f"a URDF file's root element is <robot>, not <{root.tag}>")
    _check_size(len(root.findall("link")), 0, "links")
    try:
        model = pin.buildModelFromXML(
            text.decode() if isinstance(text, bytes) else text, pin.JointModelFreeFlyer()
        )
    except (RuntimeError, ValueError, IndexError) as exc:
        message = str(exc).partition("message:")[2] or str(exc)
        raise DescriptionError(
            f"Pinocchio could not parse the URDF {name!r}: {' '.join(message.split())}"
        ) from None
    _check_size(len(root.findall("link")), model.nv, "links")
    read = _counting(read)
    root_offset = model.jointPlacements[1].copy()
    model.jointPlacements[1] = pin.SE3.Identity()
    torque_limit = np.asarray(model.effortLimit[6:], dtype=float).copy()
    torque_limit[torque_limit <= 0] = np.inf
    model.effortLimit[6:] = torque_limit
    links = {link.get("name", ""): link for link in root.iter("link")}
    parents = {
        j.find("child").get("link"): j.find("parent").get("link")
        for j in root.iter("joint")
        if j.find("child") is not None and j.find("parent") is not None
    }
    order = [f.name for f in model.frames if f.type == pin.BODY and f.name in links]
    warnings: list[str] = []
    unreadable: list[_UnreadableMesh] = []
    bodies: list[Body] = []
    for name in order:
        shapes = []
        for collision in links[name].findall("collision"):
            shape, problem = _urdf_collision_shape(collision, read)
            if problem is not None:
                unreadable.append(_UnreadableMesh(name, *problem))
            if shape is not None:
                shapes.append(shape)
        parent_name = parents.get(name)
        parent = next((i for i, b in enumerate(bodies) if b.name == parent_name), -1)
        bodies.append(Body.with_shapes(name, parent, model.getFrameId(name, pin.BODY), shapes))
    q = pin.neutral(model)
    q[:3] = root_offset.translation
    q[3:7] = pin.Quaternion(root_offset.rotation).coeffs()
    kinds = {
        model.names[i]: "effort" if np.isfinite(torque_limit[model.joints[i].idx_v - 6]) else "none"
        for i in range(2, model.njoints)
    }
    warnings += [
        f"joint {name!r} has no <limit effort>" for name, kind in kinds.items() if kind == "none"
    ]
    keyframes: dict[str, np.ndarray] = {}
    disabled: tuple[tuple[str, str], ...] = ()
    found = _find_srdf(root, read)
    if found is not None:
        keyframes, disabled, srdf_warnings = _read_srdf(*found, root, model, q)
        warnings += srdf_warnings
    draft = _Draft(model, bodies, torque_limit, kinds, {}, q, keyframes, [], warnings)
    draft.unreadable_meshes = unreadable
    draft.disabled_collision_pairs = disabled
    return draft


def _counting(read: FileReader | None) -> FileReader | None:
    """``read``, refusing once the bytes it returned exceed :data:`MAX_ASSET_BYTES`.

    A URDF names a mesh once per collision element, and each naming is loaded by MuJoCo.
    """
    if read is None:
        return None
    cost = _Cost()

    def counted(path: str) -> bytes:
        data = read(path)
        cost.add_file(path, data, 1)
        return data

    return counted


@dataclass(frozen=True)
class _UnreadableMesh:
    """A URDF collision mesh left out: its link, ``filename`` as written, and why."""

    link: str
    filename: str
    reason: str


def _urdf_collision_shape(
    collision: ET.Element, read: FileReader | None
) -> tuple[np.ndarray | None, tuple[str, str] | None]:
    """A URDF ``<collision>``'s points and radii in its link frame (meshes read by MuJoCo).

    Returns:
        The shape (``None``: none, or an unreadable mesh), and for an unreadable
        mesh its ``filename`` and why it cannot be read.
    """
    origin = collision.find("origin")
    xyz = np.array((origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split(), float)
    rpy = np.array((origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split(), float)
    rotation = pin.rpy.rpyToMatrix(*rpy)
    geometry = collision.find("geometry")
    shape = None if geometry is None or len(geometry) == 0 else geometry[0]
    if shape is None:
        return None, None

    def numbers(key: str) -> np.ndarray:
        return np.array(shape.get(key, "1 1 1").split(), float)

    if shape.tag == "box":
        local = _shape_points(_GEOM.mjGEOM_BOX, numbers("size") / 2, None)
    elif shape.tag == "sphere":
        local = _shape_points(_GEOM.mjGEOM_SPHERE, np.array([float(shape.get("radius", 0))]), None)
    elif shape.tag == "cylinder":
        radius, length = float(shape.get("radius", 0)), float(shape.get("length", 0))
        local = _shape_points(_GEOM.mjGEOM_CYLINDER, np.array([radius, length / 2]), None)
    elif shape.tag == "mesh":
        try:
            local = _urdf_mesh_points(shape, read)
        except DescriptionLimitError:
            raise
        except DescriptionError as exc:
            return None, (shape.get("filename", ""), str(exc))
    else:
        return None, None
    return (None if local is None else _placed(local, pin.SE3(rotation, xyz))), None


def _urdf_mesh_points(mesh: ET.Element, read: FileReader | None) -> np.ndarray | None:
    """A URDF mesh's vertices (scaled, own frame), loaded by MuJoCo.

    Raises:
        DescriptionError: The file cannot be read, or MuJoCo cannot load it.
    """
    filename = mesh.get("filename", "")
    key = f"mesh{_safe_suffix(filename)}"  # the file's name never reaches MuJoCo's parser
    data = _read_or_say_why(read, filename)
    try:
        # Numbers only into the XML: the URDF's text never reaches MuJoCo's parser.
        scale = " ".join(repr(float(x)) for x in mesh.get("scale", "1 1 1").split()[:3])
        xml = (
            f'<mujoco><asset><mesh name="m" file="{key}" scale="{scale}"/></asset>'
            '<worldbody><geom type="mesh" mesh="m"/></worldbody></mujoco>'
        )
        mj = mujoco.MjSpec.from_string(xml, assets={key: data}).compile()
    except ValueError as exc:
        detail = _mujoco_message(exc, {key: filename})
        raise DescriptionError(f"MuJoCo cannot load {filename!r}: {detail}") from None
    shape = _shape_points(_GEOM.mjGEOM_MESH, np.zeros(3), _mesh_vertices(mj, 0))
    return None if shape is None else _placed(shape, _se3(mj.geom_pos[0], mj.geom_quat[0]))


# -- SRDF: keyframes and disabled collisions ---------------------------------------------


def srdf_paths(urdf: bytes | str | ET.Element) -> list[str]:
    """Where a URDF's SRDF is looked for, in order, by the names its reader is asked for.

    For ``<robot name="N">``: ``N.srdf`` beside the URDF, then
    ``../srdf/N.srdf`` (example-robot-data's ``robots/`` and ``srdf/``
    directories). A reader may serve another file under the first name
    (``poise inspect --srdf FILE``). Empty for a robot without a name.
    """
    root = urdf if isinstance(urdf, ET.Element) else _parse_xml(urdf, "the URDF")
    name = (root.get("name") or "").strip()
    if not name or "/" in name or "\\" in name or name in (".", ".."):
        return []
    return [f"{name}.srdf", f"../srdf/{name}.srdf"]


def _find_srdf(root: ET.Element, read: FileReader | None) -> tuple[str, bytes] | None:
    """The first of :func:`srdf_paths` the reader serves, and its bytes (``None``: none)."""
    if read is None:
        return None
    for path in srdf_paths(root):
        try:
            return path, read(path)
        except (OSError, KeyError, ValueError):  # DescriptionError is a ValueError
            continue
    return None


def _read_srdf(
    path: str, text: bytes, urdf: ET.Element, model: pin.Model, neutral: np.ndarray
) -> tuple[dict[str, np.ndarray], tuple[tuple[str, str], ...], list[str]]:
    """An SRDF's keyframes (``group_state``) and ``disable_collisions`` pairs.

    Each ``group_state`` is a configuration: the URDF's neutral one with the
    named joints set; states of one name in several groups merge, in file
    order. Joints the URDF fixes and the SRDF's virtual joints carry no value
    and are passed over. ``disable_collisions`` pairs become sorted pairs of
    link names; pairs naming a link the URDF lacks are left out, with one
    warning.

    Raises:
        DescriptionError: Not XML, not ``<robot>``, a ``group_state`` naming a
            joint the URDF lacks, or a value that is not numbers of the joint's size.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise DescriptionError(f"the SRDF {path!r} is not valid XML: {exc}") from None
    if root.tag != "robot":
        raise DescriptionError(
            f"an SRDF file's root element is <robot>, not <{root.tag}> ({path!r})"
        )
    urdf_joints = {j.get("name", "") for j in urdf.iter("joint")}
    virtual = {j.get("name", "") for j in root.iter("virtual_joint")}
    links = {link.get("name", "") for link in urdf.iter("link")}
    keyframes: dict[str, np.ndarray] = {}
    for state in root.iter("group_state"):
        name = state.get("name", "")
        q = keyframes.setdefault(name, neutral.copy())
        for joint in state.iter("joint"):
            joint_name = joint.get("name", "")
            if model.existJointName(joint_name) and model.getJointId(joint_name) > 1:
                _set_joint(q, model, model.getJointId(joint_name), joint, name, path)
            elif joint_name not in urdf_joints and joint_name not in virtual:
                hint = did_you_mean(joint_name, model.names[2:]).rstrip()
                raise DescriptionError(
                    f"the SRDF {path!r}: group_state {name!r} sets joint {joint_name!r}, which "
                    f"the URDF does not have{'; ' + hint if hint else ''}"
                )
    pairs: set[tuple[str, str]] = set()
    unknown: list[str] = []
    for disabled in root.iter("disable_collisions"):
        pair = (disabled.get("link1", ""), disabled.get("link2", ""))
        missing = [link for link in pair if link not in links]
        if missing:
            unknown += [link for link in missing if link not in unknown]
        elif pair[0] != pair[1]:
            pairs.add(tuple(sorted(pair)))  # type: ignore[arg-type]
    warnings = []
    if unknown:
        warnings.append(
            f"the SRDF {path!r} disables collisions of {len(unknown)} link(s) the URDF does not "
            f"have ({', '.join(repr(u) for u in unknown[:3])}{', …' if len(unknown) > 3 else ''})"
            ": those pairs are ignored"
        )
    return keyframes, tuple(sorted(pairs)), warnings


def _set_joint(
    q: np.ndarray, model: pin.Model, joint_id: int, element: ET.Element, state: str, path: str
) -> None:
    """Set one joint of ``q`` from an SRDF ``<joint value>`` (a continuous joint: its angle)."""
    joint = model.joints[joint_id]
    try:
        values = [float(v) for v in element.get("value", "").split()]
    except ValueError:
        values = []
    size = 1 if joint.nq == 2 else joint.nq
    if len(values) != size:
        raise DescriptionError(
            f"the SRDF {path!r}: group_state {state!r} gives joint {model.names[joint_id]!r} "
            f"the value {element.get('value', '')!r}; write {size} number(s)"
        )
    if joint.nq == 2:  # continuous: cos, sin
        q[joint.idx_q : joint.idx_q + 2] = np.cos(values[0]), np.sin(values[0])
    else:
        q[joint.idx_q : joint.idx_q + joint.nq] = values


# -- contacts from geometry --------------------------------------------------------------


def subtree(bodies: Sequence[Body], top: int) -> list[int]:
    """Indices of body ``top`` and its descendants in ``bodies`` (parents before children)."""
    inside = [top]
    for index in range(top + 1, len(bodies)):
        if bodies[index].parent in inside:
            inside.append(index)
    return inside


def _to_world(placement: pin.SE3, points: np.ndarray) -> np.ndarray:
    """``(k, 3)`` points in a frame → in the world, given the frame's placement."""
    return points @ placement.rotation.T + placement.translation


def _lowest_points_in_world(data: pin.Data, body: Body) -> np.ndarray:
    """Each collision point's lowest point in the world: vertices, round shapes' bottoms."""
    world = _to_world(data.oMf[body.frame_id], body.collision_points)
    world[:, 2] -= body.collision_radii
    return world


def _sole(
    model: pin.Model, data: pin.Data, bodies: Sequence[Body], top: int, frame_id: int
) -> np.ndarray:
    """Corners (in the frame) of the sole rectangle of the foot ``top`` and its descendants."""
    world = np.vstack([_lowest_points_in_world(data, bodies[b]) for b in subtree(bodies, top)])
    if len(world) == 0:
        raise DescriptionError(
            f"body {bodies[top].name!r} has no collision geometry to find a sole on; "
            "give the contact's points",
            field="contacts",
        )
    low = world[world[:, 2] <= world[:, 2].min() + SOLE_HEIGHT_TOLERANCE_M]
    frame = data.oMf[frame_id]
    heading = frame.rotation[:, 0] * (1, 1, 0)
    if np.linalg.norm(heading) < 1e-6:  # the frame's x points up or down: use its z
        heading = frame.rotation[:, 2] * (1, 1, 0)
    heading /= np.linalg.norm(heading)
    lateral = np.array([-heading[1], heading[0], 0.0])
    along, across = low @ heading, low @ lateral
    corners_in_world = np.array(
        [
            a * heading + c * lateral + (0.0, 0.0, world[:, 2].min())
            for a in (along.max(), along.min())
            for c in (across.max(), across.min())
        ]
    )
    corners = (corners_in_world - frame.translation) @ frame.rotation
    # A line or point foot (spheres in a row, one sphere) has coincident corners: keep one each.
    _, first = np.unique(np.round(corners, 6), axis=0, return_index=True)
    return corners[np.sort(first)]


def _body_of_frame(model: pin.Model, bodies: Sequence[Body], frame_id: int) -> int | None:
    """Index in ``bodies`` of the body a frame is on (``None``: none, e.g. the world's).

    A body's frame is its own; a joint's is the body the joint moves (the first on it);
    any other frame's is the nearest body frame it hangs from.
    """
    index = {body.frame_id: i for i, body in enumerate(bodies)}
    frame = model.frames[frame_id]
    if frame.type == pin.JOINT:
        return next(
            (
                i
                for i, b in enumerate(bodies)
                if model.frames[b.frame_id].parentJoint == frame.parentJoint
            ),
            None,
        )
    for _ in range(len(model.frames)):
        if frame_id in index:
            return index[frame_id]
        if frame_id == 0:
            return None
        frame_id = model.frames[frame_id].parentFrame
    return None


def _named_contact(
    spec: ContactSpec, model: pin.Model, data: pin.Data, bodies: Sequence[Body]
) -> FoundContact:
    if not model.existFrame(spec.frame):
        raise FrameNotFoundError(
            spec.frame, [f.name for f in model.frames if f.type in (pin.BODY, pin.OP_FRAME)]
        )
    frame_id = model.getFrameId(spec.frame)
    if model.frames[frame_id].parentJoint == 0:
        raise DescriptionError(
            f"frame {spec.frame[:100]!r} is fixed in the world, not part of the robot: name a "
            "body, site or joint of the robot",
            field="contacts",
        )
    if spec.points_in_frame is not None:
        return FoundContact(
            spec.name,
            spec.frame,
            np.array(spec.points_in_frame, float),
            spec.friction_coefficient,
            reason="named, with its points",
        )
    top = _body_of_frame(model, bodies, frame_id)
    if top is None:
        raise DescriptionError(
            f"frame {spec.frame[:100]!r} is on no body of the robot to find a sole on: name a "
            "body or site, or give the contact's points",
            field="contacts",
        )
    return FoundContact(
        spec.name,
        spec.frame,
        _sole(model, data, bodies, top, frame_id),
        spec.friction_coefficient,
        reason=f"named; its sole from the collision geometry of {bodies[top].name!r} and below",
    )


def _find_feet(model: pin.Model, data: pin.Data, bodies: Sequence[Body]) -> list[FoundContact]:
    """The feet: lowest bodies (standing) without a lowest ancestor, named by their side."""
    lowest = {
        i: float(_lowest_points_in_world(data, b)[:, 2].min())
        for i, b in enumerate(bodies)
        if len(b.collision_points)
    }
    if not lowest:
        raise DescriptionError(
            "no body has collision geometry to find the feet on: give the contacts with their "
            "points (`contacts`)",
            field="contacts",
        )
    ground = min(lowest.values())
    touching = {i for i, z in lowest.items() if z <= ground + FOOT_HEIGHT_TOLERANCE_M}
    feet = []
    for i in sorted(touching):
        ancestor = bodies[i].parent
        while ancestor >= 0 and ancestor not in touching:
            ancestor = bodies[ancestor].parent
        if ancestor < 0:
            feet.append(i)
    # Left of the root's heading (its x axis on the ground; some files turn the root body).
    root = data.oMf[bodies[0].frame_id]
    heading = root.rotation[:, 0] * (1.0, 1.0, 0.0)
    heading = heading if np.linalg.norm(heading) > 1e-6 else np.array([1.0, 0.0, 0.0])
    lateral = np.array([-heading[1], heading[0], 0.0])
    sides = [
        float((data.oMf[bodies[i].frame_id].translation - root.translation) @ lateral) for i in feet
    ]
    lowest_reason = (
        "its collision points are among the lowest at the standing pose (within "
        f"{FOOT_HEIGHT_TOLERANCE_M:g} m of the lowest point)"
    )
    if len(feet) == 2 and sides[0] * sides[1] < 0:
        names = ["left_foot" if side > 0 else "right_foot" for side in sides]
        order = [0, 1] if names[0] == "left_foot" else [1, 0]
        feet, names = [feet[k] for k in order], [names[k] for k in order]
        sides = [sides[k] for k in order]
        reasons = [
            f"{lowest_reason}; {'left' if side > 0 else 'right'} of the root's heading "
            f"({abs(side):.3f} m)"
            for side in sides
        ]
    else:
        names = [bodies[i].name for i in feet]
        reasons = [f"{lowest_reason}; {len(feet)} such feet: named by their bodies"] * len(feet)
    # The points are in the frame the body's name resolves to (a joint of the same name
    # would come first), as every user of the contact looks it up by name.
    return [
        FoundContact(
            name,
            bodies[i].name,
            _sole(model, data, bodies, i, model.getFrameId(bodies[i].name)),
            reason=reason,
        )
        for name, i, reason in zip(names, feet, reasons, strict=True)
    ]
