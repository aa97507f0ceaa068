"""The MuJoCo backend's model: the robot file changed so MuJoCo simulates what the server controls.

:class:`~clients.physics.mujoco_backend.MujocoBackend` loads the same file the
server loads, an MJCF with its includes and assets or a URDF through MuJoCo's
importer (:func:`mujoco_spec`). Where the file cannot be simulated as the
server controls it, :class:`ModelConversions` changes it and says so in
``conversions`` (the backend's): position and velocity servos become
torque motors with their force limits, a missing floor plane is added, a
root without a free joint gets one, a URDF's joints get motors at their
effort limits, the robot's body pairs that touch at the standing pose or a
keyframe (and those its SRDF disables) do not collide, and a URDF's meshes
reach MuJoCo in memory, one asset per file. Bodies outside the robot (a
jointed prop in the scene) are left to MuJoCo (:meth:`ModelConversions.find_robot`).

Physics choices:

* **Integrator:** MuJoCo's semi-implicit Euler (``mjINT_EULER``, the
  default): velocities first, then positions with the new velocities. The
  built-in robots have no joint damping and the motors are pure force
  actuators, so ``implicitfast`` has nothing to treat implicitly: it gave
  the same standing trajectory (to 1e-9 after 0.5 s) for 5–10 % more time
  per step.
* **Friction:** the floor and the foot geoms get sliding friction ``μ``,
  and every ground geom gets a higher ``priority`` than any robot geom, so
  MuJoCo takes the ground's coefficients for each ground contact instead of
  the element-wise maximum of the pair: the effective sliding coefficient of
  every ground contact (feet, and knees or hands after a fall) is exactly
  ``μ``. Contacts use MuJoCo's elliptic cone, so ``‖f_t‖ ≤ μ f_n`` holds in
  every tangential direction (the default pyramid only bounds
  ``|f_x| + |f_y|``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import mujoco
import numpy as np

from clients.physics.errors import UnsupportedModel
from clients.physics.model_file import (
    DescriptionError,
    describe_model,
    local_reader,
    model_format,
)
from controller_server.models.description import RobotDescription, compile_mjcf, gather_files
from protocol.messages import ContactSpec

__all__ = [
    "FREE_JOINT",
    "GRAVITY_M_S2",
    "ModelConversions",
    "RobotInModel",
    "mujoco_spec",
    "subtree_bodies",
]

GRAVITY_M_S2 = 9.81
"""Magnitude of gravity (m/s²), acting along −z."""
FREE_JOINT = int(mujoco.mjtJoint.mjJNT_FREE)
"""MuJoCo's ``jnt_type`` of a free joint."""


def mujoco_spec(path: Path) -> tuple[mujoco.MjSpec, list[str]]:
    """The file as MuJoCo reads it: MJCF with its includes and assets, or URDF.

    URDF is imported by MuJoCo's own importer, with its static links kept
    (``fusestatic="false"``: the root link would otherwise be fused into the
    world) and every mesh handed over in memory (:func:`_urdf_for_mujoco`).

    Returns:
        The spec, and what was changed on the way (notes for the run's log).
    """
    text, read = path.read_bytes(), local_reader(path)
    if model_format(path) == "mjcf":
        return compile_mjcf(text, read)[0], []
    urdf, assets, notes = _urdf_for_mujoco(text, gather_files(text, "urdf", read))
    try:
        return mujoco.MjSpec.from_string(urdf, assets=assets), notes
    except ValueError as exc:
        detail = " ".join(str(exc).split())
        raise DescriptionError(f"MuJoCo could not import the URDF: {detail}") from None


