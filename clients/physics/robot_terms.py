"""What a scenario asks of a robot, in the robot's own terms: legs, trunk, inertia, push bounds.

A built-in scenario is written once and runs on any biped that ``poise
inspect`` accepts, so it cannot name one robot's joints or bodies. What it
needs is found here from the robot's description
(:func:`~clients.physics.model_file.describe_model`):

* **The legs** (:func:`leg_pitch_joints`): the chain of joints from the
  root to each contact's frame; its *pitch* degrees of freedom are those
  whose axis (at the standing pose) is the base's lateral axis (for a ball
  joint, the one of its three closest to it). The first is the hip, the last
  the ankle, and the knee the one between them with the largest range.
* **A crouch** (:func:`crouched_joint_positions`): each knee bent to at least
  an angle between thigh and shank (measured from the joint positions, not
  from the joint's zero), the hip and the ankle turned half as much the other
  way, so the foot stays flat and the trunk upright.
* **The trunk** (:func:`resolve_body`): a push on ``trunk`` (or on
  ``chest``, ``torso``, ``abdomen`` when the robot has no body of that name)
  acts on the heaviest rigid segment outside the legs; ``root`` (or
  ``pelvis``) is the root body. A body the robot has is always itself.
* **Vertical inertia** (:func:`vertical_inertia`): the composite rigid-body
  inertia about the vertical through the CM, for a twist sized as a yaw rate.
* **The no-step bound** (:func:`no_step_bound`): the largest horizontal
  impulse the robot can take on both feet without stepping (linear inverted
  pendulum, Koolen et al. 2012, Pratt et al. 2006): ``J = m ω d``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from clients.physics.model_file import RobotDescription

__all__ = [
    "ROOT_WORDS",
    "TRUNK_WORDS",
    "LegJoints",
    "NoStepBound",
    "RobotTermsError",
    "crouched_joint_positions",
    "knee_bend_rad",
    "leg_pitch_joints",
    "no_step_bound",
    "resolve_body",
    "trunk_body",
    "vertical_inertia",
]

TRUNK_WORDS = ("trunk", "chest", "torso", "abdomen")
"""Push bodies that mean "the trunk" on a robot without a body of that name."""
ROOT_WORDS = ("root", "pelvis")
"""Push bodies that mean "the root body" on a robot without a body of that name."""
PITCH_AXIS_MIN_COSINE = math.cos(math.radians(30.0))
"""A hinge whose axis is within 30° of the base's lateral axis is a pitch joint."""


class RobotTermsError(ValueError):
    """What a scenario asks cannot be found on this robot (one line: what to give instead)."""


@dataclass(frozen=True)
class PitchDof:
    """One pitch degree of freedom of a leg.

    Attributes:
        joint: Pinocchio joint id.
        name: Joint name.
        index_q: Index in the configuration ``q``.
        local_axis: Rotation axis in the joint frame along which to turn it.
        sign: +1 if a positive turn about ``local_axis`` pitches about the base's
            lateral axis (+y), −1 if the other way.
        range_rad: Its joint range (``inf`` for a ball joint or an unlimited hinge).
    """

    joint: int
    name: str
    index_q: int
    local_axis: np.ndarray
    sign: float
    range_rad: float


@dataclass(frozen=True)
class LegJoints:
    """A leg's hip, knee and ankle pitch, from the root to one contact."""

    contact: str
    hip: PitchDof
    knee: PitchDof
    ankle: PitchDof


@dataclass(frozen=True)
class NoStepBound:
    """The largest horizontal impulse survivable without a step, along one direction.

    Attributes:
        impulse_N_s: ``m ω d`` (N·s).
        mass_kg: ``m``.
        com_height_m: CM height above the soles (m).
        omega_per_s: ``ω = √(g / z)`` (1/s).
        distance_m: ``d``: from the CM's ground projection to the edge of the support
            polygon (convex hull of both soles) along the direction (m).
    """

    impulse_N_s: float
    mass_kg: float
    com_height_m: float
    omega_per_s: float
    distance_m: float


def _lateral_axis(description: RobotDescription, q: np.ndarray) -> np.ndarray:
    """The base's lateral (y) axis, horizontal, in world."""
    rotation = pin.Quaternion(np.asarray(q[3:7])).normalized().toRotationMatrix()
    axis = rotation[:, 1].copy()
    axis[2] = 0.0
    norm = np.linalg.norm(axis)
    return axis / norm if norm > 1e-6 else np.array([0.0, 1.0, 0.0])


def _chain(model: pin.Model, frame: str) -> list[int]:
    """Joint ids from the root's first child down to the joint carrying ``frame``."""
    joint = model.frames[model.getFrameId(frame)].parentJoint
    chain = []
    while joint > 1:
        chain.append(joint)
        joint = model.parents[joint]
    return chain[::-1]


