"""Where ``τ``, ``q̈`` and ``λ`` sit in the prioritized controller's unknowns, and their rows.

de Lasa et al. 2010, eq. 1 and §5: ``x = [τ, q̈, λ]``, the contact force of
every loaded sole point in the basis of its linearized friction cone
(``f = V λ``, eq. 23). :class:`PrioritizedLayout` writes a feature's rows on
``q̈`` over ``x`` and adds the rows that belong to ``x`` itself: the equations
of motion (eq. 22–24), the smallest forces and the smallest torques (eq. 15).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from controller_server.balance_points import support_polygon
from controller_server.dynamics import DynamicsTerms
from controller_server.features import Objective
from controller_server.models import RobotModel

__all__ = ["NUM_ROOT_DOFS", "PrioritizedLayout", "friction_cone_basis", "joint_limit_rows"]

NUM_ROOT_DOFS = 6


def friction_cone_basis(friction_coefficient: float) -> np.ndarray:
    """``V``: ``(3, 4)`` unit edges of the friction pyramid on a ground of normal +z (eq. 23).

    The edges ``(±μ', ±μ', 1)`` with ``μ' = μ/√2`` span the pyramid inscribed
    in Coulomb's cone, the same pyramid the weighted controller's inverse
    dynamics uses, so ``f = V λ`` with ``λ ≥ 0`` is always transmissible.
    """
    mu = friction_coefficient / math.sqrt(2.0)
    edges = np.array([[mu, mu, 1.0], [mu, -mu, 1.0], [-mu, mu, 1.0], [-mu, -mu, 1.0]]).T
    return edges / np.linalg.norm(edges, axis=0)


class PrioritizedLayout:
    """Where ``τ``, ``q̈`` and ``λ`` sit in ``x`` this tick, and the contact maps.

    Three sets of sole points:

    * *planted*: every point of every contact the ``support_mask`` allows,
      servoed to the ground by ``contact`` (Table 1: "keep feet planted"), so a
      foot a push has lifted is brought back down;
    * *supporting*: the points of the contacts the client reports as supports,
      whose centroid and hull are the base of support of ``com``;
    * *loaded*: planted points within ``contact_distance`` of the ground, the
      only ones carrying a force (a ``λ`` block) and a non-penetration row, as
      de Lasa §4 enforces contact "for all contact points close to the
      ground". A lifted heel is pulled down, not held by a force it cannot
      have; a foot set back down carries weight at once, whatever the
      client's flags (a client that flags only loaded feet would otherwise
      never see it loaded).
    """

    def __init__(
        self,
        robot: RobotModel,
        terms: DynamicsTerms,
        planted: Sequence[bool],
        supports: Sequence[bool],
        friction_coefficients: np.ndarray,
        ground_height: float,
        contact_distance: float,
    ):
        nv = robot.model.nv
        self.nv, self.nu = nv, nv - NUM_ROOT_DOFS
        owner = np.repeat(
            np.arange(len(robot.contacts)), [len(c.points_in_frame) for c in robot.contacts]
        )
        positions = np.vstack(terms.position_points_in_world)
        jacobian = np.vstack(terms.point_jacobians)
        drift = np.concatenate(terms.point_drifts)
        mus = np.asarray(friction_coefficients, dtype=float)[owner]

        def rows(points: np.ndarray) -> np.ndarray:
            return (3 * points[:, None] + np.arange(3)).reshape(-1)

        planted_points = np.flatnonzero(np.asarray(planted)[owner])
        #: Planted points: ``(3s, nv)`` Jacobian, ``(3s,)`` drift, ``(s, 3)`` positions.
        self.point_jacobian = jacobian[rows(planted_points)]
        self.point_drift = drift[rows(planted_points)]
        self.point_positions = positions[planted_points]
        supporting = np.flatnonzero(np.asarray(supports)[owner])
        #: Supporting points' positions ``(k, 3)``: the base of support.
        self.support_positions = positions[supporting]
        #: Their convex hull, counter-clockwise x–y vertices.
        self.support_polygon = support_polygon(self.support_positions)
        self.smallest_friction_coefficient = float(mus[supporting].min(initial=math.inf))
        near = positions[planted_points, 2] <= ground_height + contact_distance
        loaded = planted_points[near]
        #: Indices (over all the robot's contact points) of the points carrying force.
        self.force_point_indices = loaded
        force_jacobian = jacobian[rows(loaded)]
        self.nl = 4 * loaded.size
        #: ``(3p, 4p)`` block-diagonal V: point forces from λ (eq. 23).
        self.cone = np.zeros((3 * loaded.size, self.nl))
        for i, point in enumerate(loaded):
            self.cone[3 * i : 3 * i + 3, 4 * i : 4 * i + 4] = friction_cone_basis(mus[point])
        #: ``(4p, nv)`` and ``(4p,)``: ``Vᵀ J_c`` and ``Vᵀ J̇_c q̇`` of eq. 26.
        self.cone_jacobian = self.cone.T @ force_jacobian
        self.cone_drift = self.cone.T @ drift[rows(loaded)]
        #: ``(nv, nλ)``: J_cᵀ V, generalized force of λ (eq. 24).
        self.contact_force_map = force_jacobian.T @ self.cone
        #: ``(nv, nu)``: Sᵀ, actuated torques into generalized forces.
        self.S_T = np.vstack([np.zeros((NUM_ROOT_DOFS, self.nu)), np.eye(self.nu)])
        self.size = self.nu + nv + self.nl
        #: ``(nλ, size)``: the rows picking λ out of x.
        self.force_selection = np.hstack([np.zeros((self.nl, self.nu + nv)), np.eye(self.nl)])

    def over_acceleration(self, objective: Objective) -> Objective:
        """An objective on ``q̈`` (a feature's rows) written over ``x = [τ, q̈, λ]``."""
        full = np.zeros((objective.A.shape[0], self.size))
        full[:, self.nu : self.nu + self.nv] = objective.A
        return Objective(objective.name, full, objective.b, objective.weight)

    def equations_of_motion(self, terms: DynamicsTerms) -> Objective:
        """``‖Sᵀ τ − M q̈ + J_cᵀ V λ − h‖²`` (eq. 22–24), every row weighted 1."""
        return Objective(
            "dynamics",
            np.hstack([self.S_T, -terms.mass_matrix, self.contact_force_map]),
            terms.bias_forces,
            np.ones(self.nv),
        )

    def least_forces(self) -> Objective:
        """``‖λ‖²``: the contact forces the levels above leave free are the smallest.

        Below everything: the internal forces between two feet, which the
        levels above do not fix, as the weighted controller's distribution.
        """
        return Objective("forces", self.force_selection, np.zeros(self.nl), np.ones(self.nl))

    def least_torque(self, selection: np.ndarray, weight: float) -> Objective:
        """``Σ sᵢ τᵢ²`` on the joints of ``selection`` (eq. 15), weight α."""
        rows = np.hstack(
            [np.diag(np.sqrt(selection)), np.zeros((selection.size, self.size - selection.size))]
        )
        return Objective(
            "torque",
            rows,
            np.zeros(selection.size),
            np.full(selection.size, weight) * (selection > 0),
        )


def joint_limit_rows(
    robot: RobotModel, q: np.ndarray, size: int, nu: int
) -> tuple[np.ndarray, np.ndarray]:
    """``±q̈_i ≥ 0`` for 1-DoF joints at or past a limit (de Lasa eq. 27).

    The paper adds a limit "contact" force ``λ_lim`` per such joint; our
    simulators model no joint stop that would supply it, so only its
    non-penetration half is kept: a joint at its lower limit may not
    accelerate further down, at its upper limit not further up. Ball joints
    have no scalar range and are left to the rest pose.
    """
    model = robot.model
    rows, offsets = [], []
    for joint in model.joints[2:]:
        if joint.nq != 1:
            continue
        value = q[joint.idx_q]
        lower, upper = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
        sign = 1.0 if value <= lower else -1.0 if value >= upper else 0.0
        if sign:
            row = np.zeros(size)
            row[nu + joint.idx_v] = sign
            rows.append(row)
            offsets.append(0.0)
    if not rows:
        return np.zeros((0, size)), np.zeros(0)
    return np.array(rows), np.array(offsets)
