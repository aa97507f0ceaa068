"""Where ``τ``, ``q̈`` and ``λ`` sit in the prioritized controller's unknowns, and their rows.

de Lasa et al. 2010, eq. 1 and §5: ``x = [τ, q̈, λ]``, the contact force of
every loaded sole point in the basis of its linearized friction cone
(``f = V λ``, eq. 23). :class:`PrioritizedLayout` gives the blocks of ``x``
and the contact maps of one tick; the rows that belong to ``x`` itself are
the equations of motion (eq. 22–24), the smallest forces and the smallest
torques (eq. 15). What does not change between ticks (index arrays, ``Sᵀ``,
the joint-limit table, the friction pyramids) is computed once per robot by
:class:`LayoutIndex`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cache

import numpy as np
from scipy.linalg import lapack

from controller_server.balance_points import support_polygon
from controller_server.dynamics import DynamicsTerms
from controller_server.features import Objective
from controller_server.models import RobotModel

__all__ = [
    "DEFAULT_LIMIT_HORIZON_S",
    "LIMIT_ACCELERATION_ACTIVE",
    "LIMIT_ACCELERATION_CAP",
    "NUM_ROOT_DOFS",
    "LayoutIndex",
    "PrioritizedLayout",
    "friction_cone_basis",
]

NUM_ROOT_DOFS = 6
LIMIT_ACCELERATION_ACTIVE = 100.0
"""A joint-limit row enters once its acceleration bound is below this (rad/s² or m/s²)."""
LIMIT_ACCELERATION_CAP = 1000.0
"""Largest acceleration a joint-limit row demands, back from a limit overshot or
run into fast (rad/s² or m/s²): more would ask the equations of motion the impossible."""
DEFAULT_LIMIT_HORIZON_S = 0.1
"""T of :meth:`LayoutIndex.joint_limit_bounds` when none is given."""


def friction_cone_basis(friction_coefficient: float) -> np.ndarray:
    """``V``: ``(3, 4)`` unit edges of the friction pyramid on a ground of normal +z (eq. 23).

    The edges ``(±μ', ±μ', 1)`` with ``μ' = μ/√2`` span the pyramid inscribed
    in Coulomb's cone, the same pyramid the weighted controller's inverse
    dynamics uses, so ``f = V λ`` with ``λ ≥ 0`` is always transmissible.
    """
    mu = friction_coefficient / math.sqrt(2.0)
    edges = np.array([[mu, mu, 1.0], [mu, -mu, 1.0], [-mu, mu, 1.0], [-mu, -mu, 1.0]]).T
    return edges / np.linalg.norm(edges, axis=0)


class LayoutIndex:
    """What the layout needs of a robot that no state changes, computed once.

    Attributes:
        nv: Generalized velocities.
        nu: Actuated joint DoFs, ``nv − 6``.
        owner: ``(points,)`` contact index of every contact point.
        counts: Points per contact.
        S_T: ``(nv, nu)``: Sᵀ, actuated torques into generalized forces.
        torque_limit: ``(nu,)`` torque limits (N·m; ``inf`` where unbounded).
        lower_torque_limit: ``−torque_limit``.
        bounded_torques: Indices of the finite torque limits.
    """

    def __init__(self, robot: RobotModel):
        model = robot.model
        self.nv = model.nv
        self.nu = self.nv - NUM_ROOT_DOFS
        self.counts = tuple(len(c.points_in_frame) for c in robot.contacts)
        self.owner = np.repeat(np.arange(len(self.counts)), self.counts)
        self.S_T = np.vstack([np.zeros((NUM_ROOT_DOFS, self.nu)), np.eye(self.nu)])
        self.torque_limit = np.asarray(robot.torque_limit, dtype=float)
        self.lower_torque_limit = -self.torque_limit
        self.bounded_torques = np.flatnonzero(np.isfinite(self.torque_limit))
        scalar = [joint for joint in model.joints[2:] if joint.nq == 1]
        self._limit_q = np.array([joint.idx_q for joint in scalar], dtype=int)
        self._limit_v = np.array([joint.idx_v for joint in scalar], dtype=int)
        self._lower = np.asarray(model.lowerPositionLimit)[self._limit_q]
        self._upper = np.asarray(model.upperPositionLimit)[self._limit_q]
        self._points: dict[tuple[bool, ...], np.ndarray] = {}
        self._friction: tuple[tuple[float, ...], tuple[np.ndarray, np.ndarray]] | None = None

    def points_of(self, contacts: tuple[bool, ...]) -> np.ndarray:
        """Indices of the points of the contacts flagged in ``contacts`` (read-only, cached)."""
        points = self._points.get(contacts)
        if points is None:
            points = np.flatnonzero(np.asarray(contacts, dtype=bool)[self.owner])
            points.flags.writeable = False
            self._points = {**self._points, contacts: points} if len(self._points) < 64 else {}
        return points

    def friction_at_points(self, coefficients: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Per point: μ of its contact ``(points,)`` and its friction pyramid ``(points, 3, 4)``.

        Read-only, computed once per value of ``friction_coefficients`` (the last one kept).
        """
        if self._friction is None or self._friction[0] != coefficients:
            mus = np.asarray(coefficients, dtype=float)[self.owner]
            cones = (
                np.stack([friction_cone_basis(float(mu)) for mu in mus])
                if mus.size
                else np.zeros((0, 3, 4))
            )
            mus.flags.writeable = False
            cones.flags.writeable = False
            self._friction = (coefficients, (mus, cones))
        return self._friction[1]

    def joint_limit_bounds(
        self, q: np.ndarray, v: np.ndarray, horizon_s: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The 1-DoF joints whose limit may bind this tick, with ``s q̈_i + f_i ≥ 0`` for each.

        A joint may not reach past its limit within ``horizon_s`` (T) at constant
        acceleration: ``q + q̇ T + ½ q̈ T² ≤ q_max`` (and ``≥ q_min``), i.e. for the upper
        limit ``−q̈ + 2 (q_max − q − q̇ T) / T² ≥ 0``. Held every tick, a joint running into
        its limit follows ``ë + (2/T) ė + (2/T²) e = 0`` (ζ = 1/√2), and one past it is
        pulled back. de Lasa's eq. 27 keeps only a joint *at* its limit from accelerating
        further out, and the velocity it arrives with carries it past (a jump's arms swung
        0.9 rad past the shoulders'). The demand is at most :data:`LIMIT_ACCELERATION_CAP`
        either way; rows whose bound exceeds :data:`LIMIT_ACCELERATION_ACTIVE` are left out.

        Returns:
            Velocity indices (joint order), signs (``+1`` lower limit, ``−1`` upper) and
            offsets ``f`` (rad/s² or m/s²).
        """
        values = q[self._limit_q]
        velocities = v[self._limit_v]
        predicted = values + velocities * horizon_s
        scale = 2.0 / (horizon_s * horizon_s)
        with np.errstate(invalid="ignore"):  # unlimited joints: ±inf bounds
            upper_room = np.minimum(scale * (self._upper - predicted), LIMIT_ACCELERATION_CAP)
            lower_room = np.minimum(scale * (predicted - self._lower), LIMIT_ACCELERATION_CAP)
        upper_room = np.maximum(upper_room, -LIMIT_ACCELERATION_CAP)
        lower_room = np.maximum(lower_room, -LIMIT_ACCELERATION_CAP)
        upper = np.flatnonzero(upper_room < LIMIT_ACCELERATION_ACTIVE)
        lower = np.flatnonzero(lower_room < LIMIT_ACCELERATION_ACTIVE)
        joints = np.concatenate([lower, upper])
        signs = np.concatenate([np.ones(lower.size), -np.ones(upper.size)])
        offsets = np.concatenate([lower_room[lower], upper_room[upper]])
        return self._limit_v[joints], signs, offsets


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
        index: LayoutIndex,
        terms: DynamicsTerms,
        planted: Sequence[bool],
        supports: Sequence[bool],
        friction_coefficients: Sequence[float],
        ground_height: float,
        contact_distance: float,
    ):
        nv = index.nv
        self.index = index
        self.nv, self.nu = nv, index.nu
        positions = np.vstack(terms.position_points_in_world)
        count = len(positions)
        jacobian = np.vstack(terms.point_jacobians).reshape(count, 3, nv)
        drift = np.concatenate(terms.point_drifts).reshape(count, 3)
        mus, cones = index.friction_at_points(tuple(friction_coefficients))

        planted_points = index.points_of(tuple(planted))
        #: Planted points: ``(3s, nv)`` Jacobian, ``(3s,)`` drift, ``(s, 3)`` positions.
        self.point_jacobian = jacobian[planted_points].reshape(-1, nv)
        self.point_drift = drift[planted_points].reshape(-1)
        self.point_positions = positions[planted_points]
        self._contact_row_basis = _sole_row_basis(
            self.point_positions, [index.counts[c] for c, on in enumerate(planted) if on]
        )
        supporting = index.points_of(tuple(supports))
        #: Supporting points' positions ``(k, 3)``: the base of support.
        self.support_positions = positions[supporting]
        #: Their convex hull, counter-clockwise x–y vertices.
        self.support_polygon = support_polygon(self.support_positions)
        self.smallest_friction_coefficient = float(mus[supporting].min(initial=math.inf))
        loaded = planted_points[self.point_positions[:, 2] <= ground_height + contact_distance]
        #: Indices (over all the robot's contact points) of the points carrying force.
        self.force_point_indices = loaded
        self.nl = 4 * loaded.size
        #: ``(p, 3, 4)``: each loaded point's V, the block diagonal of eq. 23.
        self.cones = cones[loaded]
        cones_T = self.cones.transpose(0, 2, 1)
        #: ``(4p, nv)`` and ``(4p,)``: ``Vᵀ J_c`` and ``Vᵀ J̇_c q̇`` of eq. 26, point by point.
        self.cone_jacobian = np.matmul(cones_T, jacobian[loaded]).reshape(self.nl, nv)
        self.cone_drift = np.matmul(cones_T, drift[loaded][:, :, None]).reshape(self.nl)
        #: ``(nv, nλ)``: J_cᵀ V, generalized force of λ (eq. 24).
        self.contact_force_map = self.cone_jacobian.T
        #: ``(nv, nu)``: Sᵀ, actuated torques into generalized forces.
        self.S_T = index.S_T
        self.size = self.nu + nv + self.nl
        #: Blocks of ``x``.
        self.torque = slice(0, self.nu)
        self.acceleration = slice(self.nu, self.nu + nv)
        self.force = slice(self.nu + nv, self.size)

    def point_forces(self, x: np.ndarray) -> np.ndarray:
        """``(p, 3)``: the loaded points' forces ``f = V λ`` (eq. 23) from ``x``."""
        lambdas = x[self.force].reshape(-1, 4, 1)
        return np.matmul(self.cones, lambdas).reshape(-1, 3)

    def equations_of_motion(self, terms: DynamicsTerms) -> Objective:
        """``‖Sᵀ τ − M q̈ + J_cᵀ V λ − h‖²`` (eq. 22–24), every row weighted 1."""
        A = np.empty((self.nv, self.size))
        A[:, self.torque] = self.S_T
        np.negative(terms.mass_matrix, out=A[:, self.acceleration])
        A[:, self.force] = self.contact_force_map
        return Objective("dynamics", A, terms.bias_forces, np.ones(self.nv))

    def contact_row_basis(self) -> np.ndarray | None:
        """``(3s, 6c)`` orthonormal columns holding those of the planted points' Jacobian.

        The points of one sole move with it: the rows of point ``i`` are
        ``[I, −[rᵢ]×] J_frame`` (``rᵢ`` its offset from the frame origin, App. C), so the
        ``contact`` rows of ``c`` planted soles span at most ``6c`` dimensions. Per sole the
        columns of the stacked ``[I, −[rᵢ]×]`` span what ``[1, −[dᵢ]×] / …`` spans, ``dᵢ``
        the points' offsets from their centroid, whose two halves are orthogonal: ``1/√k``
        per point, and ``−[dᵢ]×`` made orthonormal through the Cholesky factor of its Gram
        ``Σ |dᵢ|² I − dᵢ dᵢᵀ`` (the points' second moment, well conditioned for a sole).
        ``None`` when a sole's points are fewer than three or on a line, or their counts
        differ (then the solver takes all the rows).
        """
        return self._contact_row_basis

    def motionless_forces(self) -> np.ndarray:
        """``(size, f)`` orthonormal basis of ``{x = (τ, 0, λ) : Sᵀ τ + J_cᵀ V λ = 0}``.

        Contact forces balanced by torques alone, with no acceleration: the internal
        forces between the feet and the torques that hold them. They are in the null space
        of the equations of motion (eq. 24) and every objective on ``q̈`` is exactly zero on
        them (their ``q̈`` rows are exact zeros), so the solver keeps them apart
        (:attr:`~controller_server.solvers.prioritized.Level.null_space_part`) for the
        levels that see ``λ`` or ``τ``. ``λ`` spans the null space of the root rows of
        ``J_cᵀ V`` (directions with a singular value above the rounding floor are left
        out: they are not exactly motionless), ``τ = −(J_cᵀ V)_joints λ``.
        """
        nl = self.nl
        root = self.contact_force_map[:NUM_ROOT_DOFS]
        if nl <= NUM_ROOT_DOFS:
            return np.zeros((self.size, 0))
        # null(root) from the Householder QR of rootᵀ, when its R shows full rank (≥ 3 loaded
        # points not on a line); otherwise no part is kept apart (a few points: small levels).
        factors, tau, _, _ = lapack.dgeqrf(root.T)
        diagonal = np.abs(factors.diagonal())
        if not diagonal.min() > diagonal.max() * nl * 8 * np.finfo(float).eps:
            return np.zeros((self.size, 0))
        selector = np.zeros((nl, nl - NUM_ROOT_DOFS), order="F")
        selector[NUM_ROOT_DOFS:] = np.eye(nl - NUM_ROOT_DOFS)
        balanced, _, _ = lapack.dormqr("L", "N", factors, tau, selector, lwork=64 * nl)
        # (τ, λ) = (−J_jointsᵀ... λ, λ): orthonormal by one Cholesky (Gram I + KᵀK, K ~ lever
        # arms, so well conditioned: orthogonal to rounding).
        torques = self.contact_force_map[NUM_ROOT_DOFS:] @ balanced
        gram = torques.T @ torques
        gram.flat[:: gram.shape[0] + 1] += 1.0
        upper, info = lapack.dpotrf(gram)  # gram = Rᵀ R
        if info:
            return np.zeros((self.size, 0))
        inverse, info = lapack.dtrtri(upper)
        if info:
            return np.zeros((self.size, 0))
        basis = np.zeros((self.size, balanced.shape[1]))
        np.matmul(torques, inverse, out=basis[self.torque])
        np.negative(basis[self.torque], out=basis[self.torque])
        np.matmul(balanced, inverse, out=basis[self.force])
        return basis

    def least_forces(self) -> Objective:
        """``‖λ‖²`` over the ``λ`` block: the smallest of the forces the levels above leave free.

        Below everything: the internal forces between two feet, which the
        levels above do not fix, as the weighted controller's distribution.
        """
        return Objective("forces", np.eye(self.nl), np.zeros(self.nl), np.ones(self.nl))

    def least_torque(self, selection: np.ndarray, weight: float) -> Objective:
        """``Σ sᵢ τᵢ²`` on the joints of ``selection`` (eq. 15), weight α, over the ``τ`` block."""
        return Objective(
            "torque",
            np.diag(np.sqrt(selection)),
            np.zeros(selection.size),
            np.full(selection.size, weight) * (selection > 0),
        )

    def inequalities(
        self,
        q: np.ndarray,
        v: np.ndarray,
        non_penetration: bool,
        limit_horizon_s: float = DEFAULT_LIMIT_HORIZON_S,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rows of ``D x + f ≥ 0``: λ ≥ 0, non-penetration, torque and joint limits.

        In this order: ``λ ≥ 0`` (eq. 25); ``Vᵀ (J_c q̈ + J̇_c q̇) ≥ 0`` (eq. 26);
        ``−τ_max ≤ τ ≤ τ_max`` (§7.2) on the bounded joints, lower then upper; the 1-DoF
        joints that would pass a limit within ``limit_horizon_s`` (eq. 27, made
        velocity-aware: :meth:`LayoutIndex.joint_limit_bounds`).
        """
        index, nu, nl = self.index, self.nu, self.nl
        bounded = index.bounded_torques
        limit_v, limit_sign, limit_offset = index.joint_limit_bounds(q, v, limit_horizon_s)
        penetration = nl if nl and non_penetration else 0
        rows = nl + penetration + 2 * bounded.size + limit_v.size
        D = np.zeros((rows, self.size))
        f = np.zeros(rows)
        if nl:
            D[np.arange(nl), self.force.start + np.arange(nl)] = 1.0
        if penetration:
            D[nl : 2 * nl, self.acceleration] = self.cone_jacobian
            f[nl : 2 * nl] = self.cone_drift
        start = nl + penetration
        if bounded.size:
            count = bounded.size
            D[start + np.arange(count), bounded] = -1.0
            D[start + count + np.arange(count), bounded] = 1.0
            f[start : start + count] = index.torque_limit[bounded]
            f[start + count : start + 2 * count] = index.torque_limit[bounded]
            start += 2 * count
        D[start + np.arange(limit_v.size), nu + limit_v] = limit_sign
        f[start:] = limit_offset
        return D, f


@cache
def _stacked_identity(points: int) -> np.ndarray:
    """``[I; …; I] / √k``: orthonormal translations of ``k`` points (read-only)."""
    stacked = np.tile(np.eye(3), (points, 1)) / math.sqrt(points)
    stacked.flags.writeable = False
    return stacked


_CROSS_INDEX = np.array([[0, 2, 1], [2, 0, 0], [1, 0, 0]])
_CROSS_SIGN = np.array([[0.0, 1.0, -1.0], [-1.0, 0.0, 1.0], [1.0, -1.0, 0.0]])
"""``−[d]× = d[_CROSS_INDEX] * _CROSS_SIGN``."""


def _sole_row_basis(positions: np.ndarray, counts: list[int]) -> np.ndarray | None:
    """:meth:`PrioritizedLayout.contact_row_basis` of soles with ``counts`` points each."""
    if not counts or min(counts) < 3 or max(counts) != min(counts):
        return None
    soles, points = len(counts), counts[0]
    offsets = positions.reshape(soles, points, 3)
    offsets = offsets - offsets.mean(axis=1, keepdims=True)
    moments = (offsets.transpose(0, 2, 1) @ offsets).tolist()
    # Per sole, L⁻ᵀ of gram = Σ |d|² I − d dᵀ = L Lᵀ (3 × 3, by hand).
    inverse_transposes = []
    for (a, b, c), (_, e, f), (_, _, i) in moments:
        trace = a + e + i
        g00, g01, g02, g11, g12, g22 = trace - a, -b, -c, trace - e, -f, trace - i
        if not g00 > 0.0:
            return None
        l00 = math.sqrt(g00)
        l10, l20 = g01 / l00, g02 / l00
        d11 = g11 - l10 * l10
        if not d11 > 1e-12 * trace:
            return None
        l11 = math.sqrt(d11)
        l21 = (g12 - l20 * l10) / l11
        d22 = g22 - l20 * l20 - l21 * l21
        if not d22 > 1e-12 * trace:  # points on a line: fewer than 6 directions
            return None
        l22 = math.sqrt(d22)
        # L⁻¹ (lower), then its transpose.
        m00, m11, m22 = 1.0 / l00, 1.0 / l11, 1.0 / l22
        m10 = -l10 * m00 * m11
        m21 = -l21 * m11 * m22
        m20 = -(l20 * m00 + l21 * m10) * m22
        inverse_transposes.append([[m00, m10, m20], [0.0, m11, m21], [0.0, 0.0, m22]])
    cross = offsets[..., _CROSS_INDEX] * _CROSS_SIGN  # (soles, points, 3, 3): −[d]×
    rotations = (cross @ np.array(inverse_transposes)[:, None]).reshape(soles, 3 * points, 3)
    rows = 3 * points
    basis = np.zeros((rows * soles, 6 * soles))
    translations = _stacked_identity(points)
    for sole in range(soles):
        block = basis[rows * sole : rows * (sole + 1)]
        block[:, 6 * sole : 6 * sole + 3] = translations
        block[:, 6 * sole + 3 : 6 * sole + 6] = rotations[sole]
    return basis
