"""Where a file named by a model is: paths, ``package://`` and ``file://`` URIs.

Every reading asks for the files a model names through a :data:`FileReader`; a reader finds
what a name stands for with :func:`resolve_file` (``package://`` URIs as ROS tools find them,
:func:`find_package`, in the directories of :func:`ros_package_path`).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from pathlib import Path

from controller_server.models.description.limits import MAX_PACKAGE_SEARCH_DEPTH, DescriptionError

__all__ = [
    "FileReader",
    "find_package",
    "resolve_file",
    "ros_package_path",
]

FileReader = Callable[[str], bytes]
"""Reads a file named by a model, by the name the model gives it.

MJCF: a path relative to the main file's directory (POSIX), ``meshdir`` and
includes resolved. URDF: a mesh's ``filename`` exactly as written (a
``package://`` or ``file://`` URI, or a path relative to the URDF's
directory) and the SRDF's :func:`srdf_paths`. The reader resolves it
(:func:`resolve_file`)."""


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
