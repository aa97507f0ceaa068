"""Per-tick rigid-body terms the controllers need, computed by Pinocchio.

A thin layer: no rigid-body algorithm is written here. One call to
:func:`compute_dynamics_terms` runs Pinocchio's ``computeAllTerms`` and the
centroidal momentum rate at zero acceleration (a kinematics pass), then reads off

* the joint-space mass matrix ``M`` and bias forces ``h`` (Macchietto 2008,
  eq. 2.1: ``h = C + G``),
* the centre of mass,
* for every contact frame, the 6-row support Jacobian ``J`` and the drift
  ``J̇ q̇`` in the world-aligned frame at the contact frame's origin (thesis
  App. A; these are the rows of the support constraint, eq. 5.1),
* for every contact point, the 3-row point Jacobian and its drift, used to
  map contact forces to generalized forces (``J_cᵀ f`` of eq. 4.2),
* the momentum derivative matrices of App. B (:mod:`controller_server.momentum`).

:func:`point_kinematics` gives the same point rows for any frame and offset
(the point-acceleration objective, App. C).

:func:`compute_dynamics_terms` is the executable specification. The controllers compute
the same terms by the compiled core (:class:`CompiledDynamics`, C++ in
``controller_server/core/``: the same Pinocchio calls in the same order, about 3× faster)
when their parameter ``kernel`` is ``"compiled"`` (:data:`KERNELS`; ``"python"`` is the
default for now); the two agree to rounding (``tests/controller_server/test_compiled_core.py``).

Pinocchio's free-flyer convention holds inside the server: ``q = [p, quat_xyzw,
q_joints]``, ``v = [v_base_in_base, ω_base_in_base, v_joints]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
import pinocchio as pin

from controller_server.compiled import load_core
from controller_server.math.spatial import wrench_map
from controller_server.models import RobotModel
from controller_server.momentum import MomentumRates, compute_momentum_rates

__all__ = [
    "KERNELS",
    "CentroidalMotion",
    "CompiledDynamics",
    "ContactGeometry",
    "DynamicsTerms",
    "PointKinematics",
    "centroidal_motion",
    "compute_contact_geometry",
    "compute_dynamics_terms",
    "new_core",
    "point_kinematics",
]

WORLD_ALIGNED = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
KERNELS = ("compiled", "python")
"""How a controller computes its :class:`DynamicsTerms`: :class:`CompiledDynamics` (the
compiled core) or :func:`compute_dynamics_terms` (Python, the specification)."""


@dataclass(frozen=True)
class DynamicsTerms:
    """Dynamics of one robot at one state ``(q, v)``.

    Attributes:
        q: Configuration (Pinocchio convention), ``(nq,)``.
        v: Generalized velocity, ``(nv,)``.
        mass_matrix: Symmetric ``M(q)``, ``(nv, nv)``.
        bias_forces: ``h(q, v)`` = Coriolis, centrifugal and gravity, ``(nv,)``.
        position_com_in_world: Centre of mass (m).
        support_jacobians: Per contact, ``(6, nv)``: ``[v_origin; ω]`` of the
            contact frame in world axes.
        support_drifts: Per contact, ``(6,)``: ``J̇ q̇`` (classical linear and
            angular acceleration at ``q̈ = 0``).
        point_jacobians: Per contact, ``(3k, nv)``: velocity of each point in world axes.
        point_drifts: Per contact, ``(3k,)``: point acceleration at ``q̈ = 0``.
        point_wrench_maps: Per contact, ``(6, 3k)``: point forces (world axes) to
            the contact wrench about the frame origin (see :class:`PointKinematics`).
        position_points_in_world: Per contact, ``(k, 3)`` point positions (m).
        position_contact_frames_in_world: ``(contacts, 3)`` contact frame origins (m).
        momentum: Momentum derivative matrices and momenta (App. B).
        total_mass: ``m_T`` (kg).
    """

    q: np.ndarray
    v: np.ndarray
    mass_matrix: np.ndarray
    bias_forces: np.ndarray
    position_com_in_world: np.ndarray
    support_jacobians: tuple[np.ndarray, ...]
    support_drifts: tuple[np.ndarray, ...]
    point_jacobians: tuple[np.ndarray, ...]
    point_drifts: tuple[np.ndarray, ...]
    point_wrench_maps: tuple[np.ndarray, ...]
    position_points_in_world: tuple[np.ndarray, ...]
    position_contact_frames_in_world: np.ndarray
    momentum: MomentumRates
    total_mass: float


@dataclass(frozen=True)
class PointKinematics:
    """Points fixed to one frame: where they are and how they move.

    Attributes:
        position_in_world: ``(k, 3)`` (m).
        velocity_in_world: ``(k, 3)`` (m/s).
        jacobian: ``(3k, nv)``, ``ṗ = J q̇`` stacked per point.
        drift: ``(3k,)``, ``p̈`` at ``q̈ = 0`` (App. C, eq. C.7 ``q_bias``).
        wrench_map: ``(6, 3k)`` ``W = [I … I; [r₁]× … [r_k]×]`` with ``r`` the
            points' offsets from the frame origin in world axes: forces ``f``
            at the points make the wrench ``W f = [Σ f; Σ r × f]`` about the
            origin, and by duality ``J = Wᵀ J_frame``.
    """

    position_in_world: np.ndarray
    velocity_in_world: np.ndarray
    jacobian: np.ndarray
    drift: np.ndarray
    wrench_map: np.ndarray


def point_kinematics(
    model: pin.Model, data: pin.Data, frame_id: int, points_in_frame: np.ndarray
) -> PointKinematics:
    """Point Jacobians and drifts (Macchietto 2008, App. C, eq. C.5–C.8).

    ``data`` must hold ``computeJointJacobians``, ``forwardKinematics(q, v, 0)``
    and ``updateFramePlacements``.
    """
    return _points_on_frame(
        pin.getFrameJacobian(model, data, frame_id, WORLD_ALIGNED),
        pin.getFrameVelocity(model, data, frame_id, WORLD_ALIGNED),
        pin.getFrameClassicalAcceleration(model, data, frame_id, WORLD_ALIGNED),
        data.oMf[frame_id],
        points_in_frame,
    )


def _points_on_frame(
    jacobian: np.ndarray,
    velocity: pin.Motion,
    drift: pin.Motion,
    placement: pin.SE3,
    points_in_frame: np.ndarray,
) -> PointKinematics:
    """Points fixed to a frame, from the frame's world-aligned Jacobian, twist and drift.

    Per point ``p = o + r``: ``v_p = v_o − [r]× ω`` and, at ``q̈ = 0``,
    ``a_p = a_o − [r]× α + ω × (ω × r)`` (App. C, eq. C.3 and C.7), all ``k``
    points at once through the wrench map ``Wᵀ = [I, −[r]×]`` per point.
    """
    offsets = points_in_frame @ placement.rotation.T  # (k, 3), world axes
    count = len(offsets)
    point_wrench_map = wrench_map(offsets)
    omega = velocity.angular
    # ω × (ω × r) = ω (ω · r) − |ω|² r
    centripetal = np.outer(offsets @ omega, omega) - (omega @ omega) * offsets
    transposed = point_wrench_map.T
    return PointKinematics(
        position_in_world=placement.translation + offsets,
        velocity_in_world=(transposed @ velocity.vector).reshape(count, 3),
        jacobian=transposed @ jacobian,
        drift=transposed @ drift.vector + centripetal.reshape(-1),
        wrench_map=point_wrench_map,
    )


@cache
def _strictly_lower(size: int) -> np.ndarray:
    """``(size, size)`` mask of the entries below the diagonal (read only)."""
    mask = np.tri(size, k=-1, dtype=bool)
    mask.setflags(write=False)
    return mask


def compute_dynamics_terms(
    robot: RobotModel, data: pin.Data, q: np.ndarray, v: np.ndarray
) -> DynamicsTerms:
    """Evaluate every term a controller needs at ``(q, v)``.

    Args:
        robot: The robot model.
        data: This session's Pinocchio data (overwritten).
        q: Configuration, ``(nq,)``.
        v: Generalized velocity, ``(nv,)``.

    Returns:
        The terms, as fresh arrays (safe to keep after ``data`` changes).
    """
    model = robot.model
    pin.computeAllTerms(model, data, q, v)
    # Pinocchio fills the upper triangle of M; mirror it (mask cached per size).
    mass_matrix = np.where(_strictly_lower(model.nv), data.M.T, data.M)
    bias_forces = data.nle.copy()
    position_com = data.com[0].copy()
    total_mass = float(data.mass[0])
    # Also leaves the kinematics of q̈ = 0 in data: the drift terms are classical
    # accelerations with q̈ = 0 (App. A, eq. A.9–A.10).
    momentum = compute_momentum_rates(model, data, q, v)
    pin.updateFramePlacements(model, data)

    support_jacobians, support_drifts = [], []
    point_jacobians, point_drifts, point_positions, wrench_maps = [], [], [], []
    for contact in robot.contacts:
        frame_id = contact.frame_id
        jacobian = pin.getFrameJacobian(model, data, frame_id, WORLD_ALIGNED)
        drift = pin.getFrameClassicalAcceleration(model, data, frame_id, WORLD_ALIGNED)
        support_jacobians.append(jacobian)
        support_drifts.append(drift.vector)
        points = _points_on_frame(
            jacobian,
            pin.getFrameVelocity(model, data, frame_id, WORLD_ALIGNED),
            drift,
            data.oMf[frame_id],
            contact.points_in_frame,
        )
        point_jacobians.append(points.jacobian)
        point_drifts.append(points.drift)
        point_positions.append(points.position_in_world)
        wrench_maps.append(points.wrench_map)

    return DynamicsTerms(
        q=q,
        v=v,
        mass_matrix=mass_matrix,
        bias_forces=bias_forces,
        position_com_in_world=position_com,
        support_jacobians=tuple(support_jacobians),
        support_drifts=tuple(support_drifts),
        point_jacobians=tuple(point_jacobians),
        point_drifts=tuple(point_drifts),
        point_wrench_maps=tuple(wrench_maps),
        position_points_in_world=tuple(point_positions),
        position_contact_frames_in_world=np.array(
            [data.oMf[c.frame_id].translation for c in robot.contacts]
        ).reshape(-1, 3),
        momentum=momentum,
        total_mass=total_mass,
    )


def new_core(robot: RobotModel) -> Any:
    """A ``controller_server._core.Core`` for ``robot``: its model and contacts, a workspace.

    Raises:
        CompiledCoreUnavailable: The core is not built or was built for another Pinocchio.
    """
    return load_core().Core(
        robot.model.saveToString(),
        [contact.frame_id for contact in robot.contacts],
        [np.ascontiguousarray(c.points_in_frame, dtype=float) for c in robot.contacts],
    )


class CompiledDynamics:
    """:func:`compute_dynamics_terms` by the compiled core, for one robot (one per controller).

    The core (``controller_server._core.Core``) holds an exact copy of the robot's Pinocchio
    model (from ``pin.Model.saveToString()``, about 0.6 ms to write and 0.7 ms to read back:
    once per controller) and its own workspace, and runs the same Pinocchio calls in the
    same order as the Python function; only the sole-point rows are summed in another order
    (they agree to rounding, ~1e-16 relative).

    Raises:
        CompiledCoreUnavailable: The core is not built or was built for another Pinocchio.
    """

    def __init__(self, robot: RobotModel):
        self.robot = robot
        self._core = new_core(robot)
        self._zero_acceleration = np.zeros(robot.model.nv)

    def compute(self, data: pin.Data, q: np.ndarray, v: np.ndarray) -> DynamicsTerms:
        """The terms at ``(q, v)``, equal in fields and types to :func:`compute_dynamics_terms`'s.

        Args:
            data: This session's Pinocchio data, left as the Python function leaves its
                kinematics: joint placements, velocities and accelerations of ``(q, v, q̈ =
                0)``, joint Jacobians and frame placements (what tasks and behaviours read,
                :class:`~controller_server.tasks.Tick`; ~2–3 µs). Its dynamics (``M``,
                ``nle``, ``Ag``, …) are not filled: they are in the terms.
            q: Configuration, ``(nq,)``.
            v: Generalized velocity, ``(nv,)``.

        Returns:
            The terms, as fresh arrays (safe to keep).
        """
        terms = self._core.compute(q, v)
        model = self.robot.model
        pin.forwardKinematics(model, data, q, v, self._zero_acceleration)
        pin.computeJointJacobians(model, data)
        pin.updateFramePlacements(model, data)
        return DynamicsTerms(
            q=q,
            v=v,
            mass_matrix=terms["mass_matrix"],
            bias_forces=terms["bias_forces"],
            position_com_in_world=terms["position_com_in_world"],
            support_jacobians=tuple(terms["support_jacobians"]),
            support_drifts=tuple(terms["support_drifts"]),
            point_jacobians=tuple(terms["point_jacobians"]),
            point_drifts=tuple(terms["point_drifts"]),
            point_wrench_maps=tuple(terms["point_wrench_maps"]),
            position_points_in_world=tuple(terms["position_points_in_world"]),
            position_contact_frames_in_world=terms["position_contact_frames_in_world"],
            momentum=MomentumRates(
                R=terms["R"],
                r_bias=terms["r_bias"],
                S=terms["S"],
                s_bias=terms["s_bias"],
                linear_momentum=terms["linear_momentum"],
                angular_momentum=terms["angular_momentum"],
            ),
            total_mass=terms["total_mass"],
        )


@dataclass(frozen=True)
class ContactGeometry:
    """Where the contacts are at ``q``: enough for the 1 kHz inverse-dynamics tick.

    Attributes:
        position_points_in_world: Per contact, ``(k, 3)`` point positions (m).
        position_contact_frames_in_world: ``(contacts, 3)`` contact frame origins (m).
        joint_ids: Per contact, the Pinocchio joint that carries its frame.
    """

    position_points_in_world: tuple[np.ndarray, ...]
    position_contact_frames_in_world: np.ndarray
    joint_ids: tuple[int, ...]


def compute_contact_geometry(robot: RobotModel, data: pin.Data, q: np.ndarray) -> ContactGeometry:
    """Contact points and frame origins by forward kinematics (overwrites ``data``)."""
    model = robot.model
    pin.forwardKinematics(model, data, q)
    points, origins, joints = [], [], []
    for contact in robot.contacts:
        placement = pin.updateFramePlacement(model, data, contact.frame_id)
        origin = placement.translation
        points.append(origin + contact.points_in_frame @ placement.rotation.T)
        origins.append(origin)
        joints.append(model.frames[contact.frame_id].parentJoint)
    return ContactGeometry(tuple(points), np.array(origins).reshape(-1, 3), tuple(joints))


@dataclass(frozen=True)
class CentroidalMotion:
    """Centre of mass, centroidal momentum and its rate for one ``q̈`` (world axes, about the CM).

    Attributes:
        position_com_in_world: ``c`` (m).
        linear_momentum: ``L = m ċ`` (kg·m/s).
        angular_momentum: ``H`` about the CM (kg·m²/s).
        linear_momentum_rate: ``L̇ = R q̈ + r_bias`` (N; App. B).
        angular_momentum_rate: ``Ḣ = S q̈ + s_bias`` (N·m; App. B).
    """

    position_com_in_world: np.ndarray
    linear_momentum: np.ndarray
    angular_momentum: np.ndarray
    linear_momentum_rate: np.ndarray
    angular_momentum_rate: np.ndarray


def centroidal_motion(
    model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray, acceleration: np.ndarray
) -> CentroidalMotion:
    """:class:`CentroidalMotion` by Pinocchio's centroidal momentum time variation."""
    rate = pin.computeCentroidalMomentumTimeVariation(model, data, q, v, acceleration)
    return CentroidalMotion(
        position_com_in_world=data.com[0].copy(),
        linear_momentum=data.hg.linear.copy(),
        angular_momentum=data.hg.angular.copy(),
        linear_momentum_rate=rate.linear.copy(),
        angular_momentum_rate=rate.angular.copy(),
    )