def _pitch_dof(
    model: pin.Model, data: pin.Data, joint: int, lateral: np.ndarray
) -> PitchDof | None:
    kind = model.joints[joint].shortname()
    rotation = data.oMi[joint].rotation
    index_q = model.joints[joint].idx_q
    if kind == "JointModelSpherical":
        cosines = rotation.T @ lateral  # the lateral axis in the joint frame
        k = int(np.argmax(np.abs(cosines)))
        if abs(cosines[k]) < PITCH_AXIS_MIN_COSINE:
            return None
        axis = np.eye(3)[k]
        return PitchDof(
            joint, model.names[joint], index_q, axis, float(np.sign(cosines[k])), math.inf
        )
    axes = {"JointModelRX": 0, "JointModelRY": 1, "JointModelRZ": 2}
    if kind in axes:
        axis = np.eye(3)[axes[kind]]
    elif kind == "JointModelRevoluteUnaligned":
        axis = np.asarray(model.joints[joint].extract().axis, dtype=float)
    else:
        return None
    cosine = float((rotation @ axis) @ lateral)
    if abs(cosine) < PITCH_AXIS_MIN_COSINE:
        return None
    span = float(model.upperPositionLimit[index_q] - model.lowerPositionLimit[index_q])
    return PitchDof(
        joint,
        model.names[joint],
        index_q,
        axis,
        float(np.sign(cosine)),
        span if math.isfinite(span) else math.inf,
    )


def leg_pitch_joints(description: RobotDescription, q: np.ndarray | None = None) -> list[LegJoints]:
    """Each contact's leg: hip, knee and ankle pitch (see the module docstring).

    Raises:
        RobotTermsError: A leg has fewer than three pitch joints.
    """
    model = description.model
    q = description.standing_configuration if q is None else q
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    lateral = _lateral_axis(description, q)
    legs = []
    for contact in description.contacts:
        chain = _chain(model, contact.frame)
        pitches = [dof for joint in chain if (dof := _pitch_dof(model, data, joint, lateral))]
        if len(pitches) < 3:
            names = ", ".join(model.names[j] for j in chain) or "none"
            raise RobotTermsError(
                f"the leg of contact {contact.name!r} has {len(pitches)} pitch joint(s) "
                f"(joints from the root: {names}), and a crouch needs a hip, a knee and an "
                "ankle; give the pose with `initial_joint_position` instead"
            )
        knee = max(pitches[1:-1], key=lambda dof: dof.range_rad)
        legs.append(LegJoints(contact.name, pitches[0], knee, pitches[-1]))
    return legs


def knee_bend_rad(description: RobotDescription, leg: LegJoints, q: np.ndarray) -> float:
    """Angle between thigh (hip → knee) and shank (knee → ankle) about the lateral axis (rad).

    Positive: the knee ahead of the line from hip to ankle (a bent knee).
    """
    model = description.model
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    hip, knee, ankle = (data.oMi[d.joint].translation for d in (leg.hip, leg.knee, leg.ankle))
    lateral = _lateral_axis(description, q)
    thigh, shank = knee - hip, ankle - knee
    thigh -= (thigh @ lateral) * lateral
    shank -= (shank @ lateral) * lateral
    return float(math.atan2(np.cross(thigh, shank) @ lateral, thigh @ shank))


def crouched_joint_positions(
    description: RobotDescription, knee_bend_at_least_rad: float, q: np.ndarray | None = None
) -> dict[str, list[float]]:
    """The legs' pitch joints of a crouch, by joint name (as ``initial_joint_position``).

    Each knee is bent to at least ``knee_bend_at_least_rad`` (:func:`knee_bend_rad`), its
    hip and ankle pitch turned half the added bend the other way (the foot keeps its
    orientation, the trunk upright). A knee bent that much already is left as it is.

    Raises:
        RobotTermsError: A leg without hip, knee and ankle pitch joints.
    """
    model = description.model
    q = np.array(description.standing_configuration if q is None else q, dtype=float)
    positions: dict[str, list[float]] = {}
    for leg in leg_pitch_joints(description, q):
        added = knee_bend_at_least_rad - knee_bend_rad(description, leg, q)
        if added <= 0.0:
            continue
        for dof, turn in ((leg.hip, -0.5 * added), (leg.knee, added), (leg.ankle, -0.5 * added)):
            joint = model.joints[dof.joint]
            dq = np.zeros(model.nv)
            if joint.nq == 4:
                dq[joint.idx_v : joint.idx_v + 3] = dof.sign * turn * dof.local_axis
            else:
                dq[joint.idx_v] = dof.sign * turn
            q = pin.integrate(model, q, dq)
            positions[dof.name] = [float(x) for x in q[joint.idx_q : joint.idx_q + joint.nq]]
    return positions


def _segment_first_bodies(description: RobotDescription) -> dict[int, int]:
    """Pinocchio joint → index of the first body it carries (its segment's name)."""
    first: dict[int, int] = {}
    for index, body in enumerate(description.bodies):
        first.setdefault(description.model.frames[body.frame_id].parentJoint, index)
    return first


