"""Reference simulator: Featherstone forward dynamics with penalty ground contact.

Macchietto 2008 ch. 4.3: the torques the controller returns, the penalty
ground forces and any pushes go into Featherstone's articulated-body
algorithm (Pinocchio's ``aba``), and the accelerations are integrated at a
fixed 1 ms step by semi-implicit (symplectic) Euler::

    a = aba(q, v, [0; τ], f_push) + M⁻¹ Jᵀ f_contact
    v ← v + Δt a
    q ← q ⊕ Δt v                      (``pinocchio.integrate``)

Ground contact (thesis ch. 4.2: penalty forces, explicit springs, dampers
at the end-of-step velocity) is
:class:`~clients.physics.reference_contact.PenaltyContact`: the contact
points of the robot's reading shared with the server, and ``f_contact``
solved each step from the free acceleration ``aba(q, v, [0; τ], f_push)``.

"Non-foot contact" (a fall) is a collision point (box and mesh vertices,
sphere and capsule extremes …) of any body outside the feet below the
ground; those points get no forces.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from clients.physics.backend import Push, StepReport
from clients.physics.errors import SimulationDiverged, UnsupportedModel
from clients.physics.model_file import (
    DescriptionError,
    contact_points,
    describe_model,
    resolve_model_path,
)
from clients.physics.reference_contact import (
    DEFAULT_CONTACT_DAMPING_NS_PER_M,
    DEFAULT_CONTACT_STIFFNESS_N_PER_M,
    PenaltyContact,
)
from clients.physics.spatial import cross
from clients.state import RobotState
from controller_server.models.description import RobotDescription, subtree
from protocol.errors import PoiseError
from protocol.messages import ContactSpec

__all__ = [
    "DEFAULT_CONTACT_DAMPING_NS_PER_M",
    "DEFAULT_CONTACT_STIFFNESS_N_PER_M",
    "BodyNotFound",
    "ReferenceBackend",
    "SimulationDiverged",
    "UnsupportedModel",
]


class BodyNotFound(PoiseError, KeyError):
    """A push names a body the model does not have.

    Attributes:
        name: The unknown body.
        available: Bodies of the model.
    """

    def __init__(self, name: str, available: list[str]):
        self.name = name
        self.available = available
        super().__init__(f"no body {name!r} in the model; bodies: {', '.join(available)}")


class ReferenceBackend:
    """Pinocchio ABA + penalty contact + semi-implicit Euler (Macchietto 2008, ch. 4.3).

    Implements :class:`clients.physics.backend.PhysicsBackend`. Starts standing in
    the standing pose (the keyframe's, or the file's), at rest.

    Args:
        model: Built-in model name, or an MJCF or URDF path.
        friction_coefficient: Coulomb μ between soles and ground.
        timestep_s: Integration step (s).
        ground_height_m: Height of the flat ground (m).
        contact_stiffness_N_per_m: Normal penalty stiffness ``k`` per point.
        contact_damping_Ns_per_m: Normal penalty damping ``c`` per point.
        tangential_stiffness_N_per_m: Stick spring ``k_t`` per point (default ``k``).
        tangential_damping_Ns_per_m: Stick damper ``c_t`` per point (default ``c``).
        gravity_in_world_m_per_s2: Overrides the MJCF ``<option gravity>``.
        contacts: The feet, as in ``hello.contacts`` (default: found as the server finds them).
        keyframe: MJCF keyframe of the standing pose.

    Raises:
        ValueError: A parameter is out of range (its value is in the message).
        UnsupportedModel: The model cannot be used as written (the message says why).
    """

    name = "reference"

    def __init__(
        self,
        model: str,
        *,
        friction_coefficient: float = 0.8,
        timestep_s: float = 0.001,
        ground_height_m: float = 0.0,
        contact_stiffness_N_per_m: float = DEFAULT_CONTACT_STIFFNESS_N_PER_M,
        contact_damping_Ns_per_m: float = DEFAULT_CONTACT_DAMPING_NS_PER_M,
        tangential_stiffness_N_per_m: float | None = None,
        tangential_damping_Ns_per_m: float | None = None,
        gravity_in_world_m_per_s2: tuple[float, float, float] | None = None,
        contacts: list[ContactSpec] | None = None,
        keyframe: str | None = None,
    ):
        if tangential_stiffness_N_per_m is None:
            tangential_stiffness_N_per_m = contact_stiffness_N_per_m
        if tangential_damping_Ns_per_m is None:
            tangential_damping_Ns_per_m = contact_damping_Ns_per_m
        for label, value, positive in (
            ("friction_coefficient", friction_coefficient, False),
            ("timestep_s", timestep_s, True),
            ("contact_stiffness_N_per_m", contact_stiffness_N_per_m, True),
            ("contact_damping_Ns_per_m", contact_damping_Ns_per_m, False),
            ("tangential_stiffness_N_per_m", tangential_stiffness_N_per_m, True),
            ("tangential_damping_Ns_per_m", tangential_damping_Ns_per_m, False),
        ):
            if not np.isfinite(value) or value < 0 or (positive and value == 0):
                raise ValueError(
                    f"{label} must be finite and {'> 0' if positive else '≥ 0'}: {value!r}"
                )
        if not np.isfinite(ground_height_m):
            raise ValueError(f"ground_height_m must be finite: {ground_height_m!r}")
        self.path = resolve_model_path(model)
        self.friction_coefficient = float(friction_coefficient)
        self.timestep_s = float(timestep_s)
        self.ground_height_m = float(ground_height_m)
        self.contact_stiffness_N_per_m = float(contact_stiffness_N_per_m)
        self.contact_damping_Ns_per_m = float(contact_damping_Ns_per_m)
        self.tangential_stiffness_N_per_m = float(tangential_stiffness_N_per_m)
        self.tangential_damping_Ns_per_m = float(tangential_damping_Ns_per_m)
        self.time_s = 0.0
        self._steps = 0  # time_s = steps · Δt, without summing rounding errors

        try:
            description = describe_model(model, contacts=contacts, keyframe=keyframe)
        except DescriptionError as exc:
            raise UnsupportedModel(f"{self.path}: {exc}") from None
        self.description = description
        self.conversions: list[str] = []  # Pinocchio takes the file as it is
        self._model = pin.Model(description.model)
        if gravity_in_world_m_per_s2 is not None:
            gravity = np.asarray(gravity_in_world_m_per_s2, dtype=float).reshape(3)
            self._model.gravity = pin.Motion(gravity, np.zeros(3))
        self._data = self._model.createData()
        self._qpos0 = np.array(description.standing_configuration)
        self._q = self._qpos0.copy()
        self._v = np.zeros(self._model.nv)
        self._tau = np.zeros(self._model.nv)
        self._fext = pin.StdVec_Force()
        for _ in range(self._model.njoints):
            self._fext.append(pin.Force.Zero())
        self._pushed_joints: set[int] = set()

        self._bodies = {
            frame.name: (frame.parentJoint, frame.placement.copy())
            for frame in self._model.frames
            if frame.type == pin.FrameType.BODY
        }
        self._contact = PenaltyContact(
            self._model,
            self._data,
            contact_points(description),
            friction_coefficient=self.friction_coefficient,
            timestep_s=self.timestep_s,
            ground_height_m=self.ground_height_m,
            contact_stiffness_N_per_m=self.contact_stiffness_N_per_m,
            contact_damping_Ns_per_m=self.contact_damping_Ns_per_m,
            tangential_stiffness_N_per_m=self.tangential_stiffness_N_per_m,
            tangential_damping_Ns_per_m=self.tangential_damping_Ns_per_m,
        )
        self.contact_points = self._contact.contact_points
        self.contact_names = self._contact.contact_names
        self._setup_non_foot_geoms(description)
        self._update_kinematics()
        self._contact.report_explicit_forces()
        self._contact_flags = self._contact.flags()

    # ----------------------------------------------------------------- setup

    def _setup_non_foot_geoms(self, description: RobotDescription) -> None:
        """Collision points of every body but the feet (and what hangs from them), per joint."""
        feet = [
            i for i, body in enumerate(description.bodies) if body.name in self._contact.foot_frames
        ]
        on_feet = {i for foot in feet for i in subtree(description.bodies, foot)}
        by_joint: dict[int, list[np.ndarray]] = {}
        for index, body in enumerate(description.bodies):
            if index in on_feet or not len(body.collision_points):
                continue
            frame = self._model.frames[body.frame_id]
            placement = frame.placement
            by_joint.setdefault(frame.parentJoint, []).append(
                np.column_stack(
                    [
                        body.collision_points @ placement.rotation.T + placement.translation,
                        body.collision_radii,
                    ]
                )
            )
        # Per joint: its points, their radii (round shapes) and their farthest
        # reach from the joint origin, to skip bodies well above the ground
        # without rotating points.
        self._non_foot_geoms = []
        for joint, blocks in sorted(by_joint.items()):
            stacked = np.vstack(blocks)
            corners, radii = stacked[:, :3].copy(), stacked[:, 3].copy()
            reach_m = float(np.max(np.linalg.norm(corners, axis=1) + radii))
            chain_m, parent = 0.0, joint
            while parent > 1:
                chain_m += float(np.linalg.norm(self._model.jointPlacements[parent].translation))
                parent = self._model.parents[parent]
            self._non_foot_geoms.append((joint, corners, radii, reach_m, chain_m))
        self._non_foot_contact = False

    # --------------------------------------------------------------- physics

    def _update_kinematics(self) -> None:
        """Contact points, touching set, anchors, flags and falls at the current state."""
        data = self._data
        pin.forwardKinematics(self._model, data, self._q, self._v)
        self._contact.place_points()

        self._non_foot_contact = False
        base_height = self._q[2]
        for joint, corners, radii, reach_m, chain_m in self._non_foot_geoms:
            # The joint is at most ``chain_m`` from the base origin: skip it unread
            # when even that leaves its geoms above the ground.
            if base_height - chain_m - reach_m > self.ground_height_m:
                continue
            transform = data.oMi[joint]
            height = transform.translation[2]
            if height - reach_m > self.ground_height_m:
                continue
            if (corners @ transform.rotation[2] - radii).min() + height < self.ground_height_m:
                self._non_foot_contact = True
                break

    def step(self, joint_torque: np.ndarray, pushes: list[Push]) -> StepReport:
        """Advance one time step with these joint torques (wire order) and active pushes.

        Args:
            joint_torque: ``(nv − 6,)`` joint torques (N·m; N for prismatic joints).
            pushes: All pushes; each acts with its force scaled by the fraction
                of ``[time_s, time_s + timestep_s)`` it covers.

        Returns:
            Contact flags of the step (as :meth:`contact_flags`) and whether a
            non-foot box corner is below the ground at the new state.

        Raises:
            ValueError: ``joint_torque`` has the wrong shape or is not finite.
            BodyNotFound: A push names an unknown body.
            SimulationDiverged: The step would make the state non-finite.
        """
        model, data = self._model, self._data
        torque = np.asarray(joint_torque, dtype=float)
        if torque.shape != (model.nv - 6,):
            raise ValueError(f"joint_torque must have {model.nv - 6} entries: {torque.shape=}")
        if not np.isfinite(torque).all():
            raise ValueError(f"joint_torque must be finite: {torque}")
        self._tau[6:] = torque

        fext = self._fext
        for joint in self._pushed_joints:
            fext[joint] = pin.Force.Zero()
        self._pushed_joints = set()
        step_end_s = (self._steps + 1) * self.timestep_s
        for push in pushes:
            # Scaled by the fraction of the step it covers: the impulse is
            # F · duration_s however the push aligns with the steps.
            overlap_s = min(step_end_s, push.start_s + push.duration_s) - max(
                self.time_s, push.start_s
            )
            if overlap_s <= 0.0:
                continue
            if push.body not in self._bodies:
                raise BodyNotFound(push.body, sorted(self._bodies))
            joint, placement = self._bodies[push.body]
            point_in_joint = placement.act(np.asarray(push.point_in_body_m, dtype=float))
            force_in_world = (overlap_s / self.timestep_s) * np.asarray(
                push.force_in_world_N, dtype=float
            )
            force_in_joint = data.oMi[joint].rotation.T @ force_in_world
            fext[joint] = fext[joint] + pin.Force(
                force_in_joint, cross(point_in_joint, force_in_joint)
            )
            self._pushed_joints.add(joint)

        acceleration = pin.aba(model, data, self._q, self._v, self._tau, fext).copy()
        self._contact.step_forces(self._q, self._v, acceleration)
        velocity = self._v + self.timestep_s * acceleration
        if not np.isfinite(velocity).all():
            largest_torque = float(np.abs(torque).max(initial=0.0))
            raise SimulationDiverged(
                self.name,
                self.time_s,
                f"largest |joint_torque| {largest_torque:.3g}; the lightest links cannot take "
                "such torques at this time step: reduce the torques or timestep_s",
            )
        self._v = velocity
        self._q = pin.integrate(model, self._q, self.timestep_s * velocity)
        self._steps += 1
        self.time_s = self._steps * self.timestep_s
        self._contact_flags = self._contact.flags()
        self._update_kinematics()
        return StepReport(list(self._contact_flags), self._non_foot_contact)

    # ------------------------------------------------------- wire conventions

    def reset(self, state: RobotState) -> None:
        """Put the robot in ``state`` at time 0 (velocities included; anchors cleared).

        Raises:
            ValueError: An array has the wrong size or is not finite.
        """
        model = self._model
        sizes = {
            "joint_position": model.nq - 7,
            "joint_velocity": model.nv - 6,
            "position_base_in_world": 3,
            "orientation_base_in_world_xyzw": 4,
            "linear_velocity_base_in_world": 3,
            "angular_velocity_base_in_base": 3,
        }
        arrays = {}
        for key, size in sizes.items():
            value = getattr(state, key)
            array = np.asarray(value, dtype=float).reshape(-1)
            if array.size != size or not np.isfinite(array).all():
                raise ValueError(f"{key} must be {size} finite numbers: {value!r}")
            arrays[key] = array
        q = np.concatenate(
            [
                arrays["position_base_in_world"],
                arrays["orientation_base_in_world_xyzw"],
                arrays["joint_position"],
            ]
        )
        self._q = pin.normalize(model, q)
        rotation = pin.Quaternion(self._q[3:7]).toRotationMatrix()
        self._v = np.concatenate(
            [
                rotation.T @ arrays["linear_velocity_base_in_world"],
                arrays["angular_velocity_base_in_base"],
                arrays["joint_velocity"],
            ]
        )
        self.time_s = 0.0
        self._steps = 0
        self._contact.clear_anchors()
        self._update_kinematics()
        self._contact.report_explicit_forces()
        self._contact_flags = self._contact.flags()

    def state(self) -> RobotState:
        """Current state in wire conventions."""
        rotation = pin.Quaternion(self._q[3:7]).toRotationMatrix()
        return RobotState(
            joint_position=self._q[7:].copy(),
            joint_velocity=self._v[6:].copy(),
            position_base_in_world=self._q[:3].copy(),
            orientation_base_in_world_xyzw=self._q[3:7].copy(),
            linear_velocity_base_in_world=rotation @ self._v[:3],
            angular_velocity_base_in_base=self._v[3:6].copy(),
        )

    def standing_state(self) -> RobotState:
        """The neutral pose at ``qpos0`` (soles on the ground for the built-ins), at rest."""
        return RobotState(
            joint_position=self._qpos0[7:].copy(),
            joint_velocity=np.zeros(self._model.nv - 6),
            position_base_in_world=self._qpos0[:3].copy(),
            orientation_base_in_world_xyzw=self._qpos0[3:7].copy(),
            linear_velocity_base_in_world=np.zeros(3),
            angular_velocity_base_in_base=np.zeros(3),
        )

    # --------------------------------------------------------------- contact

    def contact_flags(self) -> list[bool]:
        """Per contact (welcome order): was any of its points below the ground in the last step.

        That is, at the start of the last step, the state whose penalty forces
        acted during it; after :meth:`reset`, at the reset state.
        """
        return list(self._contact_flags)

    def contact_wrenches_in_world(self) -> np.ndarray:
        """``(contacts, 6)`` ground force and torque about each sole-site origin (N, N·m).

        World axes. The penalty forces that acted during the last step, about
        the site origins at the start of that step; after :meth:`reset`, the
        springs and dampers evaluated at the reset state.
        """
        return self._contact.wrenches()

    def contact_point_forces_in_world(self) -> np.ndarray:
        """``(points, 3)`` penalty force at each point during the last step (N)."""
        return self._contact.point_forces()

    def contact_point_positions_in_world(self) -> np.ndarray:
        """``(points, 3)`` position of each contact point now, contacts in order (m)."""
        return self._contact.point_positions()

    def non_foot_contact(self) -> bool:
        """Whether a box corner of a body other than the feet is below the ground now."""
        return self._non_foot_contact

    # ------------------------------------------------------------- the model

    @property
    def pinocchio_model(self) -> pin.Model:
        """The Pinocchio model being integrated (gravity set; do not modify)."""
        return self._model

    @property
    def total_mass_kg(self) -> float:
        """Total mass of the robot."""
        return float(pin.computeTotalMass(self._model))

    @property
    def configuration(self) -> np.ndarray:
        """Pinocchio ``q`` (copy): base position, base quaternion xyzw, joints."""
        return self._q.copy()

    @property
    def velocity(self) -> np.ndarray:
        """Pinocchio ``v`` (copy): base twist in the base frame, then joint velocities."""
        return self._v.copy()
