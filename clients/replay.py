"""Replay a recorded conversation against a server: a log is a regression test.

The log's own ``hello`` re-creates the session (the server must announce the
recorded model hash), its ``set_params`` and ``state`` requests are sent in
recorded order, and every returned command is compared with the recorded
one, field by field: ``|new − old| ≤ atol + rtol·|old|`` (NaN equal to NaN).
The same code reproduces a log within 1e-9; a behaviour change shows as the
first divergent ``seq`` and the fields that moved.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterable
from typing import Any

import numpy as np

from clients.client import ControllerClient, CurveKeys, ServerError
from clients.recording import LoggedMessage, read_log
from protocol.errors import PoiseError
from protocol.messages import Command, Error, Hello, SetParams, State, Welcome

__all__ = ["COMPARED_FIELDS", "ReplayError", "ReplayReport", "replay_log"]

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
    """

    compared: int = 0
    first_divergent_seq: int | None = None
    divergent_fields: list[str] = dataclasses.field(default_factory=list)
    max_abs_error: float = 0.0
    max_rel_error: float = 0.0
    divergent_commands: int = 0

    @property
    def regression(self) -> bool:
        """Whether any command left the tolerance."""
        return self.first_divergent_seq is not None

    def to_json(self) -> dict[str, Any]:
        """The report as JSON data (``poise replay --json``)."""
        return {**dataclasses.asdict(self), "regression": self.regression}


class ReplayError(PoiseError):
    """A log that cannot be replayed here: no handshake, or a server that refuses it."""


def _recorded_conversation(
    path: str | os.PathLike[str], messages: Iterable[LoggedMessage]
) -> tuple[Hello, Welcome, list[SetParams | State], dict[int, Command | Error]]:
    """The log's first session: its hello, welcome, requests and replies by ``seq``."""
    hello: Hello | None = None
    welcome: Welcome | None = None
    requests: list[SetParams | State] = []
    replies: dict[int, Command | Error] = {}
    for logged in messages:
        message = logged.message
        if logged.direction == "sent":
            if isinstance(message, Hello):
                if hello is not None:
                    break  # a second hello starts another session
                hello = message
            elif isinstance(message, SetParams | State):
                requests.append(message)
        elif isinstance(message, Welcome) and hello is not None and welcome is None:
            welcome = message
        elif isinstance(message, Command | Error):
            replies[message.seq] = message
    if hello is None or welcome is None:
        raise ReplayError(f"{str(path)!r} holds no recorded hello and welcome: nothing to replay")
    return hello, welcome, requests, replies


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
    path: str | os.PathLike[str],
    endpoint: str,
    *,
    atol: float = 1e-9,
    rtol: float = 1e-9,
    params: dict[str, Any] | None = None,
    curve: CurveKeys | None = None,
    timeout_s: float = 10.0,
) -> ReplayReport:
    """Replay the first session of a log against the server at ``endpoint``.

    Args:
        path: MCAP log written by :class:`~clients.recording.Recorder`.
        endpoint: Server to replay against.
        atol: Absolute tolerance per entry.
        rtol: Relative tolerance per entry.
        params: Parameter overrides on top of the recorded hello's (e.g. to see
            what a gain change does to a recorded run).
        curve: CURVE keys for a server that requires them.
        timeout_s: Per-request timeout.

    Raises:
        BadLog: Not a log.
        ReplayError: No recorded handshake, or the server refuses the recorded
            hello (another model hash: the detail says which).
    """
    hello, welcome, requests, replies = _recorded_conversation(path, read_log(path))
    with ControllerClient(endpoint, timeout_s=timeout_s, curve=curve) as client:
        fields = hello.model_dump(exclude={"type", "version", "seq"})
        fields["params"] = {**hello.params, **(params or {})}
        fields["expected_model_hash"] = welcome.model_hash
        try:
            client.connect(**fields)
        except ServerError as exc:
            raise ReplayError(
                f"the server refused the recorded hello of {str(path)!r}: {exc.code.name}, "
                f"{exc.detail} "
                "(a log replays against the model it was recorded with)"
            ) from None
        report = ReplayReport()
        for request in requests:
            recorded = replies.get(request.seq)
            if isinstance(request, SetParams):
                client.set_params(request.params)
                continue
            try:
                command = client.step(request)
            except ServerError as exc:
                if isinstance(recorded, Error) and recorded.code == exc.code:
                    continue  # the same refusal as recorded
                raise
            if isinstance(recorded, Command):
                _compare(command, recorded, atol, rtol, report)
    return report
