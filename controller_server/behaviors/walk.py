"""Walking (de Lasa, Mordatch & Hertzmann 2010, §6, Table 2, Fig. 3), with capture-point steps.

The state machine sets the balance controller's references, weights and
planned supports as the walk goes (its :class:`Targets`, as the jump's),
and asks ``com`` for the capture point's CM acceleration and ``swing`` for the
swing foot's path:

* ``stand``: both feet support, the balance controller as it is, for
  ``walk_delay_s``; the walk starts once ``walk_speed`` or
  ``walk_turn_rate`` is non-zero, and comes back here when both are 0 and
  the robot has stopped.
* ``shift``: both feet still support; the CM moves over the first stance foot
  (the right one): its divergent component of motion (capture point, below)
  is driven to where a step's single support starts.
* ``swing``: single support. The swing foot leaves the planned supports
  (``support_mask`` 0) and ``swing`` (E_swing,
  :mod:`controller_server.features.swing_foot`) lifts it by
  ``walk_step_height`` and lands it on the foothold at the end of
  ``walk_swing_duration_s``. The swing ends at touch-down (the foot's contact
  flag, or its sole within 2 mm of the ground, after half the swing) or
  :data:`SWING_TIMEOUT_S` after its duration.
* ``double``: double support for ``walk_double_support_s``, the weight on the
  new stance foot; then the other foot swings, or, with a zero command and the
  robot nearly at rest, ``stop``.
* ``stop``: both feet support while the CM returns between them; then ``stand``.

Footholds (beyond the paper). de Lasa's swing targets (eq. 18) and CM path
(eq. 19–20) are world-fixed curves, and §10 says so: "because these curves
are defined in world coordinates, the controller is not robust to
perturbations". Here both come from the linear inverted pendulum's capture
point (divergent component of motion) ``ξ = c + ċ/ω``, ``ω = √(g/z_c)``,
measured every tick (Pratt et al. 2006; Englsberger et al. 2015). With the
centre of pressure held at the stance foot's centre ``r``, ``ξ̇ = ω (ξ − r)``:
the CM objective (E_com∥) asks for the pendulum's own acceleration
``c̈ = ω² (c − r)`` (no world-fixed CM curve), and the capture point at
touch-down is predicted as ``ξ_end = r + (ξ − r) e^{ω t_left}``. The foot
lands at ``ξ_end − b``, where ``b`` is the offset of the capture point from
its foot that a periodic walk at speed ``v`` with step width ``w`` has at
the start of each step of period ``T = T_swing + T_double``:
``b∥ = v T / (e^{ωT} − 1)`` along the heading and
``b⊥ = ± w / (e^{ωT} + 1)`` toward the next foot. On the pendulum this
settles any capture-point error in one step (deadbeat): a push moves ``ξ``,
and the foot lands where the walk continues at the commanded speed. So the
commanded speed needs no extra velocity gain (a Raibert term
``k (v − v_d)`` would count the same error twice). The foothold is
re-planned every tick until :data:`REPLAN_STOP_S` before the landing, then
held (a late change is a jerk the foot cannot follow), and kept inside
reach (``walk_max_step_length``, between :data:`MIN_WIDTH_FRACTION` of the
standing width and ``walk_max_step_width``, so the legs do not cross).
Turning: the heading ``ψ`` turns at ``walk_turn_rate``; ``b`` and the swing
foot's yaw follow it, and so does the trunk's reference.
Cadence: a faster walk takes quicker steps, not only longer ones. Above the
speed at which a step of ``T_swing + T_double`` is ``walk_step_length`` long,
the swing shortens to keep the step at that length (down to
:data:`MIN_SWING_S`). With the cadence fixed, at 0.8 m/s the steps grew to
0.5 m: in double support the trailing leg stretched straight, the CM sank, and
the stance knee folded under saturated torques.

State-independent objectives (§6.2, Table 2): the trunk upright (``trunk``,
leaning ``walk_trunk_lean`` forward), the angular momentum damped
(E_AM, L_r = 0) at ``walk_angular_momentum_weight`` (0.1: at the balance
controller's 10, once the centre of pressure reached a sole's edge, the
damping took the vertical ground force with it and the CM sank or shot up),
the rest pose (E_pose, ranked at ``walk_pose_priority``; the pose the walk
starts from, knees bent by ``walk_knee_bend`` more). E_arms, the minimum
torque on the shoulders and elbows, is ``walk_arm_torque_weight``, off by
default (not yet tuned). §6.1 leaves the CM height free; here ``com_height``
holds the height the walk starts from (``walk_com_height_weight``, ranked with
the rest pose; 0 frees it, which has not been measured with the other
defaults as they are now). Priorities while walking: ``contact`` 1;
``com``, ``angular_momentum``, ``trunk``, ``swing`` 2; ``pose``,
``com_height`` 3 (``swing`` at 3, Table 2's level, did not walk: the rest
pose held the swing leg back).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from controller_server.behaviors.behavior import Behavior, Targets
from controller_server.behaviors.limbs import arm_dofs, knee_bend_direction
from controller_server.behaviors.observation import Observation
from controller_server.features.swing_foot import SwingTarget
from controller_server.models import RobotModel
from controller_server.params import ParamSpec

__all__ = ["WALK_PARAMETERS", "WALK_STATES", "Walk"]

WALK_STATES = ("stand", "shift", "swing", "double", "stop")
SWING_TIMEOUT_S = 0.15
"""A swing foot that has not touched this long after the swing's duration is put down."""
REPLAN_STOP_S = 0.08
"""The foothold is held for the swing's last this-many seconds."""
TOUCH_HEIGHT_M = 0.002
"""A swing foot whose sole comes this close to the ground after mid-swing has landed."""
MIN_WIDTH_FRACTION = 0.7
"""Footholds are at least this fraction of the standing width apart, sideways."""
STOP_SPEED = 0.1
"""With a zero command, the walk stops once the CM moves forward slower than this (m/s)."""
MIN_SWING_S = 0.25
"""The cadence (``walk_step_length``) shortens a swing to no less than this (s)."""
SHIFT_TOLERANCE_M = 0.01
"""``shift`` and ``stop`` end once the capture point is this close to where they drive it."""
ON_TIME_S = 0.03
"""A swing that lands within this of its duration (s) is on time: the speed correction learns
from it (:meth:`Walk._learn_speed`). Undisturbed steps land 10–12 ms early (the sole touches
before its frame reaches the ground); a stumble lands 50–80 ms early or late."""

