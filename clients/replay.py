"""Replay a recorded conversation against a server: a log is a regression test.

The log's own ``hello`` re-creates the session (the server must announce the
recorded model hash; the files it holds inline go by hash, uploaded to a server
that lacks them, see :mod:`clients.client`), its ``set_params`` and ``state`` requests are sent in
recorded order, and every returned command is compared with the recorded
one, field by field: ``|new − old| ≤ atol + rtol·|old|`` (NaN equal to NaN).
The same code reproduces a log within 1e-9; a behaviour change shows as the
first divergent ``seq`` and the fields that moved.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import tempfile
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from clients.client import ControllerClient, CurveKeys, ServerError
from clients.track import RunObserver, session_track
from protocol.errors import PoiseError
from protocol.messages import (
    PROTOCOL_VERSION,
    Command,
    Error,
    Hello,
    SetParams,
    State,
    Welcome,
)
from protocol.recording import LoggedMessage, read_log

__all__ = [
    "COMPARED_FIELDS",
    "RecordedLog",
    "RecordedSession",
    "ReplayError",
    "ReplayReport",
    "load_replay",
    "read_recorded",
    "recorded_session",
    "replay_log",
]

COMPARED_FIELDS = (
    "joint_acceleration",
    "base_linear_acceleration_in_world",
    "base_angular_acceleration_in_base",
    "joint_torque",
    "contact_force_in_world",
    "contact_wrench_in_world",
)
"""Command fields compared (what reaches an actuator or a simulator)."""


@dataclasses.dataclass
class ReplayReport:
    """What a replay found.

    Attributes:
        compared: Commands compared with their recorded counterparts.
        first_divergent_seq: Recorded ``seq`` of the first command out of
            tolerance (``None``: none).
        divergent_fields: Fields out of tolerance at that ``seq``.
        max_abs_error: Largest absolute difference over all compared commands.
        max_rel_error: Largest ``|new − old| / |old|`` over entries with ``old ≠ 0``.
        divergent_commands: Commands with any field out of tolerance.
        requests_sent: Recorded ``state`` and ``set_params`` requests sent again.
        messages_read: Messages read from the log.
        log_truncated: The log ends early (its recorder was killed); the replay
            covers the messages before the cut.
    """

    compared: int = 0
    first_divergent_seq: int | None = None
    divergent_fields: list[str] = dataclasses.field(default_factory=list)
    max_abs_error: float = 0.0
    max_rel_error: float = 0.0
    divergent_commands: int = 0
    requests_sent: int = 0
    messages_read: int = 0
    log_truncated: bool = False

    @property
    def regression(self) -> bool:
        """Whether any command left the tolerance."""
        return self.first_divergent_seq is not None

    def to_json(self) -> dict[str, Any]:
        """The report as JSON data (``poise replay --json``)."""
        return {**dataclasses.asdict(self), "regression": self.regression}


class ReplayError(PoiseError):
    """A log that cannot be replayed here: no handshake, or a server that refuses it."""


@dataclasses.dataclass
class RecordedSession:
    """The first session of a log, whichever side recorded it.

    Attributes:
        hello: The request that opened it.
        welcome: The server's answer.
        requests: ``state`` and ``set_params`` requests in recorded order, with
            their log times (ns).
        replies: Recorded ``command`` or ``error`` replies by ``seq``.
    """

    hello: Hello
    welcome: Welcome
    requests: list[tuple[int, SetParams | State]]
    replies: dict[int, Command | Error]


def recorded_session(
    path: str | os.PathLike[str], messages: Iterable[LoggedMessage]
) -> RecordedSession:
    """The log's first session, from a client's log or a server's (``poise serve --record``).

    Message types say which side sent what, so the recorded ``direction`` is
    not needed: a client log has its requests ``sent``, a server log ``received``.

    Raises:
        ReplayError: The log holds no hello answered by a welcome.
    """
    hello: Hello | None = None
    welcome: Welcome | None = None
    requests: list[tuple[int, SetParams | State]] = []
    replies: dict[int, Command | Error] = {}
    for logged in messages:
        message = logged.message
        if isinstance(message, Hello):
            if welcome is not None:
                break  # a second hello starts another session
            hello = message
        elif isinstance(message, Welcome):
            welcome = message if hello is not None else None
        elif welcome is None:
            continue  # before the handshake (or a refused hello's error)
        elif isinstance(message, SetParams | State):
            requests.append((logged.time_ns, message))
        elif isinstance(message, Command | Error):
            replies[message.seq] = message
    if hello is None or welcome is None:
        raise ReplayError(f"{str(path)!r} holds no recorded hello and welcome: nothing to replay")
    return RecordedSession(hello, welcome, requests, replies)


@dataclasses.dataclass
class RecordedLog:
    """A log read to its end and checked: its first session, ready to replay or plot.

    Attributes:
        path: The log.
        session: Its first session.
        messages_read: Messages in the whole file.
        truncated: The log ends early (its recorder was killed).
    """

    path: Path
    session: RecordedSession
    messages_read: int
    truncated: bool

    @property
    def comparable_commands(self) -> int:
        """Recorded states answered by a recorded command: what a replay compares."""
        replies = self.session.replies
        return sum(
            isinstance(request, State) and isinstance(replies.get(request.seq), Command)
            for _, request in self.session.requests
        )


def read_recorded(
    path: str | os.PathLike[str], progress: Callable[[float], None] | None = None
) -> RecordedLog:
    """Read the whole log (corruption anywhere in it is found now) and keep its first session.

    Args:
        path: The MCAP log.
        progress: Optional callable told the fraction of the file read (0 to 1).

    Raises:
        BadLog: Not a log, or a corrupt one.
        ReplayError: The log holds no hello answered by a welcome.
    """
    reader = read_log(path)
    messages = reader.reporting(progress)
    session = recorded_session(path, messages)
    for _ in messages:
        pass  # the sessions after the first: read to the end, so corruption there is found too
    return RecordedLog(Path(path), session, reader.messages_read, reader.truncated)


def load_replay(
    path: str | os.PathLike[str], progress: Callable[[float], None] | None = None
) -> RecordedLog:
    """Read and check a log for a replay, before any server is involved.

    Raises:
        BadLog: Not a log, or a corrupt one.
        ReplayError: No recorded handshake, another protocol version, or no recorded
            command to compare (a replay of it would compare nothing: no pass).
    """
    recorded = read_recorded(path, progress)
    hello = recorded.session.hello
    if hello.version != PROTOCOL_VERSION:
        raise ReplayError(
            f"{str(path)!r} was recorded with protocol version {hello.version}; this Poise "
            f"speaks version {PROTOCOL_VERSION}: replay it with the Poise that recorded it, "
            'or re-record it (docs/recording.md, "When replay fails")'
        )
    if recorded.comparable_commands == 0:
        states = sum(isinstance(request, State) for _, request in recorded.session.requests)
        raise ReplayError(
            f"{str(path)!r} holds no commands to compare ({states} recorded states, none "
            "answered by a recorded command): nothing to replay"
        )
    return recorded


def _compare(new: Command, old: Command, atol: float, rtol: float, report: ReplayReport) -> None:
    fields = []
    for name in COMPARED_FIELDS:
        new_values, old_values = getattr(new, name), getattr(old, name)
        if new_values.shape != old_values.shape:
            fields.append(name)
            continue
        both_nan = np.isnan(new_values) & np.isnan(old_values)
        difference = np.where(both_nan, 0.0, np.abs(new_values - old_values))
        difference = np.nan_to_num(difference, nan=np.inf)
        if difference.size:
            report.max_abs_error = max(report.max_abs_error, float(difference.max()))
            nonzero = old_values != 0
            if np.any(nonzero):
                relative = difference[nonzero] / np.abs(old_values[nonzero])
                report.max_rel_error = max(report.max_rel_error, float(relative.max()))
        if np.any(difference > atol + rtol * np.abs(np.nan_to_num(old_values))):
            fields.append(name)
    report.compared += 1
    if fields:
        report.divergent_commands += 1
        if report.first_divergent_seq is None:
            report.first_divergent_seq = old.seq
            report.divergent_fields = fields


def replay_log(
    log: str | os.PathLike[str] | RecordedLog,
    endpoint: str,
    *,
    atol: float = 1e-9,
    rtol: float = 1e-9,
    params: dict[str, Any] | None = None,
    curve: CurveKeys | None = None,
    timeout_s: float = 10.0,
    realtime: bool = False,
    progress: Callable[[float], None] | None = None,
    observer: RunObserver | None = None,
) -> ReplayReport:
    """Replay the first session of a log against the server at ``endpoint``.

    Args:
        log: MCAP log written by :class:`~protocol.recording.Recorder`, or one
            :func:`load_replay` read already (read it before starting a server).
        endpoint: Server to replay against.
        atol: Absolute tolerance per entry.
        rtol: Relative tolerance per entry.
        params: Parameter overrides on top of the recorded hello's (e.g. to see
            what a gain change does to a recorded run).
        curve: CURVE keys for a server that requires them.
        timeout_s: Per-request timeout.
        realtime: Send each request at its recorded time after the first
            (default: as fast as the server answers).
        progress: Called with the fraction of requests sent, now and then.
        observer: Called after every answered ``state`` with the replay's track: the
            states of the log and the commands of this server (a live view).

    Raises:
        BadLog: Not a log, or a corrupt one.
        ReplayError: No recorded handshake, another protocol version, no recorded
            command to compare, or a server that refuses the recorded hello
            (another model hash: the detail says which).
    """
    recorded_log = log if isinstance(log, RecordedLog) else load_replay(log)
    path, recorded = recorded_log.path, recorded_log.session
    hello = recorded.hello
    report = ReplayReport(
        messages_read=recorded_log.messages_read, log_truncated=recorded_log.truncated
    )
    with contextlib.ExitStack() as stack:
        client = stack.enter_context(ControllerClient(endpoint, timeout_s=timeout_s, curve=curve))
        fields = hello.model_dump(exclude={"type", "version", "seq"})
        fields["params"] = {**hello.params, **(params or {})}
        fields["expected_model_hash"] = recorded.welcome.model_hash
        try:
            welcome = client.connect(**fields)
        except ServerError as exc:
            raise ReplayError(
                f"the server refused the recorded hello of {str(path)!r}: {exc.code.name}, "
                f"{exc.detail} "
                "(a log replays against the model it was recorded with)"
            ) from None
        track = None
        if observer is not None:
            model_dir = stack.enter_context(tempfile.TemporaryDirectory(prefix="poise-replay-"))
            track = session_track(Path(path).stem, hello, welcome, "replayed", Path(model_dir))
        start_s = time.monotonic()
        first_ns = recorded.requests[0][0] if recorded.requests else 0
        for index, (time_ns, request) in enumerate(recorded.requests):
            if realtime:
                time.sleep(max(0.0, start_s + (time_ns - first_ns) * 1e-9 - time.monotonic()))
            if progress is not None and index % 100 == 0:
                progress(index / len(recorded.requests))
            report.requests_sent += 1
            command = _replay_one(
                client, request, recorded.replies.get(request.seq), atol, rtol, report
            )
            if observer is not None and track is not None and isinstance(request, State):
                if command is not None and track.add_exchange(request, command):
                    observer(track)
    if progress is not None:
        progress(1.0)
    return report


def _replay_one(
    client: ControllerClient,
    request: SetParams | State,
    recorded: Command | Error | None,
    atol: float,
    rtol: float,
    report: ReplayReport,
) -> Command | None:
    """Send one recorded request, compare the answer with the recorded one, return it."""
    if isinstance(request, SetParams):
        client.set_params(request.params)
        return None
    try:
        command = client.step(request)
    except ServerError as exc:
        if isinstance(recorded, Error) and recorded.code == exc.code:
            return None  # the same refusal as recorded
        raise
    if isinstance(recorded, Command):
        _compare(command, recorded, atol, rtol, report)
    return command
