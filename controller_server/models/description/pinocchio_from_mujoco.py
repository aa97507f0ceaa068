"""An MJCF's robot in Pinocchio, built body by body from the compiled MuJoCo model.

The robot's root body, its joints, inertias and frames (bodies, joints, sites), its
collision geometry and ``*_sole`` sites, and its actuation: torque limits and actuator kinds
per joint.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin

from controller_server.models.description.bodies import Body, Draft, FoundContact
from controller_server.models.description.files import FileReader
from controller_server.models.description.limits import DescriptionError, check_size
from controller_server.models.description.mjcf import compile_mjcf
from controller_server.models.description.shapes import (
    GEOM,
    mesh_vertices,
    placed,
    se3,
    shape_points,
)

__all__ = [
    "read_mjcf",
]

_FREE = int(mujoco.mjtJoint.mjJNT_FREE)
_BALL = int(mujoco.mjtJoint.mjJNT_BALL)
_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
_TRN_JOINT = int(mujoco.mjtTrn.mjTRN_JOINT)
_GAIN_FIXED = int(mujoco.mjtGain.mjGAIN_FIXED)
_BIAS_NONE = int(mujoco.mjtBias.mjBIAS_NONE)
_BIAS_AFFINE = int(mujoco.mjtBias.mjBIAS_AFFINE)
_UNIT_AXES = {(1.0, 0.0, 0.0): "X", (0.0, 1.0, 0.0): "Y", (0.0, 0.0, 1.0): "Z"}


def read_mjcf(text: bytes | str, read: FileReader | None) -> Draft:
    """An MJCF compiled by MuJoCo, its robot read into Pinocchio, for ``describe`` to finish."""
    _, mj = compile_mjcf(text, read)
    check_size(mj.nbody, mj.nv, "bodies")
    root = _robot_root(mj)
    builder = _PinocchioFromMujoco(mj, root)
    model = builder.model
    torque_limit, kinds, warnings = _mjcf_actuation(mj, model, builder.joints)
    return Draft(
        model=model,
        bodies=builder.bodies,
        torque_limit=torque_limit,
        actuator_kind=kinds,
        ball_swing_limit={
            mj.joint(j).name: float(mj.jnt_range[j, 1]) if mj.jnt_limited[j] else np.pi
            for j in builder.joints
            if mj.jnt_type[j] == _BALL
        },
        configuration=builder.configuration(mj.qpos0),
        keyframes={
            mj.key(k).name or f"key{k}": builder.configuration(mj.key_qpos[k])
            for k in range(mj.nkey)
        },
        sole_sites=builder.sole_sites(),
        warnings=warnings,
    )


def _robot_root(mj: mujoco.MjModel) -> int:
    """The body under the world that is the robot: the one with a free joint, else the most DoFs.

    Raises:
        DescriptionError: No body has a joint, or several have free joints.
    """
    roots = [b for b in range(1, mj.nbody) if mj.body_parentid[b] == 0]
    free = [b for b in roots if any(mj.jnt_type[j] == _FREE for j in _body_joints(mj, b))]
    if len(free) > 1:
        names = ", ".join(mj.body(b).name or f"body{b}" for b in free)
        raise DescriptionError(
            f"several bodies have a free joint ({names}); Poise controls one robot per model"
        )
    if free:
        return free[0]
    dofs = {
        b: int(sum(mj.body_dofnum[d] for d in range(mj.nbody) if mj.body_rootid[d] == b))
        for b in roots
    }
    if not dofs or max(dofs.values()) == 0:
        raise DescriptionError("the model has no body with joints under <worldbody>")
    return max(dofs, key=lambda b: dofs[b])


def _body_joints(mj: mujoco.MjModel, body: int) -> range:
    start = int(mj.body_jntadr[body])
    return range(start, start + int(mj.body_jntnum[body])) if start >= 0 else range(0)


class _PinocchioFromMujoco:
    """Builds a Pinocchio model from a compiled MuJoCo model, body by body.

    A MuJoCo joint at anchor ``p`` of its body (axis in the body frame) moves
    the body by ``T(p) · motion · T(−p)``; several joints of one body chain in
    document order. Each becomes a Pinocchio joint placed at ``T(p)``
    (relative to the previous joint of the chain: ``T(−p_prev) T(p)``), and
    the body — inertia, frame, sites — hangs from the last one at ``T(−p)``.
    Bodies without joints are welded to their parent's joint.

    Frames are looked up by name, and MuJoCo keeps bodies, joints and sites
    in separate namespaces (a free joint ``root`` on a body ``root``): a
    body's frame takes its name, a site's or a joint's only where no body
    (nor, for a joint, a site) has it.
    """

    def __init__(self, mj: mujoco.MjModel, root: int):
        self.mj = mj
        self.model = pin.Model()
        self.joints: list[int] = []  # MuJoCo joint ids in Pinocchio order (free root excluded)
        self.bodies: list[Body] = []
        self._body_index: dict[int, int] = {}
        self._placement: dict[int, tuple[int, pin.SE3]] = {}  # body → (pin joint, body in joint)
        self._site_frames: list[tuple[int, int]] = []  # (site id, frame id)
        self.root = root
        self._body_names = {mj.body(b).name for b in range(mj.nbody)}
        self._taken = self._body_names | {mj.site(s).name for s in range(mj.nsite)}
        gravity = mj.opt.gravity
        self.model.gravity = pin.Motion(np.array(gravity, float), np.zeros(3))
        free = [j for j in _body_joints(mj, root) if mj.jnt_type[j] == _FREE]
        self.root_pose = se3(mj.body_pos[root], mj.body_quat[root])
        self._free_qpos = int(mj.jnt_qposadr[free[0]]) if free else None
        joint_name = mj.joint(free[0]).name if free and mj.joint(free[0]).name else "root_joint"
        joint = self.model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), joint_name)
        self._add_joint_frame(joint)
        self._add_body(root, joint, pin.SE3.Identity(), skip_free=True)
        for body in range(root + 1, mj.nbody):
            if mj.body_rootid[body] == root:
                parent_joint, parent_in_joint = self._placement[int(mj.body_parentid[body])]
                offset = se3(mj.body_pos[body], mj.body_quat[body])
                self._add_body(body, parent_joint, parent_in_joint * offset, skip_free=False)

    def _add_joint_frame(self, joint: int) -> None:
        if self.model.names[joint] not in self._taken:
            self.model.addJointFrame(joint, 0)

    def _add_body(self, body: int, joint: int, body_in_joint: pin.SE3, *, skip_free: bool) -> None:
        mj, model = self.mj, self.model
        anchor = np.zeros(3)
        for j in _body_joints(mj, body):
            kind = int(mj.jnt_type[j])
            if kind == _FREE:
                if skip_free:
                    continue
                raise DescriptionError(f"free joint {mj.joint(j).name!r} is not on the root body")
            placement = (
                body_in_joint * pin.SE3(np.eye(3), -anchor) * pin.SE3(np.eye(3), mj.jnt_pos[j])
            )
            name = mj.joint(j).name
            if not name:
                raise DescriptionError(
                    f"a joint of body {mj.body(body).name!r} has no name; name every joint"
                )
            joint = model.addJoint(joint, _joint_model(kind, mj.jnt_axis[j]), placement, name)
            self._add_joint_frame(joint)
            v = model.joints[joint].idx_v
            model.armature[v : v + model.joints[joint].nv] = mj.dof_armature[
                mj.jnt_dofadr[j] : mj.jnt_dofadr[j] + model.joints[joint].nv
            ]
            if kind in (_HINGE, _SLIDE):
                limited = bool(mj.jnt_limited[j])
                q = model.joints[joint].idx_q
                model.lowerPositionLimit[q] = mj.jnt_range[j, 0] if limited else -np.inf
                model.upperPositionLimit[q] = mj.jnt_range[j, 1] if limited else np.inf
            self.joints.append(j)
            anchor = np.array(mj.jnt_pos[j], float)
            body_in_joint = pin.SE3.Identity()
        body_in_joint = body_in_joint * pin.SE3(np.eye(3), -anchor)
        rotation = pin.Quaternion(*mj.body_iquat[body]).normalized().matrix()
        inertia = pin.Inertia(
            float(mj.body_mass[body]),
            np.array(mj.body_ipos[body], float),
            rotation @ np.diag(mj.body_inertia[body]) @ rotation.T,
        )
        model.appendBodyToJoint(joint, inertia, body_in_joint)
        name = mj.body(body).name or f"body{body}"
        parent = self._body_index.get(int(mj.body_parentid[body]), -1)
        parent_frame = self.bodies[parent].frame_id if parent >= 0 else 0
        frame = model.addBodyFrame(name, joint, body_in_joint, parent_frame)
        for site in map(int, np.flatnonzero(mj.site_bodyid == body)):
            site_name = mj.site(site).name
            if site_name and site_name not in self._body_names:
                placement = body_in_joint * se3(mj.site_pos[site], mj.site_quat[site])
                frame_id = model.addFrame(
                    pin.Frame(mj.site(site).name, joint, frame, placement, pin.OP_FRAME)
                )
                self._site_frames.append((site, frame_id))
        self._placement[body] = (joint, body_in_joint)
        self._body_index[body] = len(self.bodies)
        self.bodies.append(Body.with_shapes(name, parent, frame, _geom_shapes(mj, body)))

    def configuration(self, qpos: np.ndarray) -> np.ndarray:
        """Pinocchio ``q`` from a MuJoCo ``qpos`` (base from the free joint, or the body's pose)."""
        mj, model = self.mj, self.model
        q = np.zeros(model.nq)
        if self._free_qpos is None:
            q[:3] = self.root_pose.translation
            q[3:7] = pin.Quaternion(self.root_pose.rotation).coeffs()
        else:
            a = self._free_qpos
            q[:3] = qpos[a : a + 3]
            w, x, y, z = qpos[a + 3 : a + 7]
            q[3:7] = (x, y, z, w)
        for pin_joint, j in enumerate(self.joints, start=2):
            idx, a = model.joints[pin_joint].idx_q, int(mj.jnt_qposadr[j])
            if mj.jnt_type[j] == _BALL:
                w, x, y, z = qpos[a : a + 4]
                q[idx : idx + 4] = (x, y, z, w)
            else:
                q[idx] = qpos[a]
        for start in [
            3,
            *(model.joints[i].idx_q for i in range(2, model.njoints) if model.joints[i].nq == 4),
        ]:
            q[start : start + 4] /= np.linalg.norm(q[start : start + 4])
        return q

    def sole_sites(self) -> list[FoundContact]:
        """Contacts from ``*_sole`` box sites: the four corners of their x–y rectangle."""
        mj = self.mj
        found = []
        for site, _ in self._site_frames:
            name = mj.site(site).name
            if name.endswith("_sole") and mj.site_type[site] == GEOM.mjGEOM_BOX:
                half_x, half_y = mj.site_size[site, :2]
                corners = [(sx * half_x, sy * half_y, 0.0) for sx in (1, -1) for sy in (1, -1)]
                found.append(
                    FoundContact(
                        name.removesuffix("_sole") + "_foot",
                        name,
                        np.array(corners),
                        reason=f"the corners of the box site {name!r}",
                    )
                )
        return found


def _joint_model(kind: int, axis: np.ndarray) -> pin.JointModel:
    if kind == _BALL:
        return pin.JointModelSpherical()
    unit = tuple(float(round(a, 12)) for a in axis)
    letter = _UNIT_AXES.get(unit)
    if kind == _HINGE:
        return (
            getattr(pin, f"JointModelR{letter}")()
            if letter
            else pin.JointModelRevoluteUnaligned(np.array(axis, float))
        )
    return (
        getattr(pin, f"JointModelP{letter}")()
        if letter
        else pin.JointModelPrismaticUnaligned(np.array(axis, float))
    )


def _geom_shapes(mj: mujoco.MjModel, body: int) -> list[np.ndarray]:
    """Points and radii (``(k, 4)`` each) of a body's colliding geoms, in the body frame."""
    shapes = []
    for geom in map(int, np.flatnonzero(mj.geom_bodyid == body)):
        if not (mj.geom_contype[geom] or mj.geom_conaffinity[geom]):
            continue
        local = shape_points(int(mj.geom_type[geom]), mj.geom_size[geom], mesh_vertices(mj, geom))
        if local is not None:
            shapes.append(placed(local, se3(mj.geom_pos[geom], mj.geom_quat[geom])))
    return shapes


def _mjcf_actuation(
    mj: mujoco.MjModel, model: pin.Model, joints: list[int]
) -> tuple[np.ndarray, dict[str, str], list[str]]:
    """Torque limits per DoF, actuator kind per joint, and warnings (see the module docstring)."""
    limit = np.zeros(model.nv)
    actuated = np.zeros(model.nv, dtype=bool)
    pin_joint = {j: model.getJointId(mj.joint(j).name) for j in joints}
    kinds: dict[str, str] = {mj.joint(j).name: "none" for j in joints}
    for actuator in range(mj.nu):
        j = int(mj.actuator_trnid[actuator, 0])
        if mj.actuator_trntype[actuator] != _TRN_JOINT or j not in pin_joint:
            continue
        kind = _actuator_kind(mj, actuator)
        name = mj.joint(j).name
        kinds[name] = kind if kinds[name] in ("none", kind) else "general"
        bound = np.inf
        if mj.actuator_forcelimited[actuator]:
            bound = float(np.abs(mj.actuator_forcerange[actuator]).max())
        if kind == "motor" and mj.actuator_ctrllimited[actuator]:
            gain = abs(float(mj.actuator_gainprm[actuator, 0]))
            bound = min(bound, gain * float(np.abs(mj.actuator_ctrlrange[actuator]).max()))
        joint = model.joints[pin_joint[j]]
        gear = np.abs(mj.actuator_gear[actuator, : joint.nv])
        dofs = slice(joint.idx_v, joint.idx_v + joint.nv)
        limit[dofs] += np.where(gear > 0, bound * gear, 0.0)
        actuated[dofs] |= gear > 0
    limit[~actuated] = np.inf
    for j, pin_id in pin_joint.items():
        if mj.jnt_actfrclimited[j]:
            joint = model.joints[pin_id]
            dofs = slice(joint.idx_v, joint.idx_v + joint.nv)
            limit[dofs] = np.minimum(limit[dofs], np.abs(mj.jnt_actfrcrange[j]).max())
    warnings = [f"joint {name!r} has no actuator" for name, kind in kinds.items() if kind == "none"]
    return limit[6:], kinds, warnings


def _actuator_kind(mj: mujoco.MjModel, actuator: int) -> str:
    """``motor`` (gain · ctrl), ``position`` (−kp q bias), ``velocity`` (−kv q̇), ``general``."""
    gain_type, bias_type = int(mj.actuator_gaintype[actuator]), int(mj.actuator_biastype[actuator])
    bias = mj.actuator_biasprm[actuator]
    if gain_type != _GAIN_FIXED or mj.actuator_dyntype[actuator] != 0:
        return "general"
    if bias_type == _BIAS_NONE:
        return "motor"
    if bias_type == _BIAS_AFFINE and bias[0] == 0 and bias[1] < 0:
        return "position"
    if bias_type == _BIAS_AFFINE and bias[0] == 0 and bias[1] == 0 and bias[2] < 0:
        return "velocity"
    return "general"
