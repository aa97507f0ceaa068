"""Reference motion clips for the tracking objective.

Macchietto 2008, eq. 5.3::

    q̈_des = k_s (θ_mot − θ) + k_d (θ̇_mot − θ̇) + θ̈_mot

A :class:`MotionClip` supplies ``θ_mot``, ``θ̇_mot`` and the feed-forward
``θ̈_mot`` at any time. The paper takes the feed-forward "by finite
differences, or by computing the derivatives of fitted curves"; here the
derivatives are finite differences taken on the configuration manifold
(``pinocchio.difference``), so ball joints get body angular velocities and
accelerations rather than derivatives of quaternion components.

A clip file is JSON::

    {"name": "stand_sway",
     "model": "thesis_humanoid",           # informational
     "joint_names": [...],                  # wire order, must equal the robot's
     "time_s": [t0, t1, ...],               # k increasing values
     "joint_position": [[...], ...],        # k rows of wire joint positions
     "orientation_base_in_world_xyzw": [[x, y, z, w], ...]}   # optional, k rows

Joint rows use the wire layout (revolute and prismatic one value, ball joints
a quaternion ``[x, y, z, w]``), which is also Pinocchio's layout of
``q[7:]``. The base position is zero and its velocity and acceleration are
zero: the base is unactuated, the clip only suggests its orientation.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from controller_server.errors import InvalidParams
from controller_server.files import ServerFileKind, display_name
from controller_server.models import RobotModel

__all__ = [
    "CLIPS_DIR",
    "CLIP_FILES",
    "ClipSample",
    "MotionClip",
    "load_motion_clip",
    "make_sway_clip",
]

CLIPS_DIR = Path(__file__).resolve().parent.parent / "clips"
"""Folder of built-in clips, looked up by bare name (``<name>.json``)."""

FIELD = "params.clip"
MIN_QUATERNION_NORM = 1e-6
_BASE_NV = 6


def _fail(detail: str) -> InvalidParams:
    return InvalidParams(FIELD, detail)


CLIP_FILES = ServerFileKind(
    kind="clip",
    field=FIELD,
    builtin={path.stem: path for path in sorted(CLIPS_DIR.glob("*.json"))},
    suffixes=(".json",),
    not_found=_fail,
)
"""The clip files ``params.clip`` may name: built-ins, or files in the model directories."""


class ClipSample(NamedTuple):
    """Reference of eq. 5.3 at one instant, in Pinocchio conventions.

    Attributes:
        q: Full configuration ``θ_mot``, ``(nq,)``; base at the origin.
        v: Full tangent velocity ``θ̇_mot``, ``(nv,)``; base components zero.
        a: Full feed-forward acceleration ``θ̈_mot``, ``(nv,)``; base components zero.
    """

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray


def _derivatives(
    d_a: np.ndarray, d_b: np.ndarray, h_a: np.ndarray, h_b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration at a frame from two neighbours (second order).

    Each neighbour at signed time offset ``h`` lies at tangent displacement
    ``d = q_i ⊖ … ≈ h v + h²/2 a`` (``pinocchio.difference`` from frame ``i``).
    Solving the two equations gives the central difference for neighbours on
    either side and the one-sided three-point formula at the ends, for any
    (non-uniform) time steps.
    """
    h_a, h_b = h_a[:, None], h_b[:, None]
    denominator = h_a * h_b * (h_b - h_a)
    velocity = (h_b**2 * d_a - h_a**2 * d_b) / denominator
    acceleration = 2.0 * (h_a * d_b - h_b * d_a) / denominator
    return velocity, acceleration


