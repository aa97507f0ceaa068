"""Floating-base inverse dynamics with contact forces in friction cones.

Macchietto 2008, eq. 4.2, written with actuated torques ``τ`` (``S = [0 I]``)::

    M q̈ + h = Sᵀ τ + J_cᵀ f

Two ground-force modes. *Measured*: the client sends the ground wrench of
every contact (the thesis' penalty forces, or force sensors) and ``τ``
compensates it, as in the thesis. *Distributed*: the six root rows have no
actuator, so the contact forces ``f`` of the supporting feet must balance
them, within linearized (pyramid) friction cones on a flat ground of normal
+z (``f_z ≥ 0``, ``|f_x|, |f_y| ≤ μ f_z`` at every support point). The
distribution is the smallest force that balances exactly::

    min_f ‖f‖²   s.t.  J_c,rootᵀ f = (M q̈ + h)_root,  f in the cones

and, when no force in the cones can (centre of pressure outside the feet,
too much traction), the least-squares balance
``min_f ‖J_c,rootᵀ f − (M q̈ + h)_root‖² + ε ‖f‖²``. Both are QPs solved by a
maintained solver through ``qpsolvers``. The actuated rows give
``τ``, clipped to the torque limits. When the cones or the limits cannot
realize ``q̈`` exactly, the returned acceleration is the one ``τ`` and ``f``
really produce, ``q̈ = M⁻¹ (Sᵀ τ + J_cᵀ f − h)``, so the command is always
dynamically consistent; the unbalanced root wrench is reported.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache

import numpy as np
import qpsolvers
import scipy.linalg

from controller_server.dynamics import DynamicsTerms
from controller_server.spatial import cross

__all__ = [
    "InverseDynamicsResult",
    "distribute_contact_forces",
    "friction_pyramid",
    "solve_inverse_dynamics",
]

NUM_ROOT_DOFS = 6


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

    Five rows per point: ``±f_x − μ f_z ≤ 0``, ``±f_y − μ f_z ≤ 0``, ``−f_z ≤ 0``.
    Built once per set of coefficients (the supports change rarely); the
    caller gets a copy, since some solvers want writeable inputs.
    """
    return _friction_pyramid(tuple(float(mu) for mu in friction_coefficients)).copy()


@cache
def _friction_pyramid(friction_coefficients: tuple[float, ...]) -> np.ndarray:
    count = len(friction_coefficients)
    rows = np.zeros((5 * count, 3 * count))
    for i, mu in enumerate(friction_coefficients):
        block = np.array(
            [[1, 0, -mu], [-1, 0, -mu], [0, 1, -mu], [0, -1, -mu], [0, 0, -1]], dtype=float
        )
        rows[5 * i : 5 * i + 5, 3 * i : 3 * i + 3] = block
    return rows


def distribute_contact_forces(
    G: np.ndarray,
    wrench: np.ndarray,
    friction_coefficients: Sequence[float],
    regularization: float,
    qp_solver: str,
) -> np.ndarray | None:
    """Point forces ``f`` in the cones with ``G f = wrench``, or closest to it.

    Args:
        G: ``(6, 3p)`` map from point forces to the root wrench (``J_c,rootᵀ``).
        wrench: Root wrench to balance.
        friction_coefficients: μ per point.
        regularization: ``ε`` of the least-squares fallback.
        qp_solver: Solver name for ``qpsolvers``.

    Returns:
        ``(3p,)`` forces, or ``None`` if the solver failed.
    """
    n = G.shape[1]
    cones = friction_pyramid(friction_coefficients)
    # The unconstrained minimum-norm balance f = Gᵀ (G Gᵀ)⁻¹ w solves the QP whenever
    # it already lies in the cones (the common case when standing): no solver call.
    try:
        minimum_norm = G.T @ np.linalg.solve(G @ G.T, wrench)
    except np.linalg.LinAlgError:
        minimum_norm = None
    if minimum_norm is not None and np.all(cones @ minimum_norm <= 1e-9 * max(1.0, abs(wrench[2]))):
        return minimum_norm
    zeros = np.zeros(cones.shape[0])
    forces = qpsolvers.solve_qp(
        np.eye(n), np.zeros(n), cones, zeros, A=G, b=wrench, solver=qp_solver
    )
    if forces is None or not np.all(np.isfinite(forces)):
        P = G.T @ G + regularization * np.eye(n)
        forces = qpsolvers.solve_qp(P, -G.T @ wrench, cones, zeros, solver=qp_solver)
    return forces if forces is not None and np.all(np.isfinite(forces)) else None