def trunk_body(description: RobotDescription) -> str:
    """The heaviest rigid segment outside the legs (a leg: a segment above a contact), by name.

    The root segment counts, although the legs hang from it.
    """
    model = description.model
    leg_joints = {
        joint for contact in description.contacts for joint in _chain(model, contact.frame)
    }
    candidates = [
        (model.inertias[joint].mass, index)
        for joint, index in _segment_first_bodies(description).items()
        if joint == 1 or not (set(_ancestors(model, joint)) & leg_joints)
    ]
    return description.bodies[max(candidates)[1]].name


def _ancestors(model: pin.Model, joint: int) -> list[int]:
    """``joint`` and its ancestors below the universe."""
    chain = []
    while joint > 0:
        chain.append(joint)
        joint = model.parents[joint]
    return chain


def resolve_body(description: RobotDescription, name: str) -> str | None:
    """The body a push on ``name`` acts on (``None``: no such body, nor a word for one).

    ``name`` itself if the robot has it, else the trunk (:data:`TRUNK_WORDS`) or the root
    (:data:`ROOT_WORDS`).
    """
    bodies = [body.name for body in description.bodies]
    if name in bodies:
        return name
    if name in TRUNK_WORDS:
        return trunk_body(description)
    if name in ROOT_WORDS:
        return bodies[0]
    return None


def vertical_inertia(description: RobotDescription, q: np.ndarray | None = None) -> float:
    """Composite rigid-body inertia of the whole robot about the vertical through its CM (kg·m²)."""
    model = description.model
    q = description.standing_configuration if q is None else q
    data = model.createData()
    pin.ccrba(model, data, q, np.zeros(model.nv))
    return float(data.Ig.inertia[2, 2])


def no_step_bound(
    description: RobotDescription,
    direction_in_world: tuple[float, float, float],
    q: np.ndarray | None = None,
) -> NoStepBound:
    """The no-step capture bound of a horizontal push along ``direction_in_world``.

    An impulse ``J`` gives the CM a velocity ``J / m``; the linear inverted pendulum's
    capture point ``ξ = c + ċ / ω``, ``ω = √(g / z)``, moves by ``J / (m ω)``; on both feet
    the robot can stop without a step while ``ξ`` stays in the support polygon (Pratt et al.
    2006; Koolen et al. 2012, capturability). So ``J ≤ m ω d``, ``d`` the distance from the
    CM's ground projection to the polygon's edge along the push. ``z`` is the CM height above
    the lowest sole point, at ``q`` (default: the standing pose). The vertical part of the
    direction is ignored.

    Raises:
        RobotTermsError: The direction has no horizontal part, or the CM is not above the
            support polygon.
    """
    model = description.model
    q = description.standing_configuration if q is None else q
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    com = pin.centerOfMass(model, data, q)
    points = np.array(
        [
            data.oMf[model.getFrameId(contact.frame)].act(np.asarray(point, dtype=float))
            for contact in description.contacts
            for point in contact.points_in_frame
        ]
    )
    direction = np.array(direction_in_world[:2], dtype=float)
    if np.linalg.norm(direction) < 1e-9:
        raise RobotTermsError(f"push direction {direction_in_world} has no horizontal part")
    direction /= np.linalg.norm(direction)
    distance = _distance_to_hull_edge(points[:, :2], com[:2], direction)
    height = float(com[2] - points[:, 2].min())
    gravity = float(np.linalg.norm(model.gravity.linear))
    omega = math.sqrt(gravity / height)
    mass = description.total_mass
    return NoStepBound(mass * omega * distance, mass, height, omega, distance)


def _convex_hull(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise hull of 2-D points (Andrew's monotone chain)."""
    unique = sorted({(float(x), float(y)) for x, y in points})

    def cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    upper: list[tuple[float, float]] = []
    for point in unique:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], point) <= 1e-12:
            lower.pop()
        lower.append(point)
    for point in reversed(unique):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], point) <= 1e-12:
            upper.pop()
        upper.append(point)
    return np.array(lower[:-1] + upper[:-1])


def _distance_to_hull_edge(points: np.ndarray, start: np.ndarray, direction: np.ndarray) -> float:
    """Distance from ``start`` (inside) along ``direction`` (unit) to the hull's boundary."""
    hull = _convex_hull(points)
    if len(hull) < 3:
        raise RobotTermsError("the soles' points span no area: no support polygon")
    best = math.inf
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        edge = b - a
        outward = np.array([edge[1], -edge[0]]) / np.linalg.norm(edge)
        inside = float(outward @ (a - start))  # ≥ 0 while start is inside this edge
        if inside < -1e-9:
            raise RobotTermsError("the CM's ground projection is outside the support polygon")
        speed = float(outward @ direction)
        if speed > 1e-12:
            best = min(best, inside / speed)
    return best
