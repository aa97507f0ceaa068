"""Floating-base inverse dynamics with contact forces in friction cones.

Macchietto 2008, eq. 4.2, written with actuated torques ``τ`` (``S = [0 I]``)::

    M q̈ + h = Sᵀ τ + J_cᵀ f

Two ground-force modes. *Measured*: the client sends the ground wrench of
every contact (the thesis' penalty forces, or force sensors) and ``τ``
compensates it, as in the thesis. *Distributed*: the six root rows have no
actuator, so the contact forces ``f`` of the supporting feet must balance
them, within linearized (pyramid) friction cones on a flat ground of normal
+z (``f_z ≥ 0``, ``|f_x|, |f_y| ≤ μ f_z / √2`` at every support point: the
pyramid inscribed in Coulomb's cone).

The common case is exact and needs no solver: the smallest forces that
balance the root, ``f = Gᵀ (G Gᵀ)⁻¹ w``, lie in the cones and the torques
within their limits. Otherwise the requested ``q̈`` cannot happen (centre of
pressure pushed off the feet, too much traction, saturated joints), and one
QP finds the nearest motion that can, with its forces and torques
(:func:`nearest_feasible_motion`). Either way the returned acceleration is
the one ``τ`` and ``f`` really produce, ``q̈ = M⁻¹ (Sᵀ τ + J_cᵀ f − h)``, so
the command is always dynamically consistent.

Between optimizer runs (the thesis' 1 kHz inverse-dynamics loop, ch. 4.3)
:func:`exact_inverse_dynamics` computes the common case with two calls of
Pinocchio's RNEA and no mass matrix, and defers to
:func:`solve_inverse_dynamics` otherwise.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache, lru_cache

import numpy as np
import pinocchio as pin
import qpsolvers
from scipy.linalg import lapack

from controller_server.dynamics import ContactGeometry, DynamicsTerms
from controller_server.math.spatial import wrench_map
from controller_server.models import RobotModel
from controller_server.solvers.qp import solve_qp_bounded

__all__ = [
    "InverseDynamicsResult",
    "exact_inverse_dynamics",
    "friction_pyramid",
    "minimum_norm_balance",
    "nearest_feasible_motion",
    "solve_inverse_dynamics",
    "wrenches_from_point_forces",
]

NUM_ROOT_DOFS = 6
QP_SETTINGS: dict[str, dict[str, float]] = {
    "proxqp": {"max_iter": 300, "max_iter_in": 10, "eps_primal_inf": 0.0, "eps_dual_inf": 0.0}
}
"""Tighter caps than :data:`~controller_server.solvers.qp.QP_ITERATION_LIMITS` for
these small QPs: ProxQP's converged solves took at most 35 outer iterations near standing and
61 with velocities of 1e3 (seeded states of the built-in models), while a capped failure
cost up to 0.2 s at the default caps. And no infeasibility verdicts: every QP here is feasible
(``f = 0`` is in the cones; any forces with clipped torques realize a motion) and strictly
convex (``ε ‖f‖²``), hence bounded, yet ProxQP's tests (thresholds 1e-4) called some feasible
force QPs infeasible within four iterations — on about 1 % of seeded QP states, differently in
two builds of the same solver. The controllers' default, quadprog (Goldfarb–Idnani's dual
active-set method, as the compiled core's eiquadprog), has no settings and needs no caps."""
QP_DATA_SCALE = 1e6
"""QPs whose linear data (``q``, ``h``, ``b``) exceed this magnitude are solved scaled down to it
(:func:`_solve_qp`). Near standing they stay below 2e4 (seeded states of the built-in models);
joint velocities of 1e3 rad/s give ~7e10, where absolute solver tolerances are below rounding
and ProxQP ran into its iteration caps (0.4 s) instead of converging in 3 ms."""