def solve_inverse_dynamics(
    terms: DynamicsTerms,
    acceleration: np.ndarray,
    supports: Sequence[bool],
    friction_coefficients: Sequence[float],
    torque_limit: np.ndarray,
    *,
    measured_wrenches: np.ndarray | None = None,
    force_regularization: float = 1e-6,
    qp_solver: str = "daqp",
) -> InverseDynamicsResult:
    """Torques and contact forces realizing ``acceleration`` (eq. 4.2).

    Args:
        terms: Dynamics at the current state.
        acceleration: Desired ``q̈`` from the optimizer, ``(nv,)``.
        supports: One flag per contact; only supports carry distributed force.
        friction_coefficients: μ per contact.
        torque_limit: ``(nv − 6,)`` symmetric limits.
        measured_wrenches: ``(contacts, 6)`` measured ground wrenches (measured
            mode), or ``None`` to distribute forces.
        force_regularization: ``ε`` of the least-squares fallback.
        qp_solver: Any solver name ``qpsolvers`` knows.
    """
    M, h = terms.mass_matrix, terms.bias_forces
    generalized_force = M @ acceleration + h
    root_wrench = generalized_force[:NUM_ROOT_DOFS]
    counts = [J.shape[0] // 3 for J in terms.point_jacobians]
    forces = np.zeros((sum(counts), 3))
    if measured_wrenches is not None:
        wrenches = np.asarray(measured_wrenches, dtype=float).reshape(-1, 6)
        contact_generalized_force = sum(
            (J.T @ w for J, w in zip(terms.support_jacobians, wrenches, strict=True)),
            np.zeros_like(h),
        )
    else:
        contact_generalized_force, forces = _distribute(
            terms, root_wrench, supports, friction_coefficients, force_regularization, qp_solver
        )
        wrenches = _wrenches_from_point_forces(terms, forces, counts)

    residual = float(np.linalg.norm(root_wrench - contact_generalized_force[:NUM_ROOT_DOFS]))
    torque_unclipped = (generalized_force - contact_generalized_force)[NUM_ROOT_DOFS:]
    joint_torque = np.clip(torque_unclipped, -torque_limit, torque_limit)
    saturated = int(np.count_nonzero(joint_torque != torque_unclipped))

    applied = contact_generalized_force - h
    applied[NUM_ROOT_DOFS:] += joint_torque
    realized = scipy.linalg.cho_solve(scipy.linalg.cho_factor(M), applied)
    return InverseDynamicsResult(joint_torque, forces, wrenches, realized, residual, saturated)


def _distribute(
    terms: DynamicsTerms,
    root_wrench: np.ndarray,
    supports: Sequence[bool],
    friction_coefficients: Sequence[float],
    regularization: float,
    qp_solver: str,
) -> tuple[np.ndarray, np.ndarray]:
    """``(J_cᵀ f, f per point)`` for forces at the supporting contacts' points."""
    counts = [J.shape[0] // 3 for J in terms.point_jacobians]
    forces = np.zeros((sum(counts), 3))
    generalized = np.zeros_like(terms.bias_forces)
    if not any(supports):
        return generalized, forces
    J_c = np.vstack([J for J, on in zip(terms.point_jacobians, supports, strict=True) if on])
    mus = [
        mu
        for mu, count, on in zip(friction_coefficients, counts, supports, strict=True)
        if on
        for _ in range(count)
    ]
    solution = distribute_contact_forces(
        J_c[:, :NUM_ROOT_DOFS].T, root_wrench, mus, regularization, qp_solver
    )
    if solution is None:
        return generalized, forces
    mask = np.concatenate([np.full(count, on) for count, on in zip(counts, supports, strict=True)])
    forces[mask] = solution.reshape(-1, 3)
    return J_c.T @ solution, forces


def _wrenches_from_point_forces(
    terms: DynamicsTerms, forces: np.ndarray, counts: Sequence[int]
) -> np.ndarray:
    """Per contact: total force and torque about the contact frame origin."""
    owner = np.repeat(np.arange(len(counts)), counts)
    offsets = (
        np.vstack(terms.position_points_in_world) - terms.position_contact_frames_in_world[owner]
    )
    per_point = np.hstack([forces, cross(offsets, forces)])
    wrenches = np.zeros((len(counts), 6))
    np.add.at(wrenches, owner, per_point)
    return wrenches