WALK_PARAMETERS: dict[str, ParamSpec] = {
    "walk_speed": ParamSpec(
        0.5,
        minimum=-0.5,
        maximum=1.5,
        doc="walk: commanded speed along the heading (m/s); 0 steps in place, then stands",
    ),
    "walk_acceleration": ParamSpec(
        0.3,
        minimum=0.01,
        maximum=10.0,
        doc="walk: the speed the footholds plan for follows `walk_speed` at most this fast "
        "(m/s²): a new speed is reached over a few steps, not in one",
    ),
    "walk_turn_rate": ParamSpec(
        0.0, minimum=-1.0, maximum=1.0, doc="walk: commanded yaw rate of the heading (rad/s)"
    ),
    "walk_swing_duration_s": ParamSpec(
        0.45, minimum=0.2, maximum=2.0, doc="walk: T, swing (single-support) duration (Table 2, s)"
    ),
    "walk_step_length": ParamSpec(
        0.36,
        minimum=0.05,
        maximum=2.0,
        doc="walk: the longest step the cadence plans for (m): above the speed at which a step "
        "of `walk_swing_duration_s` + `walk_double_support_s` is this long, the swing "
        "shortens (to at least 0.25 s), so faster walking takes quicker steps, not longer ones",
    ),
    "walk_double_support_s": ParamSpec(
        0.1, minimum=0.0, maximum=2.0, doc="walk: double support between two swings (s)"
    ),
    "walk_step_height": ParamSpec(
        0.06, minimum=0.0, maximum=0.3, doc="walk: h, swing foot height at mid-swing (Table 2, m)"
    ),
    "walk_hip_shift": ParamSpec(
        0.0,
        minimum=0.0,
        maximum=0.3,
        doc="walk: l_hip of eq. 18: footholds are the standing width + 2 l_hip apart (m)",
    ),
    "walk_speed_gain": ParamSpec(
        0.5,
        minimum=0.0,
        maximum=2.0,
        doc="walk: integral gain per step on the relative speed error: the footholds plan for "
        "the commanded speed × (1 + a correction learned from the measured steps)",
    ),
    "walk_max_step_length": ParamSpec(
        0.5,
        minimum=0.0,
        maximum=2.0,
        doc="walk: longest step along the heading, from the stance foot (m)",
    ),
    "walk_max_step_width": ParamSpec(
        0.45,
        minimum=0.0,
        maximum=2.0,
        doc="walk: widest step sideways, from the stance foot (m)",
    ),
    "walk_trunk_lean": ParamSpec(
        0.0,
        minimum=-0.5,
        maximum=0.8,
        doc="walk: forward pitch of the trunk's reference (rad; cf. l_trunk of Table 2)",
    ),
    "walk_knee_bend": ParamSpec(
        0.0,
        minimum=-0.5,
        maximum=1.0,
        doc="walk: knees of the rest pose bent this much more than the pose the walk starts "
        "from, hips and ankles half as much the other way (rad; §6.1: walking height)",
    ),
    "walk_delay_s": ParamSpec(
        0.2, minimum=0.0, maximum=60.0, doc="walk: stand this long before the first step (s)"
    ),
    "walk_shift_duration_s": ParamSpec(
        0.5,
        minimum=0.1,
        maximum=5.0,
        doc="walk: time to move the CM over the first stance foot, or back between the feet (s)",
    ),
    "walk_swing_stiffness": ParamSpec(
        100.0,
        minimum=0.0,
        maximum=1e6,
        doc="walk: k_p of the swing foot's orientation and landing setpoints (1/s²)",
    ),
    "walk_pose_priority": ParamSpec(
        3,
        kind="int",
        minimum=1,
        maximum=10,
        doc="walk: priority of `pose` while walking (`swing` keeps its own priority)",
    ),
    "walk_com_height_weight": ParamSpec(
        1.0,
        minimum=0.0,
        maximum=1e6,
        doc="walk: α of `com_height` (held at the height the walk starts from) while walking; "
        "0 leaves the CM height free, as §6.1 does",
    ),
    "walk_com_height_priority": ParamSpec(
        3,
        kind="int",
        minimum=1,
        maximum=10,
        doc="walk: priority of `com_height` while walking",
    ),
    "walk_angular_momentum_weight": ParamSpec(
        0.1,
        minimum=0.0,
        maximum=1e6,
        doc="walk: α of `angular_momentum` (E_AM, L_r = 0) while walking",
    ),
    "walk_arm_torque_weight": ParamSpec(
        0.0,
        minimum=0.0,
        maximum=1e6,
        doc="walk: α of `torque` on the shoulders and elbows while walking (E_arms, §6.2)",
    ),
}
"""The walk's parameters (``set_params``, also while walking), documented in
docs/controllers.md."""


