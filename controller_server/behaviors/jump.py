"""Standing and twisting jumps (de Lasa, Mordatch & Hertzmann 2010, §5, Fig. 2).

The state machine sets the balance controller's references, weights and
priorities as the jump goes (its :class:`Targets`, applied for each tick over
the client's parameters):

* ``stand``: balance for ``jump_delay_s``. The pose the jump starts from is
  the rest pose throughout: bent knees keep the CM height controllable (at
  straight knees its Jacobian vanishes and nothing crouches).
* ``compress``: a target objective (eq. 6–7) lowers the CM by
  ``jump_crouch_depth`` over ``jump_compress_duration_s``. For the jump the
  CM height objective ranks at ``jump_com_height_priority`` (default 3),
  below the angular momentum, and the rest pose and the trunk one level
  below it. Ranked with the angular momentum (Table 1's level), the thrust
  traded angular momentum for height and the robot left the ground pitching
  at 3 rad/s. With the trunk held upright above it, lowering the CM while
  the angular momentum is damped left only the arms to move (they swung past
  their limits, or stalled at them); the trunk leans instead.
* ``thrust``: a target objective raises the CM toward the standing pose's
  height (legs straight) at ``jump_takeoff_speed`` (eq. 7's ẏ_T, held after
  T), with vertical reference angular momentum ``jump_twist_angular_momentum``
  for a twisting jump.
* ``ascent`` once the CM, rising at half the take-off speed or more, is
  within ``jump_takeoff_margin`` of that height, or no foot touches: no
  contact is planned any more (``support_mask`` 0), the contact, CM, CM
  height, trunk and angular momentum objectives are off, and the rest pose
  becomes the take-off pose, held at ``jump_flight_pose_stiffness``: the
  body leaves as one. Straightening the knees further made the thrust
  saturate the torques and pitch the body; holding the trunk in the air took
  limb motions as large as the gain bound allowed.
* ``descent`` once the CM moves down.
* ``impact`` at the first touch while descending (a touch while rising is
  the take-off's scuffle; contact changes count after
  :data:`CONTACT_CHANGE_S`), or :data:`TAKEOFF_TIMEOUT_S` into a take-off
  that never left the ground: supports, contact, CM, trunk and angular
  momentum objectives back (L_r = 0), the rest pose back to the starting
  pose, and a target objective brings the falling CM back to the height it
  landed at within ``jump_landing_duration_s`` (over 0.6 s, a 10 cm jump's
  landing dipped so deep that a shin touched the floor).
* ``recover`` once the CM moves up again (or after :data:`IMPACT_HOLD_S`): a
  target objective brings the CM back to its starting height over
  ``jump_recover_duration_s``.
* ``done``: every weight, priority, gain and mask is back to the client's;
  the robot keeps standing in the pose it jumped from, at the CM height it
  jumped from, its trunk facing the way its feet landed.

A twisting jump can twist its body in the air too (``jump_flight_twist``,
0 by default): from take-off the spine (the ball joints that carry the arms
and head) turns the upper body that far behind the pelvis about the
vertical, half on each spine joint; with the vertical angular momentum
conserved, the pelvis and the legs turn further the twist's way. And from
the top of the flight (``descent``) the legs take back the rest pose: it
unwinds the twist the thrust left in the knees and ankles (the feet turn on
to the pelvis's heading) and they land less bent. After touch-down the
rest pose untwists the spine as the upper body's remaining spin catches up.
Held in the take-off pose instead, the thesis humanoid's half turn reached
about 140°: more angular momentum before take-off than L_r 11 rocked a
sole onto its corners (the twist asked more yaw moment than the soles'
friction gives), and in MuJoCo a shin touched the floor at landings with
the legs still twisted.

E_ankle (``ankle``: the feet at their take-off offset from the CM, and
flat) is on in flight at ``jump_ankle_weight``, 0 by default: on the
thesis and revolute humanoids it turned the body in the air (the rigid
take-off pose lands them better).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin

from controller_server.behaviors.behavior import Behavior, FeetFromCom, Targets
from controller_server.behaviors.limbs import spine_joints
from controller_server.behaviors.observation import Observation
from controller_server.models import RobotModel
from controller_server.params import ParamSpec

__all__ = ["JUMP_PARAMETERS", "JUMP_STATES", "StandingJump"]

JUMP_STATES = ("stand", "compress", "thrust", "ascent", "descent", "impact", "recover", "done")
IMPACT_HOLD_S = 0.3
"""Longest ``impact``: then ``recover`` starts even if the CM is still moving down."""
CONTACT_CHANGE_S = 0.01
"""Take-off and touch-down count once the contact flags have said so this long (a sole
bounces at the instant it leaves or meets the ground)."""
TAKEOFF_TIMEOUT_S = 0.3
"""A take-off whose feet have not left the ground this long lands where it is."""

JUMP_PARAMETERS: dict[str, ParamSpec] = {
    "jump_delay_s": ParamSpec(
        0.3, minimum=0.0, maximum=60.0, doc="jump: balance this long before compressing (s)"
    ),
    "jump_crouch_depth": ParamSpec(
        0.12, minimum=0.0, maximum=1.0, doc="jump: CM lowered by this much in `compress` (m)"
    ),
    "jump_compress_duration_s": ParamSpec(
        0.4, minimum=0.05, maximum=10.0, doc="jump: T of the crouch's target objective (s)"
    ),
    "jump_takeoff_speed": ParamSpec(
        2.6,
        minimum=0.0,
        maximum=10.0,
        doc="jump: upward CM speed `thrust` asks for at the standing pose's height (m/s)",
    ),
    "jump_thrust_duration_s": ParamSpec(
        0.25, minimum=0.05, maximum=10.0, doc="jump: T of the thrust's target objective (s)"
    ),
    "jump_takeoff_margin": ParamSpec(
        0.08,
        minimum=0.0,
        maximum=1.0,
        doc="jump: take-off (`ascent`) this far below the standing pose's CM height, "
        "before the knees straighten (m)",
    ),
    "jump_twist_angular_momentum": ParamSpec(
        0.0,
        minimum=-1e3,
        maximum=1e3,
        doc="jump: vertical L_r during `thrust` (kg·m²/s); non-zero twists the jump",
    ),
    "jump_flight_twist": ParamSpec(
        0.0,
        minimum=0.0,
        maximum=2.0,
        doc="jump: in flight the spine turns the upper body this far behind the pelvis, the "
        "twist's way, and from the top of the flight the legs take back the rest pose (rad, "
        "ball-joint spines); 0 = the take-off pose throughout the flight",
    ),
    "jump_com_height_priority": ParamSpec(
        3,
        kind="int",
        minimum=1,
        maximum=9,
        doc="jump: priority of `com_height` during the jump (the rest pose one below it)",
    ),
    "jump_com_height_weight": ParamSpec(
        10.0, minimum=0.0, maximum=1e6, doc="jump: α of `com_height` during the jump"
    ),
    "jump_flight_pose_stiffness": ParamSpec(
        200.0,
        minimum=0.0,
        maximum=1e6,
        doc="jump: k_p of `pose` in flight, holding the take-off pose (1/s²)",
    ),
    "jump_ankle_weight": ParamSpec(
        0.0, minimum=0.0, maximum=1e6, doc="jump: α of `ankle` (E_ankle) in flight; 0 = off"
    ),
    "jump_landing_duration_s": ParamSpec(
        0.25,
        minimum=0.05,
        maximum=10.0,
        doc="jump: T of the target objective that stops the CM's fall after touch-down, back "
        "to the height it landed at (s); longer lands softer and deeper",
    ),
    "jump_recover_duration_s": ParamSpec(
        0.6, minimum=0.05, maximum=10.0, doc="jump: T of the return to standing height (s)"
    ),
}
"""The jump's parameters (``set_params``), documented in docs/controllers.md."""


