"""Which server files a client may name: built-ins, or files in the model directories.

A ``hello`` names its robot model and the ``clip`` parameter its motion clip.
Either is a built-in name, or a path (absolute, or relative to one of the
directories set with :func:`set_model_directories`) that resolves, symlinks
followed, to a regular file inside one of those directories. Anything else is
refused with one message per name, whatever the reason (missing, outside,
unreadable, a directory, too long a name), so a client cannot probe the
server's file system; error messages show only the name the client sent.

Messages from deeper down (MuJoCo's compiler, a file a model names) may
still hold a server path: :func:`without_server_paths` rewrites the server's
directories in them, a file in a model directory by its path relative to it.
"""

from __future__ import annotations

import os
import re
import stat
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from controller_server.errors import FileTooLarge, ServerFault

__all__ = [
    "DEFAULT_MAX_FILE_BYTES",
    "MAX_NAME_LENGTH",
    "MODEL_DIRECTORY_PLACEHOLDER",
    "ServerFileKind",
    "display_name",
    "max_file_bytes",
    "model_directories",
    "set_model_directories",
    "without_server_paths",
]

DEFAULT_MAX_FILE_BYTES = 4 * 1024 * 1024
"""Largest model or clip file the server reads (bytes) unless set otherwise."""

MAX_NAME_LENGTH = 1024
"""Longest name (characters) a client may send; longer ones are refused unread."""

_DISPLAY_LENGTH = 100


@dataclass(frozen=True)
class _Policy:
    directories: tuple[Path, ...] = ()
    max_file_bytes: int = DEFAULT_MAX_FILE_BYTES


_policy = _Policy()


def set_model_directories(
    dirs: Sequence[str | Path], *, max_file_bytes: int = DEFAULT_MAX_FILE_BYTES
) -> None:
    """Set the process-wide policy: where clients' files may live, and how large they may be.

    Call once when the server process starts; the default is no directory
    (built-in models and clips only) and :data:`DEFAULT_MAX_FILE_BYTES`.

    Args:
        dirs: Existing directories; kept in their resolved form (symlinks followed).
        max_file_bytes: Largest file read, built-ins included (bytes, ≥ 1).

    Raises:
        NotADirectoryError: A directory does not exist or is not a directory.
        ValueError: ``max_file_bytes`` below 1.
    """
    if max_file_bytes < 1:
        raise ValueError(f"max_file_bytes must be at least 1, got {max_file_bytes=}")
    resolved = []
    for directory in dirs:
        path = Path(directory).expanduser().resolve()
        if not path.is_dir():
            raise NotADirectoryError(f"model directory {str(directory)!r} is not a directory")
        resolved.append(path)
    global _policy
    _policy = _Policy(tuple(dict.fromkeys(resolved)), max_file_bytes)


def model_directories() -> tuple[Path, ...]:
    """Resolved directories clients' model and clip files may live in (empty: built-ins only)."""
    return _policy.directories


def max_file_bytes() -> int:
    """Largest model or clip file the server reads (bytes)."""
    return _policy.max_file_bytes


def display_name(name: str) -> str:
    """The name a client sent, quoted and cut to 100 characters, for an error message."""
    shown = name if len(name) <= _DISPLAY_LENGTH else name[:_DISPLAY_LENGTH] + "…"
    return repr(shown)


MODEL_DIRECTORY_PLACEHOLDER = "<model dir>"
"""What a model directory itself is called in a message (a file in it: its relative path)."""

_PACKAGE_ROOT = Path(__file__).resolve().parent.parent


def _server_directories() -> dict[str, str]:
    """Directories whose path a client must not see, each with what it is shown as.

    A model directory followed by a path is removed (the path is relative to it); alone it
    is :data:`MODEL_DIRECTORY_PLACEHOLDER`. Each is listed as given and resolved.
    """
    shown: dict[str, str] = {}

    def add(directory: str | Path | None, placeholder: str) -> None:
        if not directory:
            return
        forms = {str(directory)}
        try:
            forms.add(str(Path(directory).resolve()))
        except (OSError, RuntimeError):
            pass
        for form in forms:
            form = form.rstrip("/")
            if form and form not in shown:  # "/" (root) is never a server directory
                shown[form] = placeholder

    for directory in _policy.directories:
        add(directory, MODEL_DIRECTORY_PLACEHOLDER)
    add(tempfile.gettempdir(), "<temp dir>")
    try:
        add(os.getcwd(), "<working dir>")
    except OSError:  # the working directory was removed
        pass
    add(_PACKAGE_ROOT, "<install dir>")
    try:
        add(Path.home(), "~")
    except (RuntimeError, KeyError):  # no home directory
        pass
    return shown