@dataclass(frozen=True)
class InverseDynamicsResult:
    """Torques, contact forces and the acceleration they produce.

    Attributes:
        joint_torque: ``(nv − 6,)`` actuated torques within limits (N·m, N).
        contact_force_in_world: ``(p, 3)`` force at every contact point, zero
            at points of contacts that are not supports and in measured mode (N).
        contact_wrench_in_world: ``(contacts, 6)`` force and torque about each
            contact frame origin, world axes (N, N·m).
        acceleration: ``(nv,)`` generalized acceleration consistent with both.
        root_wrench_residual: ``‖(M q̈ + h − J_cᵀ f)_root‖`` before correction.
        saturated_joints: Number of DoFs whose torque was clipped.
    """

    joint_torque: np.ndarray
    contact_force_in_world: np.ndarray
    contact_wrench_in_world: np.ndarray
    acceleration: np.ndarray
    root_wrench_residual: float
    saturated_joints: int


def friction_pyramid(friction_coefficients: Sequence[float]) -> np.ndarray:
    """Rows ``G`` of ``G f ≤ 0`` for point forces ``f = [f_x, f_y, f_z]`` per point.

    Five rows per point: ``±f_x − μ' f_z ≤ 0``, ``±f_y − μ' f_z ≤ 0``, ``−f_z ≤ 0``
    with ``μ' = μ/√2``: the pyramid inscribed in Coulomb's circular cone
    ``‖f_t‖ ≤ μ f_z``, so every force it admits can really be transmitted
    (the circumscribed one, ``μ' = μ``, admits diagonal forces 41 % beyond
    the cone: on ice, μ = 0.03, that is enough to slide the stance foot).
    Built once per set of coefficients (the supports change rarely); the
    caller gets a copy, since some solvers want writeable inputs.
    """
    return _friction_pyramid(tuple(float(mu) for mu in friction_coefficients)).copy()


@lru_cache(maxsize=256)  # bounded: a client may send new coefficients every tick
def _friction_pyramid(friction_coefficients: tuple[float, ...]) -> np.ndarray:
    count = len(friction_coefficients)
    rows = np.zeros((5 * count, 3 * count))
    for i, mu_circular in enumerate(friction_coefficients):
        mu = mu_circular / math.sqrt(2.0)
        block = np.array(
            [[1, 0, -mu], [-1, 0, -mu], [0, 1, -mu], [0, -1, -mu], [0, 0, -1]], dtype=float
        )
        rows[5 * i : 5 * i + 5, 3 * i : 3 * i + 3] = block
    return rows