def _finite_differences(
    model: pin.Model, time_s: np.ndarray, configurations: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Tangent velocities and accelerations ``(k, nv)`` of a frame sequence."""
    k = len(time_s)
    if k == 2:
        # Two frames only: one constant velocity, no acceleration.
        step = pin.difference(model, configurations[0], configurations[1]) / (time_s[1] - time_s[0])
        velocities = np.vstack([step, step])
        accelerations = np.zeros_like(velocities)
    else:
        # Neighbours (a, b) of each frame: previous and next inside, the next
        # two (or previous two) at the ends.
        index = np.arange(k)
        a, b = index - 1, index + 1
        a[0], b[-1] = 2, k - 3
        d_a, d_b = (
            np.array(
                [
                    pin.difference(model, configurations[i], configurations[j])
                    for i, j in zip(index, neighbour, strict=True)
                ]
            )
            for neighbour in (a, b)
        )
        velocities, accelerations = _derivatives(d_a, d_b, time_s[a] - time_s, time_s[b] - time_s)
    velocities[:, :_BASE_NV] = 0.0
    accelerations[:, :_BASE_NV] = 0.0
    return velocities, accelerations


def _as_finite_array(value: Any, name: str, ndim: int) -> np.ndarray:
    """A finite float array of ``ndim`` dimensions, or :class:`InvalidParams`."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise _fail(f"`{name}` must be {'a list' if ndim == 1 else 'rows'} of numbers") from None
    if array.ndim != ndim:
        raise _fail(f"`{name}` must have {ndim} dimension(s), got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        row = int(np.flatnonzero((~np.isfinite(array)).reshape(len(array), -1).any(axis=1))[0])
        raise _fail(f"`{name}` has a non-finite value (row {row}): {array[row]}")
    return array


def _length(value: Any) -> int | None:
    """Length of a list, tuple or 1-D array row; ``None`` for anything else."""
    if isinstance(value, list | tuple) or (isinstance(value, np.ndarray) and value.ndim >= 1):
        return len(value)
    return None


def _check_rows(rows: Any, name: str, k: int, width: int) -> np.ndarray:
    """``k`` rows of ``width`` finite numbers each."""
    if _length(rows) != k:
        raise _fail(f"`{name}` must have one row per time ({k}), got {_length(rows)}")
    for row_index, row in enumerate(rows):
        if _length(row) != width:
            got = _length(row) if _length(row) is not None else type(row).__name__
            raise _fail(f"`{name}` row {row_index} must have {width} values, got {got}")
    return _as_finite_array(rows, name, 2)


def _check_quaternions(quaternions: np.ndarray, name: str) -> None:
    norms = np.linalg.norm(quaternions, axis=-1)
    if np.any(norms < MIN_QUATERNION_NORM):
        row = int(np.argwhere(norms < MIN_QUATERNION_NORM)[0][0])
        raise _fail(f"`{name}` row {row} has a zero quaternion: {quaternions[row]}")


@dataclass(frozen=True, eq=False)
class MotionClip:
    """A reference motion ``θ_mot(t)`` with its derivatives (Macchietto 2008, eq. 5.3).

    Build one with :func:`load_motion_clip`, :meth:`from_frames` or
    :meth:`from_function`; the arrays are read-only.

    Attributes:
        name: Clip name.
        model_name: Name of the robot model it was made for (informational).
        joint_names: Wire-order joint names.
        model: The robot's Pinocchio model (free-flyer root at joint 1).
        time_s: ``(k,)`` increasing frame times (s).
        configurations: ``(k, nq)`` full configurations ``θ_mot``.
        velocities: ``(k, nv)`` tangent velocities ``θ̇_mot`` (base zero).
        accelerations: ``(k, nv)`` feed-forward accelerations ``θ̈_mot`` (base zero).
    """

    name: str
    model_name: str
    joint_names: tuple[str, ...]
    model: pin.Model
    time_s: np.ndarray
    configurations: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray

    @property
    def duration_s(self) -> float:
        """Time from the first frame to the last (s)."""
        return float(self.time_s[-1] - self.time_s[0])

    @property
    def num_frames(self) -> int:
        """Number of frames ``k``."""
        return len(self.time_s)

    @classmethod
    def from_frames(
        cls,
        robot: RobotModel,
        time_s: Sequence[float] | np.ndarray,
        joint_position: Sequence[Sequence[float]] | np.ndarray,
        orientation_base_in_world_xyzw: Sequence[Sequence[float]] | np.ndarray | None = None,
        *,
        name: str = "clip",
    ) -> MotionClip:
        """Validate frames, normalise quaternions and difference on the manifold.

        Args:
            robot: The robot the clip drives.
            time_s: ``k`` strictly increasing frame times (s), ``k ≥ 2``.
            joint_position: ``k`` rows of wire joint positions (ball: xyzw).
            orientation_base_in_world_xyzw: ``k`` base quaternions; identity if omitted.
            name: Clip name.

        Returns:
            The clip with finite-difference velocities and accelerations.

        Raises:
            InvalidParams: ``params.clip``: shapes, non-finite values, times or quaternions.
        """
        model = robot.model
        time_array = _as_finite_array(time_s, "time_s", 1)
        k = len(time_array)
        if k < 2:
            raise _fail(f"a clip needs at least 2 frames, got {k}")
        steps = np.diff(time_array)
        if np.any(steps <= 0.0):
            row = int(np.argmax(steps <= 0.0)) + 1
            raise _fail(
                f"`time_s` must increase strictly; time_s[{row}]={time_array[row]!r} "
                f"after {time_array[row - 1]!r}"
            )
        joints = _check_rows(joint_position, "joint_position", k, robot.nq_joints)
        configurations = np.tile(pin.neutral(model), (k, 1))
        configurations[:, 7:] = joints
        if orientation_base_in_world_xyzw is not None:
            configurations[:, 3:7] = _check_rows(
                orientation_base_in_world_xyzw, "orientation_base_in_world_xyzw", k, 4
            )
            _check_quaternions(configurations[:, 3:7], "orientation_base_in_world_xyzw")
        for joint in robot.joints:
            if joint.kind == "ball":
                start = model.idx_qs[model.getJointId(joint.name)]
                _check_quaternions(configurations[:, start : start + 4], "joint_position")
        for q in configurations:
            pin.normalize(model, q)
        velocities, accelerations = _finite_differences(model, time_array, configurations)
        for array in (time_array, configurations, velocities, accelerations):
            array.setflags(write=False)
        return cls(
            name=name,
            model_name=robot.name,
            joint_names=tuple(joint.name for joint in robot.joints),
            model=model,
            time_s=time_array,
            configurations=configurations,
            velocities=velocities,
            accelerations=accelerations,
        )

    @classmethod
    def from_function(
        cls,
        robot: RobotModel,
        joint_position_fn: Callable[[float], Sequence[float] | np.ndarray],
        duration_s: float,
        rate_hz: float,
        *,
        name: str = "clip",
    ) -> MotionClip:
        """Sample ``t ↦ wire joint positions`` at ``rate_hz`` over ``[0, duration_s]``.

        Args:
            robot: The robot the clip drives.
            joint_position_fn: Wire joint positions (ball: xyzw) at time ``t`` (s).
            duration_s: Clip length (s); the last frame is at ``duration_s``.
            rate_hz: Frame rate (Hz); rounded so frames divide the duration evenly.
            name: Clip name.

        Returns:
            The clip, base orientation identity.

        Raises:
            InvalidParams: ``params.clip``: bad duration or rate, or bad rows.
        """
        if not (math.isfinite(duration_s) and duration_s > 0.0):
            raise _fail(f"duration must be positive and finite, got {duration_s=}")
        if not (math.isfinite(rate_hz) and rate_hz > 0.0):
            raise _fail(f"rate must be positive and finite, got {rate_hz=}")
        num_steps = max(1, round(duration_s * rate_hz))
        # Integer multiples first, one division: frame times print as 0.7, not 0.7000000000000001.
        time_s = np.arange(num_steps + 1) * duration_s / num_steps
        rows = [joint_position_fn(float(t)) for t in time_s]
        return cls.from_frames(robot, time_s, rows, name=name)

    def sample(
        self, time_s: float, *, start_s: float = 0.0, speed: float = 1.0, loop: bool = False
    ) -> ClipSample:
        """Reference ``(θ_mot, θ̇_mot, θ̈_mot)`` of eq. 5.3 at controller time ``time_s``.

        Clip time ``τ = (time_s − start_s) · speed`` counts from the first frame.
        Before it the first frame is held, after the last frame the last one
        (both with zero velocity and acceleration) unless ``loop``, which wraps
        ``τ`` modulo the duration. Between frames ``q`` is interpolated on the
        manifold, ``v`` and ``a`` linearly; at a frame time the frame itself is
        returned.

        Args:
            time_s: Controller time (s).
            start_s: Controller time at which the clip starts (s).
            speed: Playback rate (1 = as recorded); ``v`` scales by ``speed``, ``a`` by ``speed²``.
            loop: Repeat the clip instead of holding its last frame.

        Returns:
            Full ``q`` (nq), ``v`` and ``a`` (nv) with zero base velocity and acceleration.

        Raises:
            InvalidParams: ``params.speed`` negative or not finite, ``params.start_s``
                or ``params.time_s`` not finite.
        """
        if not (math.isfinite(speed) and speed >= 0.0):
            raise InvalidParams("params.speed", f"speed must be finite and ≥ 0, got {speed=}")
        for field, value in (("start_s", start_s), ("time_s", time_s)):
            if not math.isfinite(value):
                raise InvalidParams(f"params.{field}", f"must be finite, got {value!r}")
        tau = (time_s - start_s) * speed
        duration = self.duration_s
        if loop and tau >= duration:
            tau = math.fmod(tau, duration)
        if tau < 0.0 or tau > duration:
            frame = 0 if tau < 0.0 else -1
            zeros = np.zeros(self.model.nv)
            return ClipSample(self.configurations[frame].copy(), zeros, zeros.copy())
        clip_time = self.time_s[0] + tau
        last = self.num_frames - 1
        i = int(np.clip(np.searchsorted(self.time_s, clip_time, side="right") - 1, 0, last - 1))
        s = (clip_time - self.time_s[i]) / (self.time_s[i + 1] - self.time_s[i])
        scale_v, scale_a = speed, speed * speed
        if s <= 0.0 or s >= 1.0:
            # At a frame time (or rounding past the last one): the frame itself.
            frame = i if s <= 0.0 else i + 1
            return ClipSample(
                self.configurations[frame].copy(),
                scale_v * self.velocities[frame],
                scale_a * self.accelerations[frame],
            )
        q = pin.interpolate(self.model, self.configurations[i], self.configurations[i + 1], s)
        v = (1.0 - s) * self.velocities[i] + s * self.velocities[i + 1]
        a = (1.0 - s) * self.accelerations[i] + s * self.accelerations[i + 1]
        return ClipSample(q, scale_v * v, scale_a * a)

    def to_json(self, path: str | Path | None = None) -> str:
        """The clip as JSON text (one frame per line), also written to ``path`` if given.

        The base orientation is written only when some frame is not upright.
        """
        header = {
            "name": self.name,
            "model": self.model_name,
            "joint_names": list(self.joint_names),
            "time_s": self.time_s.tolist(),
        }
        lines = ["{"]
        lines += [f"  {json.dumps(key)}: {json.dumps(value)}," for key, value in header.items()]
        tables = {"joint_position": self.configurations[:, 7:]}
        orientation = self.configurations[:, 3:7]
        if not np.array_equal(orientation, np.tile([0.0, 0.0, 0.0, 1.0], (self.num_frames, 1))):
            tables["orientation_base_in_world_xyzw"] = orientation
        for table_index, (key, table) in enumerate(tables.items()):
            rows = ",\n".join(f"    {json.dumps(row, allow_nan=False)}" for row in table.tolist())
            comma = "," if table_index < len(tables) - 1 else ""
            lines.append(f"  {json.dumps(key)}: [\n{rows}\n  ]{comma}")
        lines.append("}")
        text = "\n".join(lines) + "\n"
        if path is not None:
            Path(path).write_text(text)
        return text


def _check_joint_names(joint_names: Any, robot: RobotModel) -> None:
    """The clip's joints must be the robot's in wire order; the message quotes only the robot's."""
    expected = [joint.name for joint in robot.joints]
    if joint_names == expected:
        return
    if not isinstance(joint_names, list):
        raise _fail(f"clip `joint_names` must be a list of the joints of {robot.name!r}")
    index = next(
        (i for i, name in enumerate(expected) if i >= len(joint_names) or joint_names[i] != name),
        len(expected),
    )
    where = (
        f"at index {index} the robot has {expected[index]!r}"
        if index < len(expected)
        else f"the robot has only {len(expected)} joints"
    )
    raise _fail(
        f"clip `joint_names` differ from the joints of {robot.name!r} in wire order: {where}"
    )


def load_motion_clip(path_or_name: str | Path, robot: RobotModel) -> MotionClip:
    """Load a clip file for ``robot`` (reference of Macchietto 2008, eq. 5.3).

    Args:
        path_or_name: A built-in clip name (a file of :data:`CLIPS_DIR`
            without ``.json``), or the path of a ``.json`` file in the
            server's model directories (see :data:`CLIP_FILES`).
        robot: The robot; the clip's ``joint_names`` must equal its joints in order.

    Returns:
        The clip with manifold finite-difference velocities and accelerations.

    Raises:
        InvalidParams: ``params.clip``: unknown or unreadable file (one
            message whatever the reason), bad JSON, other joints, wrong row
            lengths, non-finite values, non-increasing times or fewer than 2
            frames. Messages name the clip as given, never its server path.
        FileTooLarge: A file over the size cap.
    """
    name = os.fspath(path_or_name)
    _, text = CLIP_FILES.read_text(name)
    shown = display_name(name)
    try:
        document = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise _fail(f"{shown} is not a JSON clip: {exc}") from None
    if not isinstance(document, dict):
        raise _fail(f"{shown} must hold a JSON object, got {type(document).__name__}")
    missing = [key for key in ("joint_names", "time_s", "joint_position") if key not in document]
    if missing:
        raise _fail(f"{shown} lacks {', '.join(missing)}")
    _check_joint_names(document["joint_names"], robot)
    time_s = document["time_s"]
    if not isinstance(time_s, list):
        raise _fail(f"`time_s` must be a list of numbers, got {type(time_s).__name__}")
    return MotionClip.from_frames(
        robot,
        time_s,
        document["joint_position"],
        document.get("orientation_base_in_world_xyzw"),
        name=str(document.get("name", Path(name).stem)),
    )


def make_sway_clip(
    robot: RobotModel,
    *,
    joint_name: str = "lower_back",
    amplitude_rad: float = 0.1,
    frequency_hz: float = 0.5,
    duration_s: float = 2.0,
    rate_hz: float = 50.0,
    name: str = "stand_sway",
) -> MotionClip:
    """A sway ``θ(t) = amplitude · sin(2π f t)`` of one ball joint about its x axis.

    Every other joint stays at the neutral pose. The defaults (one period over
    2 s) give a clip that loops without a jump; they made ``stand_sway.json``
    for ``thesis_humanoid``.

    Raises:
        InvalidParams: ``params.clip`` if ``joint_name`` is not a ball joint of the robot.
    """
    ball_joints = [joint.name for joint in robot.joints if joint.kind == "ball"]
    if joint_name not in ball_joints:
        raise _fail(f"{joint_name!r} is not a ball joint of {robot.name!r}: {ball_joints}")
    start = robot.model.idx_qs[robot.model.getJointId(joint_name)] - 7
    neutral = pin.neutral(robot.model)[7:]

    def joint_position(t: float) -> np.ndarray:
        half_angle = 0.5 * amplitude_rad * math.sin(2.0 * math.pi * frequency_hz * t)
        row = neutral.copy()
        row[start : start + 4] = [math.sin(half_angle), 0.0, 0.0, math.cos(half_angle)]
        return row

    return MotionClip.from_function(robot, joint_position, duration_s, rate_hz, name=name)
