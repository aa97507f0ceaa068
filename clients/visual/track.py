"""What a picture of a run is drawn from: one :class:`Track`, from a simulator run or a log.

A track is the run's states and commands tick by tick, with what the caption
and the overlays need (scenario, controller, backend, pushes). A simulator
run gives the backend's true states (:func:`track_of_run`); a recorded log
gives the states its client sent (:func:`track_of_log`), and for a state that
carried an IMU reading instead of the base, the base the server estimated
(its diagnostics' ``base_estimate``, held between diagnostics ticks).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from clients.replay import recorded_session
from clients.sim.runner import RunRecord
from clients.sim.scenario import PushSpec
from clients.state import RobotState
from protocol.messages import Command, Hello, State, Welcome
from protocol.recording import BadLog, read_log

__all__ = ["Track", "track_of_log", "track_of_run"]


@dataclass
class Track:
    """A run to draw, one entry per control tick.

    Attributes:
        name: The scenario's name (a log: the file's stem).
        controller: The controller that served the run.
        backend: ``reference`` or ``mujoco`` (a log: ``recorded``).
        model: What MuJoCo loads to draw the robot: a built-in name or a file path.
        keyframe: The MJCF keyframe of the standing pose (or ``None``).
        welcome: The server's handshake (joint and contact order).
        time_s: Time of each tick (s).
        states: The robot's state at each tick (wire conventions).
        commands: The server's command for each tick (some carry diagnostics).
        pushes: Pushes on the robot (a log does not record them: none).
    """

    name: str
    controller: str
    backend: str
    model: str
    keyframe: str | None
    welcome: Welcome
    time_s: np.ndarray
    states: Sequence[RobotState]
    commands: Sequence[Command]
    pushes: Sequence[PushSpec] = field(default_factory=tuple)

    @property
    def duration_s(self) -> float:
        """Time covered: from 0 to one control period past the last tick (s)."""
        if len(self.time_s) == 0:
            return 0.0
        period_s = float(np.median(np.diff(self.time_s))) if len(self.time_s) > 1 else 0.0
        return float(self.time_s[-1]) + period_s

    def tick_at(self, time_s: float) -> int:
        """The last tick at or before ``time_s`` (the first tick before it starts)."""
        return max(0, int(np.searchsorted(self.time_s, time_s + 1e-9, side="right")) - 1)


def track_of_run(record: RunRecord) -> Track:
    """The track of a simulator run (its true states)."""
    scenario = record.scenario
    return Track(
        name=scenario.name,
        controller=scenario.controller,
        backend=scenario.backend,
        model=scenario.model,
        keyframe=scenario.keyframe,
        welcome=record.welcome,
        time_s=np.asarray(record.time_s, dtype=float),
        states=record.states,
        commands=record.commands,
        pushes=scenario.pushes,
    )


def track_of_log(path: str | os.PathLike[str], model_dir: Path | None = None) -> Track:
    """The track of a log's first session: each answered ``state`` and its command.

    Time is each state's ``time_s`` less the first's. A model the client sent
    as text (``hello.model_text`` and its files) is written to ``model_dir``
    (default: a new temporary directory) so that MuJoCo can load it.

    Raises:
        BadLog: Not a log, no state answered by a command, or a state carrying an
            IMU reading before any diagnostics estimated the base.
        ReplayError: The log holds no handshake.
    """
    session = recorded_session(path, read_log(path))
    time_s: list[float] = []
    states: list[RobotState] = []
    commands: list[Command] = []
    estimate = None
    for _, request in session.requests:
        reply = session.replies.get(request.seq)
        if not (isinstance(request, State) and isinstance(reply, Command)):
            continue
        if reply.diagnostics is not None and reply.diagnostics.base_estimate is not None:
            estimate = reply.diagnostics.base_estimate
        base = request if request.position_base_in_world is not None else estimate
        if base is None:
            raise BadLog(
                path,
                f"the state at {request.time_s:.3f} s carries an IMU reading and no "
                "diagnostics estimated the base yet: nothing to draw the robot from",
            )
        states.append(
            RobotState(
                joint_position=np.asarray(request.joint_position, dtype=float),
                joint_velocity=np.asarray(request.joint_velocity, dtype=float),
                position_base_in_world=np.asarray(base.position_base_in_world, dtype=float),
                orientation_base_in_world_xyzw=np.asarray(
                    base.orientation_base_in_world_xyzw, dtype=float
                ),
                linear_velocity_base_in_world=np.asarray(
                    base.linear_velocity_base_in_world, dtype=float
                ),
                angular_velocity_base_in_base=np.asarray(
                    base.angular_velocity_base_in_base, dtype=float
                ),
            )
        )
        time_s.append(request.time_s)
        commands.append(reply)
    if not commands:
        raise BadLog(path, "no recorded state was answered by a command: nothing to draw")
    return Track(
        name=Path(path).stem,
        controller=session.welcome.controller,
        backend="recorded",
        model=_model_of_hello(session.hello, model_dir),
        keyframe=session.hello.keyframe,
        welcome=session.welcome,
        time_s=np.asarray(time_s) - time_s[0],
        states=states,
        commands=commands,
    )


def _model_of_hello(hello: Hello, model_dir: Path | None) -> str:
    """The model a hello names: a built-in name or path as is, sent text written to files."""
    if hello.model_text is None:
        return str(hello.model)
    directory = model_dir or Path(tempfile.mkdtemp(prefix="poise-log-model-"))
    main = directory / f"model.{'urdf' if hello.model_format == 'urdf' else 'xml'}"
    main.write_text(hello.model_text)
    for name, data in (hello.model_assets or {}).items():
        target = directory / PurePosixPath(name)
        if directory.resolve() not in target.resolve().parents:
            continue  # a name that climbs out of the directory: not written
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    return str(main)