def _urdf_for_mujoco(
    text: bytes, files: dict[str, bytes]
) -> tuple[str, dict[str, bytes], list[str]]:
    """The URDF as MuJoCo's importer gets it: every mesh an in-memory asset of its own.

    MuJoCo's importer names a mesh asset after its file's base name and opens
    what it cannot find in the assets from the disk (``package://`` URIs
    included, which it cannot read). So every ``<mesh filename>`` becomes a
    key ``poise_asset_N.<ext>`` of the files read beside the model (one key
    per distinct ``filename``: two meshes of the same base name in different
    directories stay two meshes), a collision whose mesh could not be read is
    dropped, and the document is written back by the XML library, so no name
    from the file reaches MuJoCo unescaped. Visual elements are dropped (as
    MuJoCo's ``discardvisual`` would: the backend simulates, it does not draw),
    and the file's own ``<mujoco><compiler>`` loses its asset directories.

    Args:
        text: The URDF.
        files: The files it names, by ``filename`` as written
            (:func:`~controller_server.models.description.gather_files`).

    Returns:
        The URDF for MuJoCo, its assets by key, and a note if meshes were dropped.
    """
    robot = ET.fromstring(text)  # the description has parsed it already
    assets: dict[str, bytes] = {}
    keys: dict[str, str] = {}
    dropped: list[str] = []
    for link in robot.iter("link"):
        for visual in link.findall("visual"):
            link.remove(visual)
        for collision in link.findall("collision"):
            mesh = collision.find("geometry/mesh")
            if mesh is None:
                continue
            filename = mesh.get("filename", "")
            data = files.get(filename)
            if data is None:
                link.remove(collision)
                dropped.append(f"{link.get('name', '')} ({filename})")
                continue
            if filename not in keys:
                keys[filename] = f"poise_asset_{len(keys)}{PurePosixPath(filename).suffix.lower()}"
                assets[keys[filename]] = data
            mesh.set("filename", keys[filename])
    for material in robot.iter("material"):
        for texture in material.findall("texture"):
            material.remove(texture)
    options = robot.find("mujoco")
    if options is None:
        options = ET.Element("mujoco")
        robot.insert(0, options)
    compiler = options.find("compiler")
    if compiler is None:
        compiler = ET.SubElement(options, "compiler")
    for directory in ("meshdir", "texturedir", "assetdir"):
        compiler.attrib.pop(directory, None)
    compiler.set("fusestatic", "false")
    compiler.set("discardvisual", "true")
    notes = (
        [f"dropped {len(dropped)} collision mesh(es) that could not be read: " + ", ".join(dropped)]
        if dropped
        else []
    )
    return ET.tostring(robot, encoding="unicode"), assets, notes


def subtree_bodies(model: mujoco.MjModel, top: int) -> list[int]:
    """``top`` and every body below it (MuJoCo numbers parents before children)."""
    inside = [top]
    for body in range(top + 1, model.nbody):
        if int(model.body_parentid[body]) in inside:
            inside.append(body)
    return inside


@dataclass(frozen=True)
class RobotInModel:
    """The robot in a compiled model: its root's subtree (other bodies are MuJoCo's).

    Attributes:
        free_joint: The root's free joint.
        qpos: Its ``qpos`` address.
        dof: Its ``qvel`` address.
        bodies: The robot's bodies.
        joints: The joints of those bodies.
    """

    free_joint: int
    qpos: int
    dof: int
    bodies: list[int]
    joints: list[int]