def solve_inverse_dynamics(
    terms: DynamicsTerms,
    acceleration: np.ndarray,
    supports: Sequence[bool],
    friction_coefficients: Sequence[float],
    torque_limit: np.ndarray,
    *,
    measured_wrenches: np.ndarray | None = None,
    force_regularization: float = 1e-4,
    support_weight: float = 100.0,
    qp_solver: str = "quadprog",
) -> InverseDynamicsResult:
    """Torques and contact forces realizing ``acceleration`` (eq. 4.2), or the nearest they can.

    Args:
        terms: Dynamics at the current state.
        acceleration: Desired ``q̈`` from the optimizer, ``(nv,)``.
        supports: One flag per contact; only supports carry distributed force.
        friction_coefficients: μ per contact.
        torque_limit: ``(nv − 6,)`` symmetric limits.
        measured_wrenches: ``(contacts, 6)`` measured ground wrenches (measured
            mode), or ``None`` to distribute forces.
        force_regularization: ``ε`` on ``‖f‖²`` when ``q̈`` cannot be realized.
        support_weight: ``w_s`` per kg of robot mass on the supports' acceleration
            when ``q̈`` cannot be realized (see :func:`nearest_feasible_motion`).
        qp_solver: Any solver name ``qpsolvers`` knows; ``"quadprog"`` (Goldfarb–Idnani's
            dual active-set method: feasible to rounding) is what the compiled core runs.
    """
    M, h = terms.mass_matrix, terms.bias_forces
    counts = [J.shape[0] // 3 for J in terms.point_jacobians]
    forces = np.zeros((sum(counts), 3))
    if measured_wrenches is not None:
        wrenches = np.asarray(measured_wrenches, dtype=float).reshape(-1, 6)
        contact_generalized_force = sum(
            (J.T @ w for J, w in zip(terms.support_jacobians, wrenches, strict=True)),
            np.zeros_like(h),
        )
        return _realize(
            terms, acceleration, contact_generalized_force, forces, wrenches, torque_limit
        )

    point_jacobian, mus = _support_points(terms, supports, friction_coefficients, counts)
    mask = np.repeat(np.asarray(supports, dtype=bool), counts)
    generalized_force = M @ acceleration + h
    solution = None
    if point_jacobian.shape[0]:
        solution = minimum_norm_balance(
            point_jacobian[:, :NUM_ROOT_DOFS].T, generalized_force[:NUM_ROOT_DOFS], mus
        )
    if solution is not None or not any(supports):
        point_force = np.zeros(point_jacobian.shape[0]) if solution is None else solution
        contact_generalized_force = point_jacobian.T @ point_force
        torque = (generalized_force - contact_generalized_force)[NUM_ROOT_DOFS:]
        exact = solution is not None or np.allclose(generalized_force[:NUM_ROOT_DOFS], 0.0)
        if exact and np.all(np.abs(torque) <= torque_limit):
            forces[mask] = point_force.reshape(-1, 3)
            wrenches = wrenches_from_point_forces(terms, forces, counts)
            return InverseDynamicsResult(torque, forces, wrenches, acceleration.copy(), 0.0, 0)
    nearest = nearest_feasible_motion(
        terms,
        acceleration,
        point_jacobian,
        [J for J, on in zip(terms.support_jacobians, supports, strict=True) if on],
        [d for d, on in zip(terms.support_drifts, supports, strict=True) if on],
        mus,
        torque_limit,
        force_regularization,
        support_weight * terms.total_mass,
        qp_solver,
    )
    if nearest is None:
        # No solver answer: least-squares forces, clipped torques (still consistent below).
        point_force = _least_squares_balance(
            point_jacobian[:, :NUM_ROOT_DOFS].T,
            generalized_force[:NUM_ROOT_DOFS],
            mus,
            force_regularization,
            qp_solver,
        )
        target = acceleration
    else:
        target, point_force = nearest
    forces[mask] = point_force.reshape(-1, 3)
    wrenches = wrenches_from_point_forces(terms, forces, counts)
    return _realize(terms, target, point_jacobian.T @ point_force, forces, wrenches, torque_limit)


def _realize(
    terms: DynamicsTerms,
    acceleration: np.ndarray,
    contact_generalized_force: np.ndarray,
    forces: np.ndarray,
    wrenches: np.ndarray,
    torque_limit: np.ndarray,
) -> InverseDynamicsResult:
    """Clip ``τ`` for ``acceleration`` and return the ``q̈ = M⁻¹ (Sᵀτ + J_cᵀf − h)`` it makes."""
    M, h = terms.mass_matrix, terms.bias_forces
    generalized_force = M @ acceleration + h
    residual = float(
        np.linalg.norm((generalized_force - contact_generalized_force)[:NUM_ROOT_DOFS])
    )
    torque_unclipped = (generalized_force - contact_generalized_force)[NUM_ROOT_DOFS:]
    joint_torque = np.clip(torque_unclipped, -torque_limit, torque_limit)
    # Solver tolerances (~1e-9 relative) are not saturation.
    saturated = int(np.count_nonzero(np.abs(joint_torque - torque_unclipped) > 1e-6))
    applied = contact_generalized_force - h
    applied[NUM_ROOT_DOFS:] += joint_torque
    lower, info = lapack.dpotrf(M, lower=1, clean=0)
    if info != 0:
        raise np.linalg.LinAlgError(f"the mass matrix is not positive definite (potrf info {info})")
    realized, _ = lapack.dpotrs(lower, applied, lower=1)
    return InverseDynamicsResult(joint_torque, forces, wrenches, realized, residual, saturated)


def _support_points(
    terms: DynamicsTerms,
    supports: Sequence[bool],
    friction_coefficients: Sequence[float],
    counts: Sequence[int],
) -> tuple[np.ndarray, list[float]]:
    """``(3p, nv)`` point Jacobians of the supporting contacts, and μ per point."""
    nv = terms.bias_forces.size
    rows = [J for J, on in zip(terms.point_jacobians, supports, strict=True) if on]
    mus = [
        mu
        for mu, count, on in zip(friction_coefficients, counts, supports, strict=True)
        if on
        for _ in range(count)
    ]
    return (np.vstack(rows) if rows else np.zeros((0, nv))), mus


def minimum_norm_balance(
    G: np.ndarray, wrench: np.ndarray, friction_coefficients: Sequence[float]
) -> np.ndarray | None:
    """``f = Gᵀ (G Gᵀ)⁻¹ w`` if it lies in the friction cones, else ``None``.

    The smallest point forces that balance the root wrench exactly; when they
    are admissible they also solve ``min ‖f‖² s.t. G f = w, f in cones`` (the
    common case when standing), with no solver call.
    """
    _, multipliers, info = lapack.dposv(G @ G.T, wrench)  # Cholesky solve
    if info != 0:  # G G^T not positive definite: the points cannot balance every wrench
        return None
    forces = G.T @ multipliers
    cones = _friction_pyramid(tuple(friction_coefficients))  # read only: no copy
    if (cones @ forces <= 1e-9 * max(1.0, abs(wrench[2]))).all():
        return forces
    return None


def _least_squares_balance(
    G: np.ndarray,
    wrench: np.ndarray,
    friction_coefficients: Sequence[float],
    regularization: float,
    qp_solver: str,
) -> np.ndarray:
    """``min ‖G f − w‖² + ε ‖f‖²`` over the cones (zeros if the solver fails)."""
    n = G.shape[1]
    if n == 0:
        return np.zeros(0)
    cones = friction_pyramid(friction_coefficients)
    forces = _solve_qp(
        G.T @ G + regularization * np.eye(n),
        -G.T @ wrench,
        cones,
        np.zeros(cones.shape[0]),
        qp_solver=qp_solver,
    )
    return forces if forces is not None else np.zeros(n)


def nearest_feasible_motion(
    terms: DynamicsTerms,
    acceleration: np.ndarray,
    point_jacobian: np.ndarray,
    support_jacobians: Sequence[np.ndarray],
    support_drifts: Sequence[np.ndarray],
    friction_coefficients: Sequence[float],
    torque_limit: np.ndarray,
    force_regularization: float,
    support_weight: float,
    qp_solver: str,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The realizable ``(q̈, f)`` closest to the request, by one QP (Gauss's principle).

    When no forces in the cones balance the root for the requested ``q̈``
    (centre of pressure pushed off the feet, too much traction) or the torques
    would exceed their limits, the optimizer's ``q̈`` cannot happen. Rather
    than clip and let the body go where it will, choose the nearest motion
    that can, in the kinetic-energy metric::

        min  ½ ‖q̈ − q̈_des‖²_M + ½ w_s ‖J_sup q̈ + J̇_sup q̇‖² + ½ ε ‖f‖²
        s.t. (M q̈ + h)_root = (J_cᵀ f)_root          (the root is unactuated)
             f in the friction pyramids
             −τ_max ≤ (M q̈ + h − J_cᵀ f)_joints ≤ τ_max

    The support term keeps the feet planted (``q̈_des`` already satisfies it,
    eq. 5.1) without making the problem infeasible: for any ``f`` in the
    cones, forward dynamics with clipped torques is a feasible point. This is
    the unknowns-``[q̈, f]`` formulation of de Lasa et al. 2010 (§ 4) used as a
    projection, not as the controller.

    Without the torque rows, ``q̈`` can be eliminated exactly (see
    :func:`_condensed_motion`), leaving a QP in the forces alone, half the
    unknowns and a third of the rows. Its answer solves the full problem
    whenever its torques are within their limits (the usual case: a relaxation
    whose optimum is feasible is optimal); otherwise the full QP is solved.

    Returns:
        ``(q̈, f)`` or ``None`` if the solver gives no finite answer.
    """
    M, h = terms.mass_matrix, terms.bias_forces
    nv, forces = h.size, point_jacobian.shape[0]
    J_sup = np.vstack(support_jacobians) if support_jacobians else np.zeros((0, nv))
    drift = np.concatenate(support_drifts) if support_drifts else np.zeros(0)
    cones = friction_pyramid(friction_coefficients)
    condensed = _condensed_motion(
        M, h, acceleration, point_jacobian, J_sup, drift, cones, force_regularization,
        support_weight, qp_solver,
    )  # fmt: skip
    if condensed is not None:
        motion, point_force = condensed
        torque = (M @ motion + h - point_jacobian.T @ point_force)[NUM_ROOT_DOFS:]
        if (np.abs(torque) <= torque_limit).all():
            return motion, point_force
    hessian = np.zeros((nv + forces, nv + forces))
    hessian[:nv, :nv] = M + support_weight * J_sup.T @ J_sup
    gradient = np.zeros(nv + forces)
    gradient[:nv] = support_weight * J_sup.T @ drift - M @ acceleration
    hessian[nv:, nv:] = force_regularization * np.eye(forces)
    # (M q̈ + h − J_cᵀ f) = [root wrench; τ]; the root rows are the equality.
    dynamics = np.hstack([M, -point_jacobian.T])
    inequality = np.vstack(
        [
            np.hstack([np.zeros((cones.shape[0], nv)), cones]),
            dynamics[NUM_ROOT_DOFS:],
            -dynamics[NUM_ROOT_DOFS:],
        ]
    )
    joint_bias = h[NUM_ROOT_DOFS:]
    bound = np.concatenate(
        [np.zeros(cones.shape[0]), torque_limit - joint_bias, torque_limit + joint_bias]
    )
    solution = _solve_qp(
        hessian,
        gradient,
        inequality,
        bound,
        A=dynamics[:NUM_ROOT_DOFS],
        b=-h[:NUM_ROOT_DOFS],
        qp_solver=qp_solver,
    )
    if solution is None:
        return None
    return solution[:nv], solution[nv:]


def _condensed_motion(
    M: np.ndarray,
    h: np.ndarray,
    acceleration: np.ndarray,
    point_jacobian: np.ndarray,
    J_sup: np.ndarray,
    drift: np.ndarray,
    cones: np.ndarray,
    force_regularization: float,
    support_weight: float,
    qp_solver: str,
) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`nearest_feasible_motion` without its torque rows, by eliminating ``q̈``.

    With ``q̈ = q̈_des + Δ``, ``N = M + w_s J_supᵀ J_sup``, ``g = w_s J_supᵀ (J_sup q̈_des
    + J̇_sup q̇)`` and ``B = M_root`` (the root rows of ``M``), the motion part is
    ``min ½ Δᵀ N Δ + gᵀ Δ s.t. B Δ = r`` with ``r = A f − w``, ``A = (J_cᵀ)_root``,
    ``w = (M q̈_des + h)_root``. Its minimizer is ``Δ = Δ₀ + Y K⁻¹ (r − B Δ₀)`` with
    ``Δ₀ = −N⁻¹ g``, ``Y = N⁻¹ Bᵀ``, ``K = B Y`` (6 × 6), and its value
    ``½ (r − B Δ₀)ᵀ K⁻¹ (r − B Δ₀)`` up to a constant. What is left is a QP in ``f``::

        min ½ (A f − c)ᵀ K⁻¹ (A f − c) + ½ ε ‖f‖²   s.t.  f in the pyramids,  c = w + B Δ₀

    Returns:
        ``(q̈, f)``, or ``None`` if a factorization or the QP fails.
    """
    N = M + support_weight * (J_sup.T @ J_sup) if len(J_sup) else M
    lower, info = lapack.dpotrf(N, lower=1, clean=0)
    if info != 0:
        return None
    root = M[:NUM_ROOT_DOFS]
    rhs = np.empty((h.size, NUM_ROOT_DOFS + 1))
    rhs[:, :NUM_ROOT_DOFS] = root.T
    rhs[:, NUM_ROOT_DOFS] = (
        -support_weight * (J_sup.T @ (J_sup @ acceleration + drift)) if len(J_sup) else 0.0
    )
    solved, info = lapack.dpotrs(lower, rhs, lower=1)
    if info != 0:
        return None
    Y, delta_free = solved[:, :NUM_ROOT_DOFS], solved[:, NUM_ROOT_DOFS]
    K = root @ Y
    A = point_jacobian[:, :NUM_ROOT_DOFS].T
    c = (M[:NUM_ROOT_DOFS] @ acceleration + h[:NUM_ROOT_DOFS]) + root @ delta_free
    K_lower, info = lapack.dpotrf(K, lower=1, clean=0)
    if info != 0:
        return None
    K_inv_A, _ = lapack.dpotrs(K_lower, A, lower=1)
    hessian = A.T @ K_inv_A
    hessian.flat[:: hessian.shape[0] + 1] += force_regularization
    point_force = _solve_qp(
        hessian, -K_inv_A.T @ c, cones, np.zeros(cones.shape[0]), qp_solver=qp_solver
    )
    if point_force is None:
        return None
    K_inv_residual, _ = lapack.dpotrs(K_lower, A @ point_force - c, lower=1)
    return acceleration + delta_free + Y @ K_inv_residual, point_force


def _solve_qp(
    P: np.ndarray,
    q: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    *,
    A: np.ndarray | None = None,
    b: np.ndarray | None = None,
    qp_solver: str,
) -> np.ndarray | None:
    """``min ½ xᵀ P x + qᵀ x  s.t.  G x ≤ h, A x = b``: a finite ``x``, or ``None``.

    Each solve is capped in iterations (:func:`solve_qp_bounded`). Linear data larger than
    :data:`QP_DATA_SCALE` are divided by ``k`` to that size and ``x = k y`` is returned from
    the solution ``y`` of the scaled problem (the same problem: its cost is ``k²`` times the
    original's). Non-finite data are not handed to a solver (ProxQP iterates on NaN residuals
    until its caps), and a solver that gives up by raising counts as no answer.
    """
    linear = np.concatenate([q, h] if b is None else [q, h, b])
    scale = float(np.max(np.abs(linear), initial=0.0))  # NaN if any is
    if not (np.isfinite(scale) and np.all(np.isfinite(P)) and np.all(np.isfinite(G))):
        return None
    if A is not None and not np.all(np.isfinite(A)):
        return None
    k = max(1.0, scale / QP_DATA_SCALE)
    if k > 1.0:
        q, h, b = q / k, h / k, None if b is None else b / k
    try:
        solution = solve_qp_bounded(
            qpsolvers.Problem(P, q, G, h, A, b), qp_solver, **QP_SETTINGS.get(qp_solver, {})
        )
    except (ValueError, np.linalg.LinAlgError, qpsolvers.ProblemError, qpsolvers.SolverError):
        return None  # e.g. quadprog's "constraints are inconsistent", "P is not definite"
    if not solution.found or solution.x is None:
        return None
    x = solution.x * k if k > 1.0 else solution.x
    return x if np.all(np.isfinite(x)) else None


def wrenches_from_point_forces(
    terms: DynamicsTerms, forces: np.ndarray, counts: Sequence[int]
) -> np.ndarray:
    """Per contact: total force and torque about the contact frame origin, ``(contacts, 6)``."""
    ends = np.cumsum(counts)
    return np.array(
        [
            wrench_map @ forces[end - count : end].reshape(-1)
            for wrench_map, count, end in zip(terms.point_wrench_maps, counts, ends, strict=True)
        ]
    ).reshape(-1, 6)


def exact_inverse_dynamics(
    robot: RobotModel,
    data: pin.Data,
    q: np.ndarray,
    v: np.ndarray,
    acceleration: np.ndarray,
    geometry: ContactGeometry,
    supports: Sequence[bool],
    friction_coefficients: Sequence[float],
    torque_limit: np.ndarray,
) -> InverseDynamicsResult | None:
    """The exact case of :func:`solve_inverse_dynamics` by RNEA, or ``None``.

    RNEA gives ``M q̈ + h``; its root rows are the wrench the root needs (base
    axes, about the base origin ``o``). In world axes a point force ``f`` at
    ``p`` supplies ``[f; (p − o) × f]`` of it. The smallest support-point
    forces that supply it all are those of :func:`minimum_norm_balance` (a
    rotation of the rows leaves the minimum-norm solution unchanged). RNEA
    again, with these forces as external forces, gives
    ``τ = (M q̈ + h − J_cᵀ f)_joints``.

    Args:
        robot: The robot (root joint 1, a free flyer).
        data: Pinocchio data (overwritten).
        q: Configuration, ``(nq,)``.
        v: Generalized velocity, ``(nv,)``.
        acceleration: ``q̈`` to realize, ``(nv,)``.
        geometry: Contact points at ``q`` (:func:`compute_contact_geometry`).
        supports: One flag per contact.
        friction_coefficients: μ per contact.
        torque_limit: ``(nv − 6,)`` symmetric limits.

    Returns:
        The result with ``acceleration`` unchanged, or ``None`` when there is
        no support, the forces leave the friction pyramids, or ``τ`` exceeds
        its limits: then only the full solve (its QP) can answer.
    """
    if not any(supports):
        return None
    model = robot.model
    root_in_base = pin.rnea(model, data, q, v, acceleration)[:NUM_ROOT_DOFS]
    root = data.oMi[1]
    origin = root.translation
    wrench_in_world = (root_in_base.reshape(2, 3) @ root.rotation.T).reshape(-1)
    points = geometry.position_points_in_world
    chosen = [index for index, on in enumerate(supports) if on]
    # [Σ f; Σ r × f] about the base origin, in world axes.
    balance = wrench_map(np.concatenate([points[index] for index in chosen]) - origin)
    mus = [friction_coefficients[index] for index in chosen for _ in points[index]]
    solution = minimum_norm_balance(balance, wrench_in_world, mus)
    if solution is None:
        return None
    counts = [len(p) for p in points]
    starts = list(itertools.accumulate(counts, initial=0))
    forces = np.zeros((starts[-1], 3))
    wrenches = np.zeros((len(counts), 6))
    external = list(_zero_forces(model.njoints))
    ox, oy, oz = origin.tolist()
    column = 0
    for index in chosen:
        count = counts[index]
        point_forces = solution[column : column + 3 * count]
        forces[starts[index] : starts[index + 1]] = point_forces.reshape(-1, 3)
        # Force, and moment about the base origin, of this contact's points.
        fx, fy, fz, mx, my, mz = (balance[:, column : column + 3 * count] @ point_forces).tolist()
        column += 3 * count
        force = np.array([fx, fy, fz])
        # Moment about the world origin: + o × F; about the contact frame origin c: − (c − o) × F.
        about_world = np.array(
            [mx + oy * fz - oz * fy, my + oz * fx - ox * fz, mz + ox * fy - oy * fx]
        )
        cx, cy, cz = (geometry.position_contact_frames_in_world[index] - origin).tolist()
        wrenches[index] = [
            fx,
            fy,
            fz,
            mx - cy * fz + cz * fy,
            my - cz * fx + cx * fz,
            mz - cx * fy + cy * fx,
        ]
        joint = geometry.joint_ids[index]
        external[joint] = external[joint] + data.oMi[joint].actInv(pin.Force(force, about_world))
    torque = pin.rnea(model, data, q, v, acceleration, external)[NUM_ROOT_DOFS:]
    if not (np.abs(torque) <= torque_limit).all():
        return None
    return InverseDynamicsResult(torque, forces, wrenches, acceleration.copy(), 0.0, 0)


@cache
def _zero_forces(count: int) -> tuple[pin.Force, ...]:
    """``count`` zero spatial forces (shared, never mutated: entries are replaced)."""
    return tuple(pin.Force.Zero() for _ in range(count))
