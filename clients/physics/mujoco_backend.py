"""MuJoCo physics backend: an independent engine for the simulator's scenarios.

The backend loads the same file the server loads — an MJCF with its
includes and assets, or a URDF through MuJoCo's importer — and takes the
robot, its contacts and its standing pose from the same reading
(:mod:`controller_server.models.description`). Where the file cannot be
simulated as the server controls it, the backend changes it and says so in
:attr:`MujocoBackend.conversions` (:mod:`clients.physics.mujoco_model`: the
changes, and the integrator, friction and cone it sets). It speaks the wire
conventions of ``docs/protocol.md`` (see :mod:`clients.physics.backend`).
The conversions at the MuJoCo boundary, each
checked against Pinocchio in ``tests/clients/test_mujoco_backend.py``:

* **Free joint.** ``qpos = [position in world, quaternion w x y z]``;
  ``qvel = [linear velocity of the body origin in WORLD axes, angular
  velocity in the BODY (local) frame]`` (MuJoCo 4.0, as before). The wire
  wants exactly that pair (``linear_velocity_base_in_world``,
  ``angular_velocity_base_in_base``), so only the quaternion is reordered.
* **Ball joints.** ``qpos`` is the quaternion ``w x y z`` of the child in
  its parent, ``qvel`` the child's angular velocity relative to the parent
  in the child (local) frame — the wire's convention once the quaternion is
  reordered to ``x y z w``.
* **Joint order.** Wire order is the server's (Pinocchio's) order of the
  shared reading; addresses are looked up by joint name (``jnt_qposadr`` /
  ``jnt_dofadr``), so a client may pass the server's ``welcome`` order.
* **Torques.** Each wire DoF is driven by the one ``<motor>`` whose
  transmission is that joint and whose gear is non-zero only on that DoF;
  ``ctrl = torque / gear``. MuJoCo clamps ``ctrl`` to ``ctrlrange``, so a
  torque beyond ``ctrlrange · gear`` (or ``forcerange``, or the joint's
  ``actuatorfrcrange``) is saturated (the server already stays within them).
* **Contact forces.** :func:`mujoco.mj_contactForce` returns the force in
  the contact frame whose first axis, the normal, points from ``geom1`` to
  ``geom2``, with a positive (repulsive) normal component: it is the force
  ``geom1`` exerts on ``geom2``. The force on a foot is that, rotated to
  world, when the foot is ``geom2``, and its negative when it is ``geom1``.

A step is ``mj_step1`` (kinematics, contacts), then controls and pushes,
then ``mj_step2``, so a push is placed with the kinematics of the state it
acts on.

Contact flags and wrenches describe the contacts that acted during the last
step (MuJoCo detects contacts at the start of a step); after :meth:`reset`
they describe the reset state under zero torques.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np

from clients.physics.backend import Push, StepReport
from clients.physics.errors import SimulationDiverged, UnsupportedModel
from clients.physics.model_file import DescriptionError, describe_model, resolve_model_path
from clients.physics.mujoco_model import (
    FREE_JOINT,
    GRAVITY_M_S2,
    ModelConversions,
    mujoco_spec,
    subtree_bodies,
)
from clients.physics.spatial import cross
from clients.state import RobotState
from protocol.messages import ContactSpec

__all__ = [
    "GRAVITY_M_S2",
    "MujocoBackend",
    "SimulationDiverged",
    "UnsupportedModel",
]

_WORLD_BODY = 0
_BALL = int(mujoco.mjtJoint.mjJNT_BALL)
_JOINT_KINDS = {
    _BALL: "ball",
    int(mujoco.mjtJoint.mjJNT_HINGE): "hinge",
    int(mujoco.mjtJoint.mjJNT_SLIDE): "slide",
}
_TRANSMISSION_JOINT = int(mujoco.mjtTrn.mjTRN_JOINT)
# MuJoCo resets the data (robot back to the file's pose) after these.
_DIVERGENCE_WARNINGS = tuple(
    int(w)
    for w in (
        mujoco.mjtWarning.mjWARN_BADQPOS,
        mujoco.mjtWarning.mjWARN_BADQVEL,
        mujoco.mjtWarning.mjWARN_BADQACC,
    )
)


def _no_log_file() -> None:
    """Keep MuJoCo's warnings on the console only, out of ``MUJOCO_LOG.TXT``.

    MuJoCo appends every warning (e.g. a diverging state) to ``MUJOCO_LOG.TXT``
    in the current directory, which litters whatever directory a run starts
    in; the backend reports divergence itself (:class:`SimulationDiverged`).
    """
    config = mujoco.MjLogConfig.get()
    config.logto_file = False
    config.set()


_no_log_file()


class MujocoBackend:
    """One robot on flat ground, integrated by MuJoCo (see the module docstring).

    Attributes:
        name: ``"mujoco"``.
        time_s: Simulation time since the last reset (s).
        timestep_s: Integration step (s).
        model_path: The MJCF file simulated.
        friction_coefficient: Sliding friction of every ground contact.
        ground_height_m: Height of the floor plane (m).
        joint_names: Joints in wire order.
        contact_names: Contacts in ``contact_flags`` order (``<side>_foot``).
        contact_frames: Sole site of each contact (wrench reference point).
        total_mass_kg: Robot mass (kg).
    """

    name = "mujoco"

    def __init__(
        self,
        model: str,
        *,
        friction_coefficient: float = 0.8,
        timestep_s: float = 0.001,
        ground_height_m: float = 0.0,
        joint_names: Sequence[str] | None = None,
        contacts: list[ContactSpec] | None = None,
        keyframe: str | None = None,
        contact_time_constant_s: float | None = None,
        srdf: str | Path | None = None,
    ):
        """Load the model and build the wire ↔ MuJoCo maps once.

        Args:
            model: Built-in model name (``thesis_humanoid``, …) or MJCF path.
            friction_coefficient: Sliding friction ``μ`` between feet and ground.
            timestep_s: Integration step (s).
            ground_height_m: Height of the floor plane (m).
            joint_names: Wire joint order (e.g. from ``welcome.joints``);
                default: the server's (Pinocchio's) order.
            contacts: The feet, as in ``hello.contacts`` (default: found as the server finds them).
            keyframe: Keyframe of the standing pose (MJCF ``<key>``, a URDF's SRDF
                ``group_state``); the contacts are found in it.
            contact_time_constant_s: Time constant of every contact with the floor (the
                first number of MuJoCo's ``solref``, damping ratio 1); ``None`` keeps the
                model's (MuJoCo's default 0.02 s: the thesis humanoid standing sinks 1.1 mm
                into the floor, at 0.005 s 0.15 mm). At least two steps.
            srdf: A URDF's SRDF (keyframes, disabled collision pairs), instead of the one
                beside it.

        Raises:
            ValueError: A non-positive or non-finite coefficient or step, or a contact
                time constant shorter than two steps.
            UnsupportedModel: The file cannot be used as written, a floor that
                is not horizontal, a DoF without an actuator, an actuator
                that is neither a motor nor a position or velocity servo, or
                a joint type the wire cannot carry.
        """
        if not (math.isfinite(friction_coefficient) and friction_coefficient > 0):
            raise ValueError(f"{friction_coefficient=} must be a positive number")
        if not (math.isfinite(timestep_s) and timestep_s > 0):
            raise ValueError(f"{timestep_s=} must be a positive number of seconds")
        if not math.isfinite(ground_height_m):
            raise ValueError(f"{ground_height_m=} must be finite")
        if contact_time_constant_s is not None and not (
            math.isfinite(contact_time_constant_s) and contact_time_constant_s >= 2 * timestep_s
        ):
            raise ValueError(
                f"{contact_time_constant_s=} must be at least two steps ({2 * timestep_s} s): "
                "MuJoCo's soft contacts are unstable below"
            )
        self.contact_time_constant_s = contact_time_constant_s
        self.model_path = resolve_model_path(model)
        self.friction_coefficient = float(friction_coefficient)
        self.timestep_s = float(timestep_s)
        self.ground_height_m = float(ground_height_m)
        self.time_s = 0.0
        self._step_count = 0

        try:
            self.description = describe_model(
                model, contacts=contacts, keyframe=keyframe, srdf=srdf
            )
            spec, notes = mujoco_spec(self.model_path)
        except DescriptionError as exc:
            raise self._fail(str(exc)) from None
        self._model_conversions = ModelConversions(
            self.model_path,
            self.description,
            friction_coefficient=self.friction_coefficient,
            timestep_s=self.timestep_s,
            ground_height_m=self.ground_height_m,
            contact_time_constant_s=contact_time_constant_s,
            srdf=srdf,
            notes=notes,
        )
        self.conversions: list[str] = self._model_conversions.conversions
        """What was changed so MuJoCo simulates what the server controls (for the run's log)."""
        self._model_conversions.configure(spec)
        # Edits go through MjSpec so that compiled, derived fields (static
        # geom poses, same-frame flags) follow them.
        self._model = spec.compile()
        self._data = mujoco.MjData(self._model)
        robot = self._robot = self._model_conversions.find_robot(self._model)
        self._base_joint, self._base_qpos, self._base_dof = robot.free_joint, robot.qpos, robot.dof
        self._robot_bodies, self._robot_joints = robot.bodies, robot.joints
        self._map_joints(
            list(joint_names) if joint_names is not None else self.description.joint_names
        )
        self._exclude_self_collisions(spec)
        self._map_actuators()
        self._map_contacts()
        self.total_mass_kg = float(self._model.body_mass[self._robot_bodies].sum())
        self._body_ids: dict[str, int] = {}
        self._pushed_bodies: list[int] = []
        self._flags = [False] * len(self.contact_names)
        self._non_foot_contact = False
        self._divergence_warnings = 0
        mujoco.mj_forward(self._model, self._data)
        self._update_contact_flags()

    # -- construction -----------------------------------------------------------------

    def _fail(self, detail: str) -> UnsupportedModel:
        return UnsupportedModel(f"{self.model_path}: {detail}")

    def _exclude_self_collisions(self, spec: mujoco.MjSpec) -> None:
        """Exclude the robot's body pairs that touch at the standing pose or a keyframe."""
        self._model, self._data = self._model_conversions.exclude_self_collisions(
            spec, self._model, self._data, self._robot
        )

    def _map_joints(self, names: list[str]) -> None:
        """Wire DoF → ``qpos`` / ``qvel`` addresses, by the names of the robot's joints.

        Only the robot's joints (its root's subtree) are compared with the wire:
        the joints of other bodies in the scene are MuJoCo's alone.
        """
        model = self._model
        qpos_index: list[int] = []
        dof_index: list[int] = []
        mujoco_names = [
            model.joint(j).name for j in self._robot_joints if model.jnt_type[j] != FREE_JOINT
        ]
        if sorted(names) != sorted(mujoco_names):
            missing = [name for name in names if name not in mujoco_names]
            extra = [name for name in mujoco_names if name not in names]
            twice = sorted({name for name in names if names.count(name) > 1})
            detail = "; ".join(
                f"{what}: {', '.join(found)}"
                for what, found in (
                    ("on the wire, not in the robot", missing),
                    ("in the robot, not on the wire", extra),
                    ("twice on the wire", twice),
                )
                if found
            )
            raise self._fail(
                f"the wire's joints are not the robot's ({detail}); "
                "run the server and the simulator on the same robot file"
            )
        for joint_name in names:
            joint = model.joint(joint_name).id
            kind = _JOINT_KINDS.get(int(model.jnt_type[joint]))
            if kind is None:
                raise self._fail(f"joint {joint_name!r} has an unsupported type")
            qpos, dof = int(model.jnt_qposadr[joint]), int(model.jnt_dofadr[joint])
            if kind == "ball":
                # Wire x y z w ← MuJoCo w x y z.
                qpos_index += [qpos + 1, qpos + 2, qpos + 3, qpos]
                dof_index += [dof, dof + 1, dof + 2]
            else:
                qpos_index.append(qpos)
                dof_index.append(dof)
        self.joint_names = tuple(names)
        self._qpos_index = np.array(qpos_index, dtype=np.intp)
        self._dof_index = np.array(dof_index, dtype=np.intp)
        self._ball_qpos_starts = [
            int(model.jnt_qposadr[j]) for j in range(model.njnt) if model.jnt_type[j] == _BALL
        ]

    def _map_actuators(self) -> None:
        """For each wire DoF, the motor on that joint whose gear is non-zero only there."""
        model = self._model
        robot_joints = set(self._robot_joints)
        dof_to_actuator: dict[int, tuple[int, float]] = {}
        for actuator in range(model.nu):
            if model.actuator_trntype[actuator] != _TRANSMISSION_JOINT:
                continue
            joint = int(model.actuator_trnid[actuator, 0])
            if joint == self._base_joint or joint not in robot_joints:
                continue  # the free base, or a body outside the robot (MuJoCo's)
            gear = model.actuator_gear[actuator]
            nonzero = np.flatnonzero(gear)
            if len(nonzero) != 1 or (model.jnt_type[joint] != _BALL and nonzero[0] != 0):
                raise self._fail(
                    f"motor {model.actuator(actuator).name!r} has gear {gear.tolist()}; "
                    "use one non-zero entry on the DoF it drives"
                )
            dof = int(model.jnt_dofadr[joint]) + int(nonzero[0])
            if dof in dof_to_actuator:
                raise self._fail(
                    f"motors {model.actuator(dof_to_actuator[dof][0]).name!r} and "
                    f"{model.actuator(actuator).name!r} drive the same DoF"
                )
            dof_to_actuator[dof] = (actuator, float(gear[nonzero[0]]))
        missing = [int(d) for d in self._dof_index if int(d) not in dof_to_actuator]
        if missing:
            names = sorted({model.joint(model.dof_jntid[d]).name for d in missing})
            raise self._fail(f"no motor drives some DoF of joints {names}; add a <motor>")
        self._actuator_index = np.array(
            [dof_to_actuator[int(d)][0] for d in self._dof_index], dtype=np.intp
        )
        self._actuator_gear = np.array([dof_to_actuator[int(d)][1] for d in self._dof_index])

    def _map_contacts(self) -> None:
        """Per contact: its reference point (a site or body origin) and the geoms of its foot.

        A foot is the body of the contact's frame and every body below it.
        """
        model = self._model
        contacts = self.description.contacts
        self.contact_names = tuple(c.name for c in contacts)
        self.contact_frames = tuple(c.frame for c in contacts)
        sites = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f) for f in self.contact_frames]
        bodies = [
            int(model.site_bodyid[site])
            if site >= 0
            else mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, frame)
            for site, frame in zip(sites, self.contact_frames, strict=True)
        ]

        self._reference_sites = [(index, site) for index, site in enumerate(sites) if site >= 0]
        self._reference_bodies = [
            (index, body)
            for index, (site, body) in enumerate(zip(sites, bodies, strict=True))
            if site < 0
        ]
        # Per geom: index of the contact whose foot it belongs to, −1 otherwise.
        self._geom_contact = np.full(model.ngeom, -1, dtype=np.intp)
        for contact, body in enumerate(bodies):
            self._geom_contact[np.isin(model.geom_bodyid, subtree_bodies(model, body))] = contact
        self._geom_is_ground = model.geom_bodyid == _WORLD_BODY
        self._ground_list: list[bool] = self._geom_is_ground.tolist()
        # A body outside the robot (a prop, a dummy) on the floor is not the robot falling.
        self._robot_list: list[bool] = np.isin(model.geom_bodyid, self._robot_bodies).tolist()
        self._contact_of_geom: list[int] = self._geom_contact.tolist()

    def _reference_points(self) -> np.ndarray:
        """``(contacts, 3)`` world position of each contact's frame origin."""
        data = self._data
        points = np.empty((len(self.contact_names), 3))
        for index, site in self._reference_sites:
            points[index] = data.site_xpos[site]
        for index, body in self._reference_bodies:
            points[index] = data.xpos[body]
        return points

    # -- PhysicsBackend -----------------------------------------------------------------

    @property
    def model(self) -> mujoco.MjModel:
        """The MuJoCo model (for viewers and tests; edit at your own risk)."""
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        """The MuJoCo data (for viewers and tests; edit at your own risk)."""
        return self._data

    def reset(self, state: RobotState) -> None:
        """Put the robot in ``state`` at time 0 (velocities included).

        Quaternions are normalised; their sign is kept.

        Raises:
            ValueError: An array of the wrong length or a zero quaternion.
        """
        self._check_lengths(state)
        base_q, base_v = self._base_qpos, self._base_dof
        # Build and check the configuration before touching the data.
        qpos = self._model.qpos0.copy()
        qpos[base_q : base_q + 3] = state.position_base_in_world
        x, y, z, w = np.asarray(state.orientation_base_in_world_xyzw, dtype=float)
        qpos[base_q + 3 : base_q + 7] = (w, x, y, z)
        qpos[self._qpos_index] = state.joint_position
        for start in [base_q + 3, *self._ball_qpos_starts]:
            quaternion = qpos[start : start + 4]  # a view: normalised in place
            norm = np.linalg.norm(quaternion)
            if not norm > 1e-9:
                raise ValueError(f"quaternion {quaternion.tolist()} cannot be normalised")
            quaternion /= norm
        data = self._data
        mujoco.mj_resetData(self._model, data)
        data.qpos[:] = qpos
        data.qvel[base_v : base_v + 3] = state.linear_velocity_base_in_world
        data.qvel[base_v + 3 : base_v + 6] = state.angular_velocity_base_in_base
        data.qvel[self._dof_index] = state.joint_velocity
        self._step_count = 0
        self.time_s = 0.0
        self._divergence_warnings = 0
        mujoco.mj_forward(self._model, data)
        self._update_contact_flags()

    def _check_lengths(self, state: RobotState) -> None:
        expected = {
            "joint_position": len(self._qpos_index),
            "joint_velocity": len(self._dof_index),
            "position_base_in_world": 3,
            "orientation_base_in_world_xyzw": 4,
            "linear_velocity_base_in_world": 3,
            "angular_velocity_base_in_base": 3,
        }
        for field, length in expected.items():
            value = np.asarray(getattr(state, field))
            if value.shape != (length,):
                raise ValueError(f"{field} has shape {value.shape}, expected ({length},)")

    def state(self) -> RobotState:
        """Current state in wire conventions."""
        qpos, qvel = self._data.qpos, self._data.qvel
        base_q, base_v = self._base_qpos, self._base_dof
        w, x, y, z = qpos[base_q + 3 : base_q + 7]
        return RobotState(
            joint_position=qpos[self._qpos_index],
            joint_velocity=qvel[self._dof_index],
            position_base_in_world=qpos[base_q : base_q + 3].copy(),
            orientation_base_in_world_xyzw=np.array([x, y, z, w]),
            linear_velocity_base_in_world=qvel[base_v : base_v + 3].copy(),
            angular_velocity_base_in_base=qvel[base_v + 3 : base_v + 6].copy(),
        )

    def step(self, joint_torque: np.ndarray, pushes: list[Push]) -> StepReport:
        """Advance one step with these torques (wire order) and the pushes acting now.

        Args:
            joint_torque: One torque (N·m) or force (N) per wire DoF.
            pushes: All pushes of the scenario. Each acts with its force
                scaled by the fraction of ``[time_s, time_s + timestep_s)``
                it covers, so a push delivers exactly ``F · duration_s``
                even when its ends fall inside a step.

        Returns:
            Contact flags and whether a non-foot robot geom touched the ground.

        Raises:
            ValueError: A torque vector of the wrong length or not finite.
            KeyError: A push on a body the model does not have.
            SimulationDiverged: MuJoCo reset its data after a non-finite or
                huge state; :meth:`reset` before stepping on.
        """
        joint_torque = np.asarray(joint_torque, dtype=float)
        if joint_torque.shape != self._actuator_gear.shape:
            raise ValueError(
                f"joint_torque has shape {joint_torque.shape}, expected {self._actuator_gear.shape}"
            )
        if not np.isfinite(joint_torque).all():
            raise ValueError(f"joint_torque is not finite: {joint_torque}")
        model, data = self._model, self._data
        mujoco.mj_step1(model, data)  # kinematics and contacts of the current state
        data.ctrl[self._actuator_index] = joint_torque / self._actuator_gear
        step_start_s = self.time_s
        step_end_s = (self._step_count + 1) * self.timestep_s
        for push in pushes:
            # The fraction of this step the push covers scales its force, so
            # the impulse is F · duration whatever the step alignment.
            overlap_s = min(step_end_s, push.start_s + push.duration_s) - max(
                step_start_s, push.start_s
            )
            if overlap_s > 0.0:
                self._apply_push(push, overlap_s / self.timestep_s)
        mujoco.mj_step2(model, data)
        for body in self._pushed_bodies:
            data.xfrc_applied[body] = 0.0
        self._pushed_bodies.clear()
        counts = data.warning.number
        warnings = sum(int(counts[w]) for w in _DIVERGENCE_WARNINGS)
        if warnings != self._divergence_warnings:
            self._divergence_warnings = warnings
            raise SimulationDiverged(
                self.name,
                self.time_s,
                "MuJoCo reset the robot to the model file's pose; call reset() "
                "(a smaller timestep_s or gentler torques help)",
            )
        self._step_count += 1
        self.time_s = self._step_count * self.timestep_s
        self._update_contact_flags()
        return StepReport(list(self._flags), self._non_foot_contact)

    def _apply_push(self, push: Push, fraction: float) -> None:
        """Force at a body point → ``xfrc_applied`` (force, torque about the body CoM, world)."""
        body = self._body_id(push.body)
        data = self._data
        force_in_world = fraction * np.asarray(push.force_in_world_N, dtype=float)
        point_in_world = self.body_point_in_world(push.body, push.point_in_body_m)
        data.xfrc_applied[body, :3] += force_in_world
        data.xfrc_applied[body, 3:] += np.cross(point_in_world - data.xipos[body], force_in_world)
        self._pushed_bodies.append(body)

    def body_point_in_world(
        self, body: str, point_in_body_m: Sequence[float] | np.ndarray
    ) -> np.ndarray:
        """Where a point fixed in ``body`` (its frame, m) is in the world, at the current state.

        Raises:
            KeyError: The model has no such body (the message lists them).
        """
        index = self._body_id(body)
        rotation = self._data.xmat[index].reshape(3, 3)
        return self._data.xpos[index] + rotation @ np.asarray(point_in_body_m, dtype=float)

    def _body_id(self, name: str) -> int:
        body = self._body_ids.get(name)
        if body is None:
            body = mujoco.mj_name2id(self._model, mujoco.mjtObj.mjOBJ_BODY, name)
            if body < 0:
                available = [self._model.body(b).name for b in range(1, self._model.nbody)]
                raise KeyError(f"push on body {name!r}, not in the model; available: {available}")
            self._body_ids[name] = body
        return body

    def _ground_contacts(self) -> list[tuple[int, int, bool]]:
        """Active contacts between the ground and a robot geom (not another body's).

        Returns:
            Per contact: its index in ``data.contact``, the robot geom, and
            whether that geom is the contact's ``geom2``. (Plain Python: a
            step has a handful of contacts, too few for numpy to pay off.)
        """
        contacts = self._data.contact
        is_ground, is_robot = self._ground_list, self._robot_list
        found = []
        for index, ((geom1, geom2), address) in enumerate(
            zip(contacts.geom.tolist(), contacts.efc_address.tolist(), strict=True)
        ):
            if address < 0:
                continue
            if is_ground[geom1] and is_robot[geom2]:
                found.append((index, geom2, True))
            elif is_ground[geom2] and is_robot[geom1]:
                found.append((index, geom1, False))
        return found

    def _update_contact_flags(self) -> None:
        flags = [False] * len(self.contact_names)
        non_foot_contact = False
        for _, robot_geom, _ in self._ground_contacts():
            foot = self._contact_of_geom[robot_geom]
            if foot < 0:
                non_foot_contact = True
            else:
                flags[foot] = True
        self._flags = flags
        self._non_foot_contact = non_foot_contact

    def contact_flags(self) -> list[bool]:
        """Per contact: did any foot geom touch the ground during the last step."""
        return list(self._flags)

    def contact_wrenches_in_world(self) -> np.ndarray:
        """``(contacts, 6)``: ground force on each foot and its torque about the contact frame.

        Forces are in world axes (N), torques about the origin of the contact's
        frame (its sole site, or its body) in world axes (N·m), for the
        contacts that acted during the last step.
        """
        model, data = self._model, self._data
        wrenches = np.zeros((len(self.contact_names), 6))
        on_feet = [
            (index, self._contact_of_geom[geom], 1.0 if geom2 else -1.0)
            for index, geom, geom2 in self._ground_contacts()
            if self._contact_of_geom[geom] >= 0
        ]
        if not on_feet:
            return wrenches
        index, feet, sign = zip(*on_feet, strict=True)
        in_contact_frame = np.empty((len(index), 6))
        for row, contact in zip(in_contact_frame, index, strict=True):
            mujoco.mj_contactForce(model, data, contact, row)
        # Rows of ``frame``: normal (geom1 → geom2), tangent 1, tangent 2.
        # mj_contactForce is the force geom1 exerts on geom2; the sign makes
        # it the force on the foot.
        contacts = data.contact
        frames = contacts.frame[list(index)].reshape(-1, 3, 3) * np.array(sign)[:, None, None]
        force = np.matmul(in_contact_frame[:, None, :3], frames)[:, 0]  # frameᵀ f
        torque = np.matmul(in_contact_frame[:, None, 3:], frames)[:, 0]
        lever = contacts.pos[list(index)] - self._reference_points()[list(feet)]
        np.add.at(wrenches, list(feet), np.hstack([force, torque + cross(lever, force)]))
        return wrenches