class ModelConversions:
    """The changes that make MuJoCo simulate a model file as the server controls it.

    Args:
        model_path: The file simulated.
        description: The server's reading of it.
        friction_coefficient: Sliding friction ``μ`` of every ground contact.
        timestep_s: Integration step (s).
        ground_height_m: Height of the floor plane (m).
        contact_time_constant_s: Time constant of every contact with the floor
            (``solref``, damping ratio 1), or ``None`` for the model's.
        srdf: A URDF's SRDF, instead of the one beside it.
        notes: What was changed already (:func:`mujoco_spec`).

    Attributes:
        conversions: What was changed so MuJoCo simulates what the server controls
            (for the run's log), in order.
    """

    def __init__(
        self,
        model_path: Path,
        description: RobotDescription,
        *,
        friction_coefficient: float,
        timestep_s: float,
        ground_height_m: float,
        contact_time_constant_s: float | None,
        srdf: str | Path | None,
        notes: list[str],
    ):
        self.model_path = model_path
        self.description = description
        self.friction_coefficient = friction_coefficient
        self.timestep_s = timestep_s
        self.ground_height_m = ground_height_m
        self.contact_time_constant_s = contact_time_constant_s
        self._srdf = srdf
        self.conversions: list[str] = list(notes)

    def _fail(self, detail: str) -> UnsupportedModel:
        return UnsupportedModel(f"{self.model_path}: {detail}")

    def configure(self, spec: mujoco.MjSpec) -> None:
        """Options, floor, free root, actuators, friction and priorities, before compiling."""
        options = spec.option
        options.timestep = self.timestep_s
        options.gravity = [0.0, 0.0, -GRAVITY_M_S2]
        options.integrator = mujoco.mjtIntegrator.mjINT_EULER
        options.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        planes = [g for g in spec.worldbody.geoms if g.type == mujoco.mjtGeom.mjGEOM_PLANE]
        if not planes:
            planes = [spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1])]
            self.conversions.append("added a floor (the model has no plane)")
        for plane in planes:
            if not np.allclose(plane.quat, (1.0, 0.0, 0.0, 0.0)):
                raise self._fail(f"floor {plane.name!r} is not horizontal")
            plane.pos[2] = self.ground_height_m
        root = spec.body(self.description.bodies[0].name)
        if not any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in root.joints):
            root.add_freejoint()
            self.conversions.append(f"gave the root body {root.name!r} a free joint")
        self._convert_actuators(spec)
        top_priority = max(geom.priority for geom in spec.geoms)
        for geom in spec.worldbody.geoms:
            geom.friction[0] = self.friction_coefficient
            geom.priority = top_priority + 1
            if self.contact_time_constant_s is not None:
                # The higher priority makes MuJoCo take this geom's solref for the contact.
                geom.solref = [self.contact_time_constant_s, 1.0]
        for contact in self.description.contacts:
            site = spec.site(contact.frame)
            body = site.parent if site is not None else spec.body(contact.frame)
            if body is None:
                raise self._fail(
                    f"contact frame {contact.frame!r} is neither a body nor a site: name one"
                )
            for geom in body.find_all(mujoco.mjtObj.mjOBJ_GEOM) + list(body.geoms):
                geom.friction[0] = self.friction_coefficient
        self._exclude_disabled_pairs(spec)

    def _exclude_disabled_pairs(self, spec: mujoco.MjSpec) -> None:
        """Exclude the body pairs the robot's SRDF disables (``disable_collisions``)."""
        pairs = self.description.disabled_collision_pairs
        present = [p for p in pairs if spec.body(p[0]) is not None and spec.body(p[1]) is not None]
        for first, second in present:
            spec.add_exclude(bodyname1=first, bodyname2=second)
        if pairs:
            absent = len(pairs) - len(present)
            self.conversions.append(
                f"excluded {len(present)} pair{'' if len(present) == 1 else 's'} the SRDF disables"
                + (f" ({absent} name a link this model lacks)" if absent else "")
            )

    def _convert_actuators(self, spec: mujoco.MjSpec) -> None:
        """Position and velocity servos become torque motors, force limits kept.

        The server commands torques; a servo would take them as set-points. A
        URDF's joints (no actuators in MuJoCo's import) get motors at their
        ``<limit effort>``. Anything else on a robot joint is refused.
        """
        joints = set(self.description.joint_names)
        converted = []
        for actuator in spec.actuators:
            if actuator.target not in joints:
                continue
            kind = self.description.actuator_kind.get(actuator.target, "general")
            if kind == "motor":
                continue
            if kind not in ("position", "velocity"):
                raise self._fail(
                    f"actuator {actuator.name!r} on joint {actuator.target!r} is a general "
                    "actuator; Poise sends torques: make it a <motor> (with its forcerange)"
                )
            actuator.set_to_motor()
            actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
            actuator.inheritrange = 0.0
            converted.append(actuator.name or actuator.target)
        if converted:
            self.conversions.append(
                f"made {len(converted)} position/velocity servos torque motors, force "
                f"limits kept: {', '.join(converted)}"
            )
        if self.description.format == "urdf":
            limits = dict(
                zip(self.description.joint_names, self.description.torque_limit, strict=True)
            )
            for name, limit in limits.items():
                motor = spec.add_actuator(target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
                motor.name = name
                if np.isfinite(limit):
                    motor.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
                    motor.forcerange = [-limit, limit]
            self.conversions.append(f"added {len(limits)} motors at the URDF's effort limits")

    def find_robot(self, model: mujoco.MjModel) -> RobotInModel:
        """The robot's free joint and bodies; the bodies outside it, left to MuJoCo, noted."""
        root = model.body(self.description.bodies[0].name).id
        free = [j for j in range(model.njnt) if model.jnt_type[j] == FREE_JOINT]
        free = [j for j in free if model.jnt_bodyid[j] == root]
        base_joint = free[0]
        base_qpos = int(model.jnt_qposadr[free[0]])
        base_dof = int(model.jnt_dofadr[free[0]])
        robot_bodies = subtree_bodies(model, root)
        robot = set(robot_bodies)
        robot_joints = [j for j in range(model.njnt) if int(model.jnt_bodyid[j]) in robot]
        outside: dict[int, list[str]] = {}
        for joint in range(model.njnt):
            body = int(model.jnt_bodyid[joint])
            if body not in robot:
                outside.setdefault(body, []).append(model.joint(joint).name or f"#{joint}")
        if outside:
            listed = ", ".join(
                f"{model.body(body).name or f'body #{body}'} "
                f"(joint{'s' if len(joints) > 1 else ''} {', '.join(joints)})"
                for body, joints in outside.items()
            )
            count = f"{len(outside)} bod{'ies' if len(outside) > 1 else 'y'}"
            self.conversions.append(f"left {count} outside the robot to the simulator: {listed}")
        return RobotInModel(base_joint, base_qpos, base_dof, robot_bodies, robot_joints)

    def exclude_self_collisions(
        self,
        spec: mujoco.MjSpec,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        robot_in_model: RobotInModel,
    ) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """Exclude the robot's body pairs that touch at the standing pose or a keyframe.

        MuJoCo excludes only parent–child pairs, so links a vendor drew
        overlapping (hip links across the pelvis, a hand in a thigh) push each
        other apart from the first step, and the robot fights itself. Each pair
        is noted with its depth and the pose it touched in; the model is
        recompiled (bodies, joints and addresses do not change).

        Args:
            spec: The spec ``model`` was compiled from.
            model: The compiled model.
            data: Its data (reset on return).
            robot_in_model: The robot in ``model`` (:meth:`find_robot`).

        Returns:
            The model and its data, recompiled if a pair was excluded.
        """
        robot = np.zeros(model.nbody, dtype=bool)
        robot[robot_in_model.bodies] = True
        touching: dict[tuple[int, int], tuple[float, str]] = {}
        for pose, configuration in self._poses():
            data.qpos[:] = self._qpos(model, robot_in_model.qpos, configuration)
            mujoco.mj_forward(model, data)
            contacts = data.contact
            for geoms, distance_m in zip(
                contacts.geom.tolist(), contacts.dist.tolist(), strict=True
            ):
                first, second = sorted(int(model.geom_bodyid[g]) for g in geoms)
                if not (robot[first] and robot[second]):
                    continue
                depth_m = max(0.0, -distance_m)
                if (first, second) not in touching or depth_m > touching[first, second][0]:
                    touching[first, second] = (depth_m, pose)
        mujoco.mj_resetData(model, data)
        if not touching:
            return model, data
        names = _body_names(model, spec)
        for (first, second), (depth_m, pose) in sorted(touching.items()):
            spec.add_exclude(bodyname1=names[first], bodyname2=names[second])
            self.conversions.append(
                f"excluded the self-collision {names[first]} – {names[second]}: "
                f"{1000 * depth_m:.1f} mm deep at {pose}"
            )
        model = spec.compile()
        return model, mujoco.MjData(model)

    def _poses(self) -> list[tuple[str, np.ndarray]]:
        """The standing pose and every keyframe the description knows (Pinocchio ``q``)."""
        poses = [("the standing pose", self.description.standing_configuration)]
        feet = [
            ContactSpec(name=c.name, frame=c.frame, points_in_frame=c.points_in_frame.tolist())
            for c in self.description.contacts
        ]
        for name in self.description.keyframes:
            if name == self.description.keyframe:
                continue
            try:
                keyframe = describe_model(
                    str(self.model_path), contacts=feet, keyframe=name, srdf=self._srdf
                )
            except DescriptionError as exc:
                self.conversions.append(f"keyframe {name!r} not checked for self-collision: {exc}")
                continue
            poses.append((f"keyframe {name!r}", keyframe.standing_configuration))
        return poses

    def _qpos(self, model: mujoco.MjModel, base_qpos: int, configuration: np.ndarray) -> np.ndarray:
        """MuJoCo ``qpos`` of a Pinocchio ``q`` of the description (others at ``qpos0``)."""
        pinocchio = self.description.model
        qpos = model.qpos0.copy()
        base = base_qpos
        qpos[base : base + 3] = configuration[:3]
        x, y, z, w = configuration[3:7]
        qpos[base + 3 : base + 7] = (w, x, y, z)
        for joint in range(2, pinocchio.njoints):
            start, count = pinocchio.joints[joint].idx_q, pinocchio.joints[joint].nq
            address = int(model.jnt_qposadr[model.joint(pinocchio.names[joint]).id])
            value = configuration[start : start + count]
            qpos[address : address + count] = (value[3], *value[:3]) if count == 4 else value
        return qpos


def _body_names(model: mujoco.MjModel, spec: mujoco.MjSpec) -> list[str]:
    """Every body's name, an unnamed one named now (an exclusion names its bodies)."""
    names = [model.body(b).name for b in range(model.nbody)]
    taken = set(names)
    for body, name in enumerate(names):
        if not name:
            fresh = f"unnamed_body_{body}"
            while fresh in taken:
                fresh += "_"
            spec.bodies[body].name = names[body] = fresh
            taken.add(fresh)
    return names