def without_server_paths(text: str) -> str:
    """``text`` with the server's directories rewritten, for a message a client reads.

    A path inside one of the model directories becomes its path relative to that
    directory (``/srv/models/robot/meshes/foot.stl`` → ``robot/meshes/foot.stl``);
    the temporary directory, the working directory, Poise's install directory and
    the home directory become ``<temp dir>``, ``<working dir>``, ``<install dir>``
    and ``~``. The innermost directory wins (a model directory under ``/tmp`` gives
    relative paths). A directory is matched only as a whole path component at the
    start of a path: ``/tmpfiles`` and ``/a/tmp`` are left alone.

    Args:
        text: A message that may quote server paths (MuJoCo's, the system's).

    Returns:
        The message as a client may read it.
    """
    shown = _server_directories()
    if not shown:
        return text
    alternatives = "|".join(re.escape(d) for d in sorted(shown, key=len, reverse=True))
    pattern = re.compile(
        rf"(?<![\w.~-])(?P<directory>{alternatives})(?:(?P<separator>/+)|(?![\w.~-]))"
    )

    def rewrite(match: re.Match[str]) -> str:
        placeholder = shown[match["directory"]]
        if placeholder == MODEL_DIRECTORY_PLACEHOLDER and match["separator"]:
            return ""
        return placeholder + ("/" if match["separator"] else "")

    return pattern.sub(rewrite, text)


@dataclass(frozen=True)
class ServerFileKind:
    """One kind of server file a client may name (a robot model, a motion clip).

    Attributes:
        kind: What the file is, for messages (``"model"``, ``"clip"``).
        field: Wire field that carries the name (``"model"``, ``"params.clip"``).
        builtin: Built-in names and their package files, looked up first.
        suffixes: Lower-case suffixes a file in the model directories must end with.
        not_found: Makes the wire error for a refused name from its detail text.
    """

    kind: str
    field: str
    builtin: Mapping[str, Path]
    suffixes: tuple[str, ...]
    not_found: Callable[[str], ServerFault]

    def refusal(self, name: str) -> ServerFault:
        """The one error for every name that is not a built-in nor an allowed file."""
        return self.not_found(
            f"{display_name(name)} is not a built-in {self.kind} ({', '.join(self.builtin)}) "
            f"nor a file in the server's model directories ({' or '.join(self.suffixes)})"
        )

    def resolve(self, name: str) -> Path:
        """The file a client's name stands for: a built-in, or an allowed file.

        A name that is not built in is a path, absolute or relative to each
        model directory in turn. It is resolved (symlinks followed) and
        accepted only as a regular file with one of :attr:`suffixes` inside
        the resolved form of a model directory.

        Args:
            name: What the client sent.

        Returns:
            The built-in's package path, or the resolved path of the file.

        Raises:
            ServerFault: :meth:`refusal` for every other name (empty, NUL,
                longer than :data:`MAX_NAME_LENGTH`, missing, outside,
                unreadable, not a regular file).
        """
        if name in self.builtin:
            return self.builtin[name]
        if not name or "\0" in name or len(name) > MAX_NAME_LENGTH:
            raise self.refusal(name)
        directories = _policy.directories
        for directory in directories:
            try:
                # An absolute name replaces the directory; containment is checked below.
                path = (directory / name).resolve(strict=True)
                is_file = stat.S_ISREG(path.stat().st_mode)
            except (OSError, RuntimeError, ValueError):  # RuntimeError: symlink loop
                continue
            inside = any(path.is_relative_to(allowed) for allowed in directories)
            if is_file and inside and path.suffix.lower() in self.suffixes:
                return path
        raise self.refusal(name)

    def read_bytes(self, name: str) -> tuple[Path, bytes]:
        """Resolve a name (:meth:`resolve`) and read its file, within the size cap.

        Returns:
            The path (as :meth:`resolve`) and the file's bytes.

        Raises:
            ServerFault: :meth:`refusal` if the name is refused or the file
                cannot be read; :class:`FileTooLarge` if it is larger than
                :func:`max_file_bytes`.
        """
        path = self.resolve(name)
        limit = _policy.max_file_bytes
        try:
            # O_NONBLOCK: a file swapped for a FIFO since resolve() must not hang the server.
            descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
            with os.fdopen(descriptor, "rb") as file:
                status = os.fstat(file.fileno())
                if not stat.S_ISREG(status.st_mode):
                    raise self.refusal(name)
                if status.st_size > limit:
                    raise self._too_large(limit)
                data = file.read(limit + 1)
        except OSError:
            raise self.refusal(name) from None
        if len(data) > limit:  # grew since fstat
            raise self._too_large(limit)
        return path, data

    def read_text(self, name: str) -> tuple[Path, str]:
        """As :meth:`read_bytes`, decoded as UTF-8 (undecodable: :meth:`refusal`)."""
        path, data = self.read_bytes(name)
        try:
            return path, data.decode("utf-8")
        except UnicodeDecodeError:
            raise self.refusal(name) from None

    def _too_large(self, limit: int) -> FileTooLarge:
        return FileTooLarge(
            self.field,
            f"the {self.kind} file exceeds the server's limit of {limit} bytes",
        )
