"""A run tick by tick, as a picture of it needs it: one :class:`Track` for every client.

A track is the robot's state and the server's command at each tick, with
what a caption and the overlays need (scenario or log name, controller,
backend, pushes). Every client that can be watched fills one as it goes:
the simulator (its true states, :func:`~clients.sim.runner.track_of_run`),
a replay and a recorded log (the states the client sent, :meth:`Track.add_exchange`),
the hardware bridge (its measured states, :meth:`Track.add`). An observer,
such as the live view, is called with the same growing track after each
tick: a new track object is a new run.

A state that carried an IMU reading instead of the base is drawn with the
base the server estimated (its diagnostics' ``base_estimate``, held between
diagnostics ticks); before the first estimate it is not added.
"""

from __future__ import annotations

import bisect
import dataclasses
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from clients.physics.backend import PushSpec
from clients.state import RobotState
from protocol.messages import BaseEstimateDiagnostics, Command, Hello, State, Welcome

__all__ = ["RunObserver", "Track", "session_track"]


@dataclass
class Track:
    """A run to draw, one entry per control tick.

    Attributes:
        name: The scenario's name (a log or a replay: the file's stem).
        controller: The controller that served the run.
        backend: What produced the states: ``reference`` or ``mujoco`` (a
            simulator run), ``recorded``, ``replayed``, or the bridge's.
        model: What MuJoCo loads to draw the robot: a built-in name or a file path.
        keyframe: The MJCF keyframe of the standing pose (or ``None``).
        welcome: The server's handshake (joint and contact order).
        time_s: Time of each tick (s).
        states: The robot's state at each tick (wire conventions).
        commands: The server's command for each tick (some carry diagnostics).
        pushes: Pushes on the robot (a log does not record them: none).
        keep_s: Keep only the ticks of the last ``keep_s`` seconds (at least;
            ``None``: all), for a run without end.
    """

    name: str
    controller: str
    backend: str
    model: str
    keyframe: str | None
    welcome: Welcome
    time_s: list[float] = field(default_factory=list)
    states: list[RobotState] = field(default_factory=list)
    commands: list[Command] = field(default_factory=list)
    pushes: Sequence[PushSpec] = field(default_factory=tuple)
    keep_s: float | None = None
    _base_estimate: BaseEstimateDiagnostics | None = field(default=None, init=False, repr=False)
    _time_origin_s: float | None = field(default=None, init=False, repr=False)

    @property
    def duration_s(self) -> float:
        """Time covered: from 0 to one control period past the last tick (s)."""
        if not self.time_s:
            return 0.0
        period_s = float(np.median(np.diff(self.time_s))) if len(self.time_s) > 1 else 0.0
        return float(self.time_s[-1]) + period_s

    def tick_at(self, time_s: float) -> int:
        """The last tick at or before ``time_s`` (the first tick before it starts)."""
        return max(0, bisect.bisect_right(self.time_s, time_s + 1e-9) - 1)

    def empty(self) -> Track:
        """A track of the same run without its ticks (what an observer elsewhere starts from)."""
        return dataclasses.replace(self, time_s=[], states=[], commands=[])

    def add(
        self, time_s: float, state: RobotState, command: Command, *, base_estimated: bool = False
    ) -> bool:
        """Add a tick: the robot's state and the server's command for it.

        Args:
            time_s: The tick's time (s), after the last tick's.
            state: The robot's state (wire conventions).
            command: The server's command.
            base_estimated: The state's base was not measured (it went as an
                IMU reading): the server's estimate is drawn instead.

        Returns:
            Whether the tick was added: not if its base is estimated and the
            server has not estimated it yet.
        """
        diagnostics = command.diagnostics
        if diagnostics is not None and diagnostics.base_estimate is not None:
            self._base_estimate = diagnostics.base_estimate
        if base_estimated:
            estimate = self._base_estimate
            if estimate is None:
                return False
            state = RobotState(
                state.joint_position,
                state.joint_velocity,
                np.asarray(estimate.position_base_in_world, dtype=float),
                np.asarray(estimate.orientation_base_in_world_xyzw, dtype=float),
                np.asarray(estimate.linear_velocity_base_in_world, dtype=float),
                np.asarray(estimate.angular_velocity_base_in_base, dtype=float),
            )
        self.time_s.append(time_s)
        self.states.append(state)
        self.commands.append(command)
        if self.keep_s is not None and time_s - self.time_s[0] > 2 * self.keep_s:
            # Every keep_s seconds, not every tick: the lists move once per window.
            first = bisect.bisect_left(self.time_s, time_s - self.keep_s)
            del self.time_s[:first], self.states[:first], self.commands[:first]
        return True

    def add_exchange(self, state: State, command: Command) -> bool:
        """Add a ``state`` message as a client sent it and the command that answered it.

        Time is the state's ``time_s`` less that of the first state given here; see :meth:`add`.
        """
        imu = state.position_base_in_world is None
        robot = RobotState(
            np.asarray(state.joint_position, dtype=float),
            np.asarray(state.joint_velocity, dtype=float),
            *(
                np.zeros(3) if imu else np.asarray(value, dtype=float)
                for value in (
                    state.position_base_in_world,
                    state.orientation_base_in_world_xyzw,
                    state.linear_velocity_base_in_world,
                    state.angular_velocity_base_in_base,
                )
            ),
        )
        if self._time_origin_s is None:
            self._time_origin_s = state.time_s
        return self.add(state.time_s - self._time_origin_s, robot, command, base_estimated=imu)


RunObserver = Callable[[Track], None]
"""Called with a run's track after every tick added to it (the live view).

The simulator, a replay and the bridge call it from their loops: it must
return quickly (the bridge's must not wait at all: a view in a process of its
own, :class:`~clients.visual.live_process.LiveViewProcess`).
"""


def session_track(
    name: str,
    hello: Hello,
    welcome: Welcome,
    backend: str,
    model_dir: Path | None = None,
) -> Track:
    """An empty track of the session a client opened with ``hello`` (a log, a replay).

    A model the client sent as text (``hello.model_text`` and its files) is
    written to ``model_dir`` (default: a new temporary directory) so that
    MuJoCo can load it.
    """
    return Track(
        name=name,
        controller=welcome.controller,
        backend=backend,
        model=_model_of_hello(hello, model_dir),
        keyframe=hello.keyframe,
        welcome=welcome,
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
