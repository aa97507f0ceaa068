"""MJCF through MuJoCo's compiler: includes inlined, assets handed over in memory.

:func:`expand_mjcf` makes one document of an MJCF and the files it includes, every asset
it names read through the caller's reader and handed to MuJoCo in memory; on the way the
XML's depth and elements (repeats counted) and the assets' bytes and pixels are held to the
caps of :mod:`~controller_server.models.description.limits`. :func:`compile_mjcf` compiles
the document with MuJoCo.
"""

from __future__ import annotations

import math
import posixpath
import re
import struct
import xml.etree.ElementTree as ET
from pathlib import PurePosixPath

import mujoco

from controller_server.models.description.files import FileReader
from controller_server.models.description.limits import (
    MAX_ASSET_BYTES,
    MAX_IMAGE_PIXELS,
    MAX_INCLUDE_DEPTH,
    MAX_XML_DEPTH,
    MAX_XML_ELEMENTS,
    DescriptionError,
    DescriptionLimitError,
)

__all__ = [
    "Cost",
    "compile_mjcf",
    "expand_mjcf",
    "mujoco_message",
    "parse_xml",
    "safe_suffix",
]

_ASSET_DIRECTORY = {
    "mesh": "meshdir",
    "skin": "meshdir",
    "hfield": "meshdir",
    "texture": "texturedir",
}


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
    root = parse_xml(text, "the model")
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
    cost = Cost()
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
                keys[path] = f"poise_asset_{len(keys)}{safe_suffix(path)}"
                assets[keys[path]] = _read(read, path, f"<{element.tag} {attribute}>")
            element.set(attribute, keys[path])
            cost.add_file(path, assets[keys[path]], times)
    paths = {key: path for path, key in keys.items()}
    return ET.tostring(root, encoding="unicode"), assets, paths


def mujoco_message(exc: ValueError, paths: dict[str, str]) -> str:
    """MuJoCo's message on one line, each asset key replaced by the path the model names.

    MuJoCo names a file it cannot decode by its key, a name the client never wrote.
    """
    detail = " ".join(str(exc).split())
    if not paths:
        return detail
    keys = "|".join(re.escape(key) for key in sorted(paths, key=len, reverse=True))
    return re.sub(rf"(?<![\w.])(?:{keys})(?![\w.])", lambda key: paths[key[0]], detail)


def safe_suffix(path: str) -> str:
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


class Cost:
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


def parse_xml(text: bytes | str, what: str) -> ET.Element:
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
        included = parse_xml(_read(read, path, "<include file>"), f"included file {path!r}")
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
        detail = mujoco_message(exc, paths)
        raise DescriptionError(f"MuJoCo could not compile the model: {detail}") from None