class StandingJump(Behavior):
    """One standing (or twisting) jump, from ``stand`` to ``done`` (see the module docstring).

    The pose it jumps from (the joints at its first tick) is the rest pose from then on; its
    CM height then is the height the landing recovers. The thrust aims at the standing
    pose's CM height (legs straight); the spine (:func:`spine_joints`) twists in flight
    (``jump_flight_twist``). After ``done`` it keeps asking for that pose and CM height,
    and for the trunk to face the way the feet landed, until another ``behavior`` is set.

    Attributes:
        state: The current state (:data:`JUMP_STATES`).
    """

    name = "jump"
    SUMMARY = "one standing (or twisting) jump, de Lasa §5 (the `jump_` parameters)"
    PARAMETERS = JUMP_PARAMETERS
    HOSTS = ("prioritized",)

    def __init__(self, robot: RobotModel):
        super().__init__(robot)
        model = robot.model
        self._reach = float(
            pin.centerOfMass(model, model.createData(), robot.standing_configuration)[2]
        )
        self._standing = np.nan  # the CM height it jumps from, set at the first tick
        self._feet_heading = 0.0  # the feet's mean heading then (rad)
        self._rest_pose: list[float] = []  # the pose it jumps from, set at the first tick
        self._spine = spine_joints(model)
        self._since_s: float | None = None
        self._ankle_offsets: np.ndarray | None = None
        self._foot_rotations: np.ndarray | None = None
        self._airborne = False
        self._left_ground = False
        self._thrust_end_s = np.inf  # when ascent began
        self._flags_since_s = -np.inf  # when the flags last went from some to none or back

    def update(self, observation: Observation, params: Mapping[str, Any]) -> Targets:
        """This tick's targets: the parameters the states so far have set, and ``ankle``'s."""
        self._advance(observation, params)
        feet = None
        if self._foot_rotations is not None:
            feet = FeetFromCom(self._ankle_offsets, self._foot_rotations)
        return self._targets(feet_from_com=feet)

    def _advance(self, observation: Observation, params: Mapping[str, Any]) -> None:
        o, p = observation, params
        if self._since_s is None:
            self._since_s = o.time_s
        elapsed = o.time_s - self._since_s
        height = o.position_com_in_world[2] - o.ground_height
        rising = o.velocity_com_in_world[2] > 0.0
        if self._airborne == any(o.touching):
            self._airborne = not self._airborne
            self._flags_since_s = o.time_s
        settled = o.time_s - self._flags_since_s >= CONTACT_CHANGE_S
        airborne, grounded = self._airborne and settled, not self._airborne and settled
        if self.state == "stand" and elapsed == 0.0:
            self._standing = float(height)
            self._feet_heading = _feet_heading(o.orientation_contact_frames_in_world)
            # The pose it jumps from is the rest pose: bent knees keep the CM height
            # controllable (at straight knees its Jacobian vanishes).
            self._rest_pose = [float(x) for x in o.joint_position]
            self._set(reference_joint_position=self._rest_pose)
            return
        if self.state == "stand" and elapsed >= p["jump_delay_s"]:
            self._enter(
                o,
                "compress",
                com_height=self._standing - p["jump_crouch_depth"],
                com_height_duration_s=p["jump_compress_duration_s"],
                priority_com_height=p["jump_com_height_priority"],
                priority_pose=p["jump_com_height_priority"] + 1,
                priority_trunk=p["jump_com_height_priority"] + 1,
                weight_com_height=p["jump_com_height_weight"],
            )
            return
        if self.state == "compress" and elapsed >= p["jump_compress_duration_s"]:
            self._enter(
                o,
                "thrust",
                com_height=self._reach,
                com_height_velocity=p["jump_takeoff_speed"],
                com_height_duration_s=p["jump_thrust_duration_s"],
                reference_angular_momentum=[0.0, 0.0, p["jump_twist_angular_momentum"]],
            )
            return
        takeoff_height = self._reach - p["jump_takeoff_margin"]
        launched = o.velocity_com_in_world[2] >= 0.5 * p["jump_takeoff_speed"]
        if self.state == "thrust" and (airborne or (launched and height >= takeoff_height)):
            # The feet keep the orientation they stand in (flat) from now to touch-down.
            self._foot_rotations = o.orientation_contact_frames_in_world.copy()
            self._thrust_end_s = o.time_s
            self._unset("priority_pose")
            self._enter(
                o,
                "ascent",
                weight_contact=0.0,
                weight_com=0.0,
                weight_com_height=0.0,
                com_height_velocity=0.0,
                weight_trunk=0.0,
                weight_angular_momentum=0.0,
                pose_stiffness=p["jump_flight_pose_stiffness"],
                weight_ankle=p["jump_ankle_weight"],
                support_mask=[0.0] * len(o.touching),
                # The legs keep the pose they leave in: the crouch would tuck them while
                # the feet still push (measured: the torques saturated).
                reference_joint_position=self._twisted([float(x) for x in o.joint_position], p),
            )
            return
        if self.state == "ascent" and not rising:
            if p["jump_flight_twist"] > 0.0:
                # The legs unwind the thrust's twist and straighten a little to land.
                self._enter(
                    o, "descent", reference_joint_position=self._twisted(self._rest_pose, p)
                )
                return
            self._enter(o, "descent")
        if self.state in ("ascent", "descent") and airborne and not self._left_ground:
            # In the air: the ankles keep the offset from the CM they left the ground with
            # (held while the feet still touch, it pushed the feet into the ground).
            self._left_ground = True
            self._ankle_offsets = o.position_contact_frames_in_world - o.position_com_in_world
        thrust_failed = self.state == "thrust" and elapsed >= (
            p["jump_thrust_duration_s"] + TAKEOFF_TIMEOUT_S
        )
        never_left = (
            self.state in ("ascent", "descent")
            and not self._left_ground
            and o.time_s - self._thrust_end_s >= TAKEOFF_TIMEOUT_S
        )
        # A touch while the CM still rises is the take-off's scuffle, not the landing.
        landed = self.state == "descent" and self._left_ground and grounded
        if thrust_failed or never_left or landed:
            # The client's own contact, CM, trunk, angular momentum weights, supports and
            # pose stiffness are back.
            self._unset(
                "weight_contact",
                "weight_com",
                "weight_trunk",
                "support_mask",
                "pose_stiffness",
                "weight_angular_momentum",
            )
            self._enter(
                o,
                "impact",
                weight_com_height=p["jump_com_height_weight"],
                weight_ankle=0.0,
                priority_pose=p["jump_com_height_priority"] + 1,
                priority_trunk=p["jump_com_height_priority"] + 1,
                reference_joint_position=self._rest_pose,
                com_height=float(height),
                com_height_duration_s=p["jump_landing_duration_s"],
                reference_angular_momentum=[0.0, 0.0, 0.0],
                # Upright, facing the way its feet landed (a twisting jump turned it; the
                # pelvis, free to yaw on the hips, would turn back to where it took off).
                reference_trunk_orientation_xyzw=_turned(
                    p["reference_trunk_orientation_xyzw"],
                    _feet_heading(o.orientation_contact_frames_in_world) - self._feet_heading,
                ),
            )
            return
        if self.state == "impact" and (rising or elapsed >= IMPACT_HOLD_S):
            self._enter(
                o,
                "recover",
                com_height=self._standing,
                com_height_duration_s=p["jump_recover_duration_s"],
            )
            return
        if self.state == "recover" and elapsed >= p["jump_recover_duration_s"]:
            self._ankle_offsets = self._foot_rotations = None
            # It stands where it jumped from, facing the way it landed: that pose, CM height
            # and trunk heading stay the references, every other parameter is the client's.
            kept = ("reference_joint_position", "reference_trunk_orientation_xyzw")
            self._unset(*(name for name in self.overrides if name not in kept))
            self._enter(o, "done", com_height=self._standing)

    def _twisted(self, pose: list[float], params: Mapping[str, Any]) -> list[float]:
        """``pose``, its spine turning the upper body ``jump_flight_twist`` behind the pelvis."""
        twist = params["jump_flight_twist"] * np.sign(params["jump_twist_angular_momentum"])
        pose = list(pose)
        for start in self._spine:
            # Each spine joint turns its child about its parent's vertical.
            pose[start : start + 4] = _turned(pose[start : start + 4], -twist / len(self._spine))
        return pose

    def _enter(self, observation: Observation, state: str, **changes: Any) -> None:
        """Enter ``state``; a ``com_height`` among ``changes`` is reached by a target objective."""
        self.state = state
        self._since_s = observation.time_s
        self._set(**changes)
        if "com_height" in changes:
            self.com_height_changes += 1


def _feet_heading(orientations: np.ndarray) -> float:
    """Mean heading (yaw of the x axis) of the ``(contacts, 3, 3)`` contact frames (rad)."""
    x_axes = orientations[:, :2, 0].sum(axis=0)
    return float(np.arctan2(x_axes[1], x_axes[0]))


def _turned(orientation_xyzw: Any, yaw: float) -> list[float]:
    """``orientation_xyzw`` turned by ``yaw`` about the world's vertical (xyzw)."""
    x, y, z, w = (float(c) for c in orientation_xyzw)
    s, c = float(np.sin(yaw / 2.0)), float(np.cos(yaw / 2.0))
    # [0, 0, s, c] ⊗ [x, y, z, w]
    return [c * x - s * y, c * y + s * x, c * z + s * w, c * w - s * z]