class Walk(Behavior):
    """A walk, from ``stand`` through its steps (see the module docstring).

    The pose at its first tick is the pose it starts from (its rest pose, knees bent by
    ``walk_knee_bend``); the robot's knees, hips and ankles (:func:`knee_bend_direction`)
    and arms (:func:`arm_dofs`) are found from its joint names.

    Attributes:
        state: The current state (:data:`WALK_STATES`).
        swing: The swing foot's target while one swings, else ``None``.
        com_acceleration_xy: The CM acceleration the walk asks of `com` (m/s², world x and
            y), ``None`` when `com` balances as usual.
        steps: Touch-downs so far.
    """

    name = "walk"
    SUMMARY = "walking, de Lasa §6 with capture-point footholds (the `walk_` parameters)"
    PARAMETERS = WALK_PARAMETERS
    HOSTS = ("prioritized",)

    def __init__(self, robot: RobotModel):
        super().__init__(robot)
        points_in_frame = [np.asarray(contact.points_in_frame) for contact in robot.contacts]
        self.swing: SwingTarget | None = None
        self.com_acceleration_xy: np.ndarray | None = None
        self.steps = 0
        self._sole_offsets = [points.mean(axis=0) for points in points_in_frame]
        self._points = points_in_frame
        self._start_pose = np.zeros(0)  # the pose it starts from, set at the first tick
        self._knee_direction = knee_bend_direction(robot.model)
        self._arm_dofs = arm_dofs(robot.model)
        self._since_s: float | None = None
        self._last_s: float | None = None
        self._heading = 0.0
        self._left = 0  # contact index of the left foot, set at the first tick
        self._width = 0.2  # standing distance between the feet, sideways (m)
        self._stance = 1
        self._target_xy = np.zeros(2)
        self._knee_bend: float | None = None  # the rest pose's, as last set
        self._lean: float | None = None
        self._speed = 0.0  # the planned speed: walk_speed, rate-limited (walk_acceleration)
        self._speed_correction = 0.0  # relative, learned step by step (walk_speed_gain)
        self._touchdown: tuple[float, np.ndarray] | None = None  # time, CM xy

    # One tick -------------------------------------------------------------------------

    def update(self, observation: Observation, params: Mapping[str, Any]) -> Targets:
        """This tick's targets: the parameters it sets, ``com``'s acceleration, ``swing``."""
        self._advance(observation, params)
        return self._targets(com_acceleration_xy=self.com_acceleration_xy, swing=self.swing)

    def _advance(self, observation: Observation, params: Mapping[str, Any]) -> None:
        o, p = observation, params
        if self._since_s is None:
            self._begin(o, p)
        dt = 0.0 if self._last_s is None else max(o.time_s - self._last_s, 0.0)
        self._last_s = o.time_s
        elapsed = o.time_s - self._since()
        walking = self.state in ("swing", "double")
        if walking:
            self._heading += p["walk_turn_rate"] * dt
            change = float(np.clip(p["walk_speed"] - self._speed, -1.0, 1.0))
            self._speed += float(
                np.clip(change, -p["walk_acceleration"] * dt, p["walk_acceleration"] * dt)
            )
        if (
            p["walk_knee_bend"] != self._knee_bend
            or p["walk_trunk_lean"] != self._lean
            or (walking and p["walk_turn_rate"])
        ):
            self._posture(p)
        centers = [
            position + rotation @ offset
            for position, rotation, offset in zip(
                o.position_contact_frames_in_world,
                o.orientation_contact_frames_in_world,
                self._sole_offsets,
                strict=True,
            )
        ]
        height = max(float(o.position_com_in_world[2] - o.ground_height), 0.05)
        omega = math.sqrt(self.gravity / height)
        com_xy = o.position_com_in_world[:2]
        capture = com_xy + o.velocity_com_in_world[:2] / omega
        command = p["walk_speed"] != 0.0 or p["walk_turn_rate"] != 0.0

        if self.state == "stand":
            if command and elapsed >= p["walk_delay_s"]:
                self._stance = 1 - self._left  # the right foot first
                self._target_xy = centers[self._stance][:2] + self._offset(
                    p, omega, self._stance, p["walk_swing_duration_s"]
                )
                self._enter(o, "shift")
            else:
                return
        elapsed = o.time_s - self._since()
        if self.state in ("shift", "stop"):
            if self.state == "stop":
                self._target_xy = 0.5 * (centers[0][:2] + centers[1][:2])
            # Drive ξ to the target: ξ̇_d = (ξ_T − ξ)/τ, by the COP r = ξ − ξ̇_d/ω.
            tau = p["walk_shift_duration_s"] / 3.0
            cop = capture - (self._target_xy - capture) / (tau * omega)
            self.com_acceleration_xy = omega**2 * (com_xy - cop)
            done = np.linalg.norm(capture - self._target_xy) < SHIFT_TOLERANCE_M
            if self.state == "shift" and (done or elapsed >= 1.5 * p["walk_shift_duration_s"]):
                self._lift(o, p, centers)
            elif self.state == "stop" and (done or elapsed >= 1.5 * p["walk_shift_duration_s"]):
                self.com_acceleration_xy = None
                self._enter(o, "stand")
            return
        stance_center = centers[self._stance]
        self.com_acceleration_xy = omega**2 * (com_xy - stance_center[:2])
        if self.state == "swing":
            assert self.swing is not None
            swing = self.swing
            foot = swing.contact
            left_s = swing.duration_s - elapsed
            if left_s > REPLAN_STOP_S:
                self.swing = self._replan(p, o, swing, stance_center, capture, omega, left_s)
            lowest = min(
                float((o.orientation_contact_frames_in_world[foot] @ point)[2])
                for point in self._points[foot]
            ) + float(o.position_contact_frames_in_world[foot][2] - o.ground_height)
            landed = elapsed >= 0.5 * swing.duration_s and (
                o.touching[foot] or lowest <= TOUCH_HEIGHT_M
            )
            if landed or elapsed >= swing.duration_s + SWING_TIMEOUT_S:
                self._learn_speed(o, p, abs(elapsed - swing.duration_s) <= ON_TIME_S)
                self.swing = None
                self._stance = foot
                self.steps += 1
                self._enter(o, "double")
                self._unset("support_mask")
        elif self.state == "double" and elapsed >= p["walk_double_support_s"]:
            feet_apart = np.array(centers[0][:2] - centers[1][:2])
            along = abs(feet_apart @ _direction(self._heading))
            # Forward only: in place the CM still sways sideways from foot to foot.
            at_rest = abs(o.velocity_com_in_world[:2] @ _direction(self._heading)) < STOP_SPEED
            if not command and at_rest and along < 0.1:
                self._enter(o, "stop")
            else:
                self._lift(o, p, centers)

    # Transitions ----------------------------------------------------------------------

    def _begin(self, o: Observation, p: Mapping[str, Any]) -> None:
        """First tick: heading, which foot is left, standing width; the walk's objectives."""
        self._since_s = o.time_s
        self._start_pose = np.array(o.joint_position, dtype=float)
        x, y, z, w = o.orientation_base_in_world_xyzw
        self._heading = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        lateral = _direction(self._heading + 0.5 * math.pi)
        sideways = [
            float(position[:2] @ lateral) for position in o.position_contact_frames_in_world
        ]
        self._left = int(np.argmax(sideways))
        self._width = abs(sideways[0] - sideways[1]) if len(sideways) > 1 else 0.2
        selection = np.where(self._arm_dofs, 1.0, 0.0)
        self._set(
            priority_pose=p["walk_pose_priority"],
            weight_com_height=p["walk_com_height_weight"],
            priority_com_height=p["walk_com_height_priority"],
            weight_angular_momentum=p["walk_angular_momentum_weight"],
            com_height=float(o.position_com_in_world[2] - o.ground_height),
        )
        if p["walk_arm_torque_weight"] > 0.0 and selection.any():
            self._set(
                torque_selection=selection.tolist(),
                weight_torque=p["walk_arm_torque_weight"],
                priority_torque=p["walk_pose_priority"],
            )

    def _learn_speed(self, o: Observation, p: Mapping[str, Any], on_time: bool = True) -> None:
        """Integrate the relative speed error of the step that ends (``walk_speed_gain``).

        The pendulum's footholds are exact for the linear inverted pendulum only; the body's
        CM rises and falls and the legs carry momentum, so the measured speed falls short
        of the command by a steady fraction (at 0.5 m/s the thesis humanoid walked 0.40 m/s;
        the correction settles near +28 %). An integral on the step's mean speed along the
        heading removes it.

        Only steps that landed on time (``on_time``: within :data:`ON_TIME_S` of the swing's
        duration) teach it: a foot that touched early or late (a stumble, a push, a stance
        foot that rolled) measures the disturbance, not the model's steady bias, and the
        capture-point footholds already correct the disturbance in the next step. Learned
        as well, it was counted twice: on the revolute humanoid in MuJoCo one stumble swung
        the correction from +0.41 to −0.50 in two steps, the footholds ran into
        ``walk_max_step_length`` and the walk fell.
        """
        com_xy = o.position_com_in_world[:2].copy()
        previous, self._touchdown = self._touchdown, (o.time_s, com_xy)
        speed = self._speed
        ramping = abs(p["walk_speed"] - speed) > 1e-6  # the step is not at the speed it aims for
        if (
            previous is None
            or not on_time
            or abs(speed) < 0.1
            or ramping
            or o.time_s - previous[0] <= 0.0
        ):
            return
        measured = float((com_xy - previous[1]) @ _direction(self._heading)) / (
            o.time_s - previous[0]
        )
        self._speed_correction = float(
            np.clip(
                self._speed_correction + p["walk_speed_gain"] * (speed - measured) / speed,
                -0.5,
                1.0,
            )
        )

    def _posture(self, p: Mapping[str, Any]) -> None:
        """Rest pose (knee bend) and trunk reference (heading, lean)."""
        bend, lean = float(p["walk_knee_bend"]), float(p["walk_trunk_lean"])
        if bend != self._knee_bend:
            self._knee_bend = bend
            self._set(reference_joint_position=self._rest_pose(bend))
        self._lean = lean
        half_yaw, half_pitch = 0.5 * self._heading, 0.5 * lean
        # yaw about z, then pitch about the heading's y: q = q_z(ψ) ⊗ q_y(θ), xyzw.
        cz, sz, cy, sy = (
            math.cos(half_yaw),
            math.sin(half_yaw),
            math.cos(half_pitch),
            math.sin(half_pitch),
        )
        self._set(reference_trunk_orientation_xyzw=[-sz * sy, cz * sy, sz * cy, cz * cy])

    def _rest_pose(self, bend: float) -> list[float]:
        """The starting pose with the knees' pitch bent by ``bend`` (hips, ankles −½ each)."""
        if bend == 0.0:
            return self._start_pose.tolist()
        model = self.robot.model
        q = np.concatenate([[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], self._start_pose])
        dq = np.concatenate([np.zeros(6), bend * self._knee_direction])
        return pin.integrate(model, q, dq)[7:].tolist()

    def _lift(self, o: Observation, p: Mapping[str, Any], centers: Sequence[np.ndarray]) -> None:
        """The other foot leaves the supports and swings (E_swing on)."""
        foot = 1 - self._stance
        duration_s = self._swing_duration_s(p)
        rotation = _yaw_rotation(self._heading + p["walk_turn_rate"] * duration_s)
        target = centers[foot].copy()
        target[2] = o.ground_height
        self.swing = SwingTarget(
            contact=foot,
            position_target_in_world=target - rotation @ self._sole_offsets[foot],
            orientation_target_in_world=rotation,
            step_height=p["walk_step_height"],
            stiffness=p["walk_swing_stiffness"],
            start_s=o.time_s,
            duration_s=duration_s,
        )
        mask = [float(x) for x in p["support_mask"]]  # the client's: unset since the landing
        mask[foot] = 0.0
        self._enter(o, "swing")
        self._set(support_mask=mask)

    def _replan(
        self,
        p: Mapping[str, Any],
        o: Observation,
        swing: SwingTarget,
        stance_center: np.ndarray,
        capture: np.ndarray,
        omega: float,
        left_s: float,
    ) -> SwingTarget:
        """The foothold from the capture point predicted at touch-down (module docstring)."""
        foot = swing.contact
        heading = self._heading + p["walk_turn_rate"] * left_s
        r = stance_center[:2]
        capture_end = r + (capture - r) * math.exp(omega * left_s)
        cycle = swing.duration_s + p["walk_double_support_s"]
        foothold = capture_end - self._offset(p, omega, foot, cycle, heading)
        # Within reach, on its own side of the stance foot.
        forward, lateral = _direction(heading), _direction(heading + 0.5 * math.pi)
        step = foothold - r
        side = 1.0 if foot == self._left else -1.0
        along = float(
            np.clip(step @ forward, -p["walk_max_step_length"], p["walk_max_step_length"])
        )
        across = side * float(
            np.clip(
                side * (step @ lateral),
                MIN_WIDTH_FRACTION * self._width,
                max(p["walk_max_step_width"], MIN_WIDTH_FRACTION * self._width),
            )
        )
        foothold = r + along * forward + across * lateral
        rotation = _yaw_rotation(heading)
        target = np.array([*foothold, o.ground_height]) - rotation @ self._sole_offsets[foot]
        target[2] = o.ground_height - (rotation @ self._sole_offsets[foot])[2]
        return SwingTarget(
            contact=foot,
            position_target_in_world=target,
            orientation_target_in_world=rotation,
            step_height=p["walk_step_height"],
            stiffness=p["walk_swing_stiffness"],
            start_s=swing.start_s,
            duration_s=swing.duration_s,
        )

    def _swing_duration_s(self, p: Mapping[str, Any]) -> float:
        """``T`` of the next swing: ``walk_swing_duration_s``, shortened at speed (cadence).

        At the commanded speed ``v`` (as ``walk_acceleration`` lets it change) a step of
        period ``T + T_double`` is ``v (T + T_double)`` long; above ``walk_step_length`` the
        swing shortens to keep it there, down to :data:`MIN_SWING_S`. Longer steps at the same
        cadence stretched the trailing leg straight in double support, and the CM sank until
        the stance knee folded (0.8 m/s).
        """
        nominal = float(p["walk_swing_duration_s"])
        speed = abs(self._speed)
        if speed <= 0.0:
            return nominal
        shortened = p["walk_step_length"] / speed - p["walk_double_support_s"]
        return float(min(nominal, max(MIN_SWING_S, shortened)))

    def _offset(
        self,
        p: Mapping[str, Any],
        omega: float,
        stance: int,
        period_s: float,
        heading: float | None = None,
    ) -> np.ndarray:
        """``b``: the capture point's offset from the stance foot at the start of its step.

        ``b∥ = v T / (e^{ωT} − 1)``, ``b⊥ = ± w / (e^{ωT} + 1)`` toward the other foot, with
        ``T`` the step's period and ``w`` the step width (module docstring).
        """
        heading = self._heading if heading is None else heading
        growth = math.exp(omega * period_s)
        width = self._width + 2.0 * p["walk_hip_shift"]
        toward_other = -1.0 if stance == self._left else 1.0
        speed = self._speed * (1.0 + self._speed_correction)
        along = speed * period_s / (growth - 1.0)
        across = toward_other * width / (growth + 1.0)
        return along * _direction(heading) + across * _direction(heading + 0.5 * math.pi)

    def _since(self) -> float:
        """When the current state began (s; set at the first tick)."""
        return 0.0 if self._since_s is None else self._since_s

    def _enter(self, observation: Observation, state: str) -> None:
        self.state = state
        self._since_s = observation.time_s


def _direction(angle: float) -> np.ndarray:
    return np.array([math.cos(angle), math.sin(angle)])


def _yaw_rotation(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
