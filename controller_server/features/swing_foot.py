"""The swing foot toward its next foothold: de Lasa's E_swing (2010, §6.1, eq. 18).

"This objective first raises the foot to a user-specified step-height h and
then lowers it, all the while moving the foot forward." The feature is the
swing foot's contact frame: its origin ``y`` (world) and its rotation ``R``.
Its desired accelerations come from target objectives (eq. 6–7):

* parallel to the ground, ``y∥`` reaches the foothold at rest at the end of the
  swing duration ``T`` (the foothold may move while the foot swings: it is
  re-planned from the capture point every tick);
* perpendicular to the ground, ``y⊥`` reaches the step height ``h`` at rest
  at ``T/2``, then the ground at ``T`` while moving down at ``landing_speed``
  (the paper's ``y_r⊥ = h`` then 0), and after ``T`` keeps moving down at that
  speed until the foot touches: a late foot is pressed down, not held above
  the ground;
* the rotation reaches ``R_r`` (flat, facing the walk's heading) at rest at
  ``T``: a target objective on the rotation vector ``e = log(R_r Rᵀ)`` (world
  axes), ``−e → 0`` with ``ω`` as its rate (exact to first order in ``e``; a
  foot is off by a few degrees). A setpoint ``ω̇_d = k_p e − k_v ω`` (eq. 4) at
  ``k_p`` = 100 landed a foot that left the ground on its toe (MuJoCo) still
  3–4° toe-down, heel 14–16 mm up: the next stance began on the toe.

Each target objective hands over to a setpoint on its end point for the last
:data:`TARGET_HANDOVER_S` (re-planned every tick, eq. 7 amplifies what is
left of an error as ``T → 0``). The rows over ``q̈`` are the frame's Jacobian,
``ÿ = J q̈ + J̇ q̇`` (eq. 5)::

    [J_v; J_ω] q̈ = [ÿ_d; ω̇_d] − J̇ q̇
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from controller_server.features.objective import Objective
from controller_server.features.setpoint import setpoint_acceleration, target_acceleration

__all__ = [
    "TARGET_HANDOVER_S",
    "SwingTarget",
    "compute_swing_objective",
    "swing_acceleration",
    "swing_angular_acceleration",
]

TARGET_HANDOVER_S = 0.05
"""The target objectives hand over to a setpoint this long before their end (s)."""


@dataclass(frozen=True)
class SwingTarget:
    """Where and when one swing foot goes.

    Attributes:
        contact: Index of the swinging contact (``welcome.contacts`` order).
        position_target_in_world: Where the contact frame's origin lands (m); its z is the
            ground's height there.
        orientation_target_in_world: ``R_r``, the frame's ``(3, 3)`` rotation at landing.
        step_height: ``h``, the frame's height above the landing height at mid-swing (m).
        start_s: When the swing began (s, client time).
        duration_s: ``T``, the swing's duration (s).
        landing_speed: Downward speed at ``T`` and after it (m/s).
        stiffness: ``k_p`` of the foot's orientation and landing setpoints (1/s²).
    """

    contact: int
    position_target_in_world: np.ndarray
    orientation_target_in_world: np.ndarray
    step_height: float
    start_s: float
    duration_s: float
    landing_speed: float = 0.1
    stiffness: float = 100.0


def swing_acceleration(
    target: SwingTarget,
    time_s: float,
    position: np.ndarray,
    velocity: np.ndarray,
    stiffness: float,
    damping: float,
) -> np.ndarray:
    """``ÿ_d`` of the frame origin (world, m/s²) at ``time_s`` (eq. 6–7, then eq. 4).

    Args:
        target: The swing.
        time_s: Now (s).
        position: Frame origin ``y`` (m).
        velocity: ``ẏ`` (m/s).
        stiffness: ``k_p`` of the setpoints after the hand-over (1/s²).
        damping: ``k_v`` (1/s).
    """
    elapsed = time_s - target.start_s
    remaining = target.duration_s - elapsed
    goal = np.asarray(target.position_target_in_world, dtype=float)
    desired = np.empty(3)
    if remaining > TARGET_HANDOVER_S:
        desired[:2] = target_acceleration(
            position[:2], velocity[:2], goal[:2], np.zeros(2), remaining
        )
    else:
        desired[:2] = setpoint_acceleration(
            goal[:2], position[:2], velocity[:2], stiffness, damping
        )
    apex_remaining = 0.5 * target.duration_s - elapsed
    if apex_remaining > TARGET_HANDOVER_S:
        desired[2] = target_acceleration(
            position[2], velocity[2], goal[2] + target.step_height, np.zeros(()), apex_remaining
        )
    elif apex_remaining > 0.0:
        desired[2] = setpoint_acceleration(
            goal[2] + target.step_height, position[2], velocity[2], stiffness, damping
        )
    elif remaining > TARGET_HANDOVER_S:
        desired[2] = target_acceleration(
            position[2], velocity[2], goal[2], np.full((), -target.landing_speed), remaining
        )
    else:  # down at the landing speed until the foot touches
        desired[2] = damping * (-target.landing_speed - velocity[2])
    return desired


def swing_angular_acceleration(
    target: SwingTarget,
    time_s: float,
    rotation: np.ndarray,
    angular_velocity: np.ndarray,
    stiffness: float,
    damping: float,
) -> np.ndarray:
    """``ω̇_d`` of the frame (world, rad/s²) at ``time_s`` (eq. 6–7 on ``log(R_r Rᵀ)``, then eq. 4).

    Args:
        target: The swing.
        time_s: Now (s).
        rotation: The frame's rotation ``R`` in the world.
        angular_velocity: ``ω`` (world, rad/s).
        stiffness: ``k_p`` of the setpoint after the hand-over (1/s²).
        damping: ``k_v`` (1/s).
    """
    error = pin.log3(target.orientation_target_in_world @ rotation.T)
    remaining = target.duration_s - (time_s - target.start_s)
    if remaining > TARGET_HANDOVER_S:
        return target_acceleration(-error, angular_velocity, np.zeros(3), np.zeros(3), remaining)
    return setpoint_acceleration(np.zeros(3), -error, angular_velocity, stiffness, damping)


def compute_swing_objective(
    target: SwingTarget,
    time_s: float,
    jacobian: np.ndarray,
    drift: np.ndarray,
    position: np.ndarray,
    rotation: np.ndarray,
    v: np.ndarray,
    stiffness: float,
    damping: float,
    weight: float,
    name: str = "swing",
) -> Objective:
    """Rows ``J`` and ``[ÿ_d; ω̇_d] − J̇ q̇`` of the swing foot's frame (eq. 5, 6–7, 4).

    Args:
        target: The swing.
        time_s: Now (s).
        jacobian: ``(6, nv)`` ``[v_origin; ω]`` of the contact frame, world axes.
        drift: ``(6,)`` ``J̇ q̇`` (classical linear and angular acceleration at ``q̈ = 0``).
        position: Frame origin (m, world).
        rotation: Frame rotation ``R`` in the world.
        v: Generalized velocity.
        stiffness: ``k_p`` of the hand-over setpoints (1/s²).
        damping: ``k_v`` (1/s).
        weight: α of every row.
        name: Objective name.
    """
    twist = jacobian @ v
    linear = swing_acceleration(target, time_s, position, twist[:3], stiffness, damping)
    angular = swing_angular_acceleration(target, time_s, rotation, twist[3:], stiffness, damping)
    return Objective(name, jacobian, np.concatenate([linear, angular]) - drift, np.full(6, weight))
