"""Soft joint limits: limit violations that stiffen the tracking gains.

Macchietto 2008, §6.2: rather than constraining the joints, the tracking
gains of eq. 5.3 are raised on a joint in proportion to how far it is past its
limits (eq. 6.5–6.6)::

    k'_s = k_s + l_s (e_axis + e_twist)
    k'_d = k_d + l_d (e_axis + e_twist)

Ball joints are limited by a swing cone on the bone axis (``e_axis``) and a
twist interval (``e_twist``), see :mod:`controller_server.features.swing_twist`;
revolute and prismatic joints by a box on their coordinate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from controller_server.compiled import load_core
from controller_server.errors import ModelError
from controller_server.features.swing_twist import (
    SwingCone,
    cones_contain_units,
    rotate,
    swing_twist,
    twist_angle,
)
from controller_server.math.spatial import cross

if TYPE_CHECKING:
    from collections.abc import Iterable

    from controller_server.models import RobotModel

__all__ = [
    "BallJointLimit",
    "JointLimit",
    "JointLimitSet",
    "RevoluteJointLimit",
    "default_joint_limits",
    "joint_limit_errors",
    "soft_limit_gains",
]

_MAX_DEFAULT_TWIST_RAD = math.pi / 2
"""Default twist range is ±min(swing limit, π/2): MJCF ``range`` gives no twist bound."""


def _box_violation(value: float, lower: float, upper: float) -> float:
    """Distance of ``value`` outside ``[lower, upper]``, ``0`` inside."""
    return max(lower - value, 0.0, value - upper)


@dataclass(frozen=True, eq=False)
class BallJointLimit:
    """Swing cone and twist interval of a ball joint (Macchietto 2008, §6.2).

    Attributes:
        name: Joint name.
        idx_q: Index of the joint's quaternion ``[x, y, z, w]`` in the full ``q``.
        idx_v: Index of its 3 angular-velocity DoFs in the full ``v``.
        bone_axis_in_parent: Unit bone axis ``a`` at rest, in the parent-side
            joint frame (equal to the child frame at rest).
        cone: Allowed directions of ``a' = q a q⁻¹``.
        twist_lower_rad: ``α_l``, lowest twist about ``a``.
        twist_upper_rad: ``α_u``, highest twist about ``a`` (``α_l < α_u``).
    """

    nv: ClassVar[int] = 3

    name: str
    idx_q: int
    idx_v: int
    bone_axis_in_parent: np.ndarray
    cone: SwingCone
    twist_lower_rad: float
    twist_upper_rad: float

    def __post_init__(self) -> None:
        axis = np.array(self.bone_axis_in_parent, dtype=float)
        norm = float(np.linalg.norm(axis)) if axis.shape == (3,) else 0.0
        if not norm > 1e-12 or not math.isfinite(norm):
            raise ValueError(f"joint {self.name!r}: bone axis must be a non-zero 3-vector, {axis=}")
        if not self.twist_lower_rad < self.twist_upper_rad:
            raise ValueError(
                f"joint {self.name!r}: need twist_lower_rad < twist_upper_rad, got "
                f"{self.twist_lower_rad=}, {self.twist_upper_rad=}"
            )
        axis /= norm
        axis.setflags(write=False)
        object.__setattr__(self, "bone_axis_in_parent", axis)

    def error(self, q: np.ndarray) -> float:
        """``e_axis + e_twist`` (rad) at configuration ``q`` (Macchietto 2008, §6.2).

        ``e_twist`` is the distance of the twist angle ``φ`` outside
        ``[α_l, α_u]`` and ``0`` inside; the thesis's ``min(|α_l − φ|, |α_u − φ|)``
        equals it only outside the interval.
        """
        quaternion = np.asarray(q[self.idx_q : self.idx_q + 4], dtype=float)
        if self._within(quaternion):
            return 0.0
        axis_error_rad = self.cone.violation(rotate(quaternion, self.bone_axis_in_parent))
        _, twist = swing_twist(quaternion, self.bone_axis_in_parent)
        twist_rad = twist_angle(twist, self.bone_axis_in_parent)
        twist_error_rad = _box_violation(twist_rad, self.twist_lower_rad, self.twist_upper_rad)
        return axis_error_rad + twist_error_rad

    def _within(self, quaternion: np.ndarray) -> bool:
        """Cheap test that both errors are zero (the common case), in scalar arithmetic."""
        x, y, z, w = quaternion.tolist()
        norm = math.sqrt(x * x + y * y + z * z + w * w)
        x, y, z, w = x / norm, y / norm, z / norm, w / norm
        ax, ay, az = self.bone_axis_in_parent.tolist()
        # a' = a + w t + u × t with t = 2 u × a (rotation of the bone axis).
        tx, ty, tz = 2 * (y * az - z * ay), 2 * (z * ax - x * az), 2 * (x * ay - y * ax)
        bone = np.array(
            [
                ax + w * tx + y * tz - z * ty,
                ay + w * ty + z * tx - x * tz,
                az + w * tz + x * ty - y * tx,
            ]
        )
        # Twist angle about a: 2 atan2(u·a, w), wrapped to (−π, π].
        twist = 2.0 * math.atan2(x * ax + y * ay + z * az, w)
        twist = (
            twist - 2 * math.pi
            if twist > math.pi
            else twist + 2 * math.pi
            if twist <= -math.pi
            else twist
        )
        return self.twist_lower_rad <= twist <= self.twist_upper_rad and self.cone.contains_unit(
            bone
        )


@dataclass(frozen=True)
class RevoluteJointLimit:
    """Box limit of a 1-DoF joint: rad for revolute, m for prismatic joints.

    Attributes:
        name: Joint name.
        idx_q: Index of the joint coordinate in the full ``q``.
        idx_v: Index of its DoF in the full ``v``.
        lower: Lowest position.
        upper: Highest position.
    """

    nv: ClassVar[int] = 1

    name: str
    idx_q: int
    idx_v: int
    lower: float
    upper: float

    def error(self, q: np.ndarray) -> float:
        """Distance of the coordinate outside ``[lower, upper]``, ``0`` inside."""
        return _box_violation(float(q[self.idx_q]), self.lower, self.upper)


JointLimit = BallJointLimit | RevoluteJointLimit
"""Any joint limit: both kinds have ``error(q)``, ``idx_v`` and ``nv``."""


def default_joint_limits(robot: RobotModel) -> tuple[JointLimit, ...]:
    """One limit per actuated joint, from the model file.

    Ball joints: the bone axis points from the joint to the child body's centre
    of mass (``model.inertias[joint].lever``; joint-frame ``−z`` if the centre
    of mass is on the joint); the swing cone is
    ``SwingCone.regular(axis, ball_swing_limit[name])`` (an 8-sided cone
    inscribed in the circular limit); the twist interval is ``±min(swing, π/2)``
    since MJCF gives no twist limit. Revolute and prismatic joints: the box
    ``[lowerPositionLimit, upperPositionLimit]``.

    Args:
        robot: The robot; joint 1 is the free-flyer root and gets no limit.

    Returns:
        Limits in the order of ``robot.joints``.

    Raises:
        ModelError: A ball joint's swing limit is not positive.
    """
    model = robot.model
    limits: list[JointLimit] = []
    for info in robot.joints:
        joint_id = model.getJointId(info.name)
        joint = model.joints[joint_id]
        if info.kind != "ball":
            limits.append(
                RevoluteJointLimit(
                    name=info.name,
                    idx_q=joint.idx_q,
                    idx_v=joint.idx_v,
                    lower=float(model.lowerPositionLimit[joint.idx_q]),
                    upper=float(model.upperPositionLimit[joint.idx_q]),
                )
            )
            continue
        lever = np.asarray(model.inertias[joint_id].lever, dtype=float)
        lever_length = float(np.linalg.norm(lever))
        axis = lever / lever_length if lever_length > 1e-9 else np.array([0.0, 0.0, -1.0])
        swing_rad = float(robot.ball_swing_limit.get(info.name, math.pi))
        if not swing_rad > 0.0:
            raise ModelError(f"ball joint {info.name!r} has {swing_rad=}; it must be > 0")
        twist_rad = min(swing_rad, _MAX_DEFAULT_TWIST_RAD)
        limits.append(
            BallJointLimit(
                name=info.name,
                idx_q=joint.idx_q,
                idx_v=joint.idx_v,
                bone_axis_in_parent=axis,
                cone=SwingCone.regular(axis, swing_rad),
                twist_lower_rad=-twist_rad,
                twist_upper_rad=twist_rad,
            )
        )
    return tuple(limits)


class JointLimitSet:
    """A robot's joint limits, screened for violations in one vectorized pass.

    Most joints are inside their limits on most ticks. Box limits are evaluated
    for all 1-DoF joints at once; for ball joints the cheap inside test of
    :class:`BallJointLimit` runs on all quaternions at once, and only the
    joints it finds outside go through the exact (per-joint) error.

    Args:
        limits: Joint limits, e.g. from :func:`default_joint_limits`.
        nv: Size of the velocity vector.
    """

    def __init__(self, limits: Iterable[JointLimit], nv: int):
        self.limits = tuple(limits)
        self.nv = nv
        boxes = [limit for limit in self.limits if isinstance(limit, RevoluteJointLimit)]
        self._box_idx_q = np.array([limit.idx_q for limit in boxes], dtype=int)
        self._box_idx_v = np.array([limit.idx_v for limit in boxes], dtype=int)
        self._box_lower = np.array([limit.lower for limit in boxes], dtype=float)
        self._box_upper = np.array([limit.upper for limit in boxes], dtype=float)
        self._balls = [limit for limit in self.limits if isinstance(limit, BallJointLimit)]
        self._ball_idx_q = np.array([limit.idx_q for limit in self._balls], dtype=int)[:, None]
        self._ball_idx_q = self._ball_idx_q + np.arange(4)
        self._axes = np.array([limit.bone_axis_in_parent for limit in self._balls]).reshape(-1, 3)
        self._twist_lower = np.array([limit.twist_lower_rad for limit in self._balls])
        self._twist_upper = np.array([limit.twist_upper_rad for limit in self._balls])
        sides = max((len(ball.cone.face_normals_in_parent) for ball in self._balls), default=0)
        # Faces padded by repeating the first one: the max (min) projection is unchanged.
        self._normals = np.zeros((len(self._balls), max(sides, 1), 3))
        for row, ball in zip(self._normals, self._balls, strict=True):
            normals = ball.cone.face_normals_in_parent
            if len(normals):
                row[:] = normals[np.minimum(np.arange(len(row)), len(normals) - 1)]
        self._reflex = np.array([ball.cone.reflex for ball in self._balls], dtype=bool)
        self._unlimited = np.array(
            [not len(ball.cone.face_normals_in_parent) for ball in self._balls], dtype=bool
        )

    def errors(self, q: np.ndarray) -> np.ndarray:
        """Limit violation per DoF, ``(nv,)``: as :func:`joint_limit_errors`."""
        errors = np.zeros(self.nv)
        if self._box_idx_q.size:
            value = q[self._box_idx_q]
            errors[self._box_idx_v] = np.maximum(
                np.maximum(self._box_lower - value, 0.0), value - self._box_upper
            )
        if self._balls:
            for index in np.flatnonzero(~self._balls_within(q)).tolist():
                ball = self._balls[index]
                errors[ball.idx_v : ball.idx_v + 3] = ball.error(q)
        return errors

    def _balls_within(self, q: np.ndarray) -> np.ndarray:
        """:meth:`BallJointLimit._within` for every ball joint at once."""
        quaternions = q[self._ball_idx_q]
        quaternions = quaternions / np.sqrt((quaternions * quaternions).sum(axis=1))[:, None]
        u, w = quaternions[:, :3], quaternions[:, 3:]
        a = self._axes
        t = 2.0 * cross(u, a)
        bone = a + w * t + cross(u, t)
        twist = 2.0 * np.arctan2((u * a).sum(axis=1), w[:, 0])
        twist = np.where(twist > math.pi, twist - 2 * math.pi, twist)
        twist = np.where(twist <= -math.pi, twist + 2 * math.pi, twist)
        inside = cones_contain_units(self._normals, self._reflex, self._unlimited, bone)
        return inside & (self._twist_lower <= twist) & (twist <= self._twist_upper)

    def compiled(self) -> Any:
        """These limits in the compiled core, for the compiled tick: ``_core.JointLimits``.

        Its ``errors(q)`` is :meth:`errors` in C++ (``controller_server/core/joint_limits.cpp``,
        agreeing to rounding: ``tests/controller_server/test_compiled_joint_limits.py``). The
        limits go over as they are here, so Python stays their source: each box's
        ``lower``/``upper``; each ball's bone axis, its cone's face normals, edges and
        ``reflex``, and its twist interval.

        Returns:
            A ``controller_server._core.JointLimits`` of ``nv`` DoFs.

        Raises:
            CompiledCoreUnavailable: The compiled core is not built (or stale).
        """
        core = load_core()
        boxes = [
            core.BoxLimit(
                name=limit.name,
                idx_q=limit.idx_q,
                idx_v=limit.idx_v,
                lower=limit.lower,
                upper=limit.upper,
            )
            for limit in self.limits
            if isinstance(limit, RevoluteJointLimit)
        ]
        balls = [
            core.BallLimit(
                name=ball.name,
                idx_q=ball.idx_q,
                idx_v=ball.idx_v,
                bone_axis_in_parent=ball.bone_axis_in_parent,
                face_normals_in_parent=ball.cone.face_normals_in_parent.reshape(-1, 3),
                edges_in_parent=ball.cone.edges_in_parent.reshape(-1, 3),
                reflex=ball.cone.reflex,
                twist_lower_rad=ball.twist_lower_rad,
                twist_upper_rad=ball.twist_upper_rad,
            )
            for ball in self._balls
        ]
        return core.JointLimits(self.nv, boxes, balls)


def joint_limit_errors(limits: Iterable[JointLimit], q: np.ndarray, nv: int) -> np.ndarray:
    """Limit violation per DoF (Macchietto 2008, §6.2).

    Each ball joint's ``e_axis + e_twist`` is written on all 3 of its DoFs,
    since the tracking gains of the whole joint are raised; a 1-DoF joint gets
    its box violation. DoFs without a limit (the free-flyer root) get ``0``.
    A controller evaluating the same limits every tick keeps a
    :class:`JointLimitSet` instead.

    Args:
        limits: Joint limits, e.g. from :func:`default_joint_limits`.
        q: Configuration, ``(nq,)``.
        nv: Size of the velocity vector.

    Returns:
        ``(nv,)`` non-negative errors (rad, or m for prismatic joints).
    """
    return JointLimitSet(limits, nv).errors(q)


def soft_limit_gains(
    stiffness: float | np.ndarray,
    damping: float | np.ndarray,
    limit_stiffness: float | np.ndarray,
    limit_damping: float | np.ndarray,
    errors: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Tracking gains raised by the limit errors (Macchietto 2008, eq. 6.5–6.6).

    ``k'_s = k_s + l_s e`` and ``k'_d = k_d + l_d e``, per DoF.

    Args:
        stiffness: ``k_s`` (1/s²), scalar or per DoF.
        damping: ``k_d`` (1/s), scalar or per DoF.
        limit_stiffness: ``l_s`` (1/s² per unit error), scalar or per DoF.
        limit_damping: ``l_d`` (1/s per unit error), scalar or per DoF.
        errors: ``(nv,)`` errors from :func:`joint_limit_errors`.

    Returns:
        ``(stiffness_per_dof, damping_per_dof)``, each ``(nv,)``.
    """
    e = np.asarray(errors, dtype=float)
    stiffness_per_dof, damping_per_dof = np.empty(e.shape), np.empty(e.shape)
    stiffness_per_dof[...] = stiffness + np.multiply(limit_stiffness, e)
    damping_per_dof[...] = damping + np.multiply(limit_damping, e)
    return stiffness_per_dof, damping_per_dof
