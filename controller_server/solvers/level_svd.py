"""The SVD of a priority level, from the eigendecomposition of its Gram matrix when it may be.

Algorithm 1 (de Lasa et al. 2010) needs each level's ``Ā = A C̄`` as ``U Σ Vᵀ``
(Maciejewski 1990's analysis and damping of its singular values). For a well-conditioned
level the eigendecomposition of ``Ā Āᵀ`` (wide) or ``Āᵀ Ā`` (tall) gives it at about a
third of the cost of the SVD, at a loss of ``ε κ²`` in ``σ_min`` that is accepted only up to
:data:`GRAM_CONDITION_LIMIT`; otherwise these return ``None`` and the caller takes the SVD.
"""

from __future__ import annotations

import eigenpy
import numpy as np
from scipy.linalg import lapack as _lapack

__all__ = [
    "GRAM_CONDITION_LIMIT",
    "GRAM_MIN_COLUMNS",
    "gram_svd",
    "gram_svd_tall",
    "orthogonal_complement",
    "symmetric_eigen",
]

GRAM_CONDITION_LIMIT = 1e3
"""Largest condition number of a level flagged well conditioned (:attr:`Level.well_conditioned`)
whose SVD comes from the eigendecomposition of ``Ā Āᵀ`` (:func:`gram_svd`)."""

_GRAM_MIN_COLUMNS = 8
"""Tall levels with fewer columns take the SVD: it costs little more than the Gram matrix."""

GRAM_MIN_COLUMNS = 8
"""Tall levels with fewer columns take the SVD: it costs little more than the Gram matrix."""


def symmetric_eigen(G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (ascending) and eigenvectors of a symmetric ``G``.

    Eigen's ``SelfAdjointEigenSolver`` (through eigenpy, which Pinocchio's bindings are built
    on): 1.5–2× faster than LAPACK's ``syevd`` at the sizes of the levels (15–45), as
    backward stable.
    """
    solver = eigenpy.SelfAdjointEigenSolver(G)
    return solver.eigenvalues(), solver.eigenvectors()


def gram_svd(
    A: np.ndarray, null_space_part: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``U``, ``σ`` (descending) and ``V`` (``k × k``) of a wide ``A`` from ``eigh(A Aᵀ)``.

    ``A Aᵀ = U Σ² Uᵀ``, ``V[:, :m] = Aᵀ U Σ⁻¹`` and the rest of ``V`` any orthonormal basis
    of ``null(A)``: the directions without a singular value all get the same QP curvature,
    so which basis does not matter. It is the complement (:func:`orthogonal_complement`)
    of ``V[:, :m]`` and ``null_space_part`` (orthonormal columns in ``null(A)``), then
    ``null_space_part`` itself, last. Squaring loses ``ε κ²`` relative in ``σ_min`` (κ the
    condition number); ``None`` unless ``κ ≤`` :data:`GRAM_CONDITION_LIMIT` (then ≲ 1e-10,
    and ≈ 2e-12 for the equations of motion of the built-in models, κ ≈ 100): the caller
    takes the SVD of ``A`` instead. The ``m × m`` eigendecomposition costs about a third of
    the ``m × k`` SVD.
    """
    m, k = A.shape
    eigenvalues, eigenvectors = symmetric_eigen(A @ A.T)
    if not eigenvalues[0] >= eigenvalues[-1] / GRAM_CONDITION_LIMIT**2:  # also NaN
        return None
    sigma = np.sqrt(eigenvalues[::-1])
    U = np.ascontiguousarray(eigenvectors[:, ::-1])  # descending; BLAS needs positive strides
    V = np.empty((k, k))
    V[:, :m] = (A.T @ U) / sigma
    given = 0 if null_space_part is None else null_space_part.shape[1]
    if given:
        V[:, k - given :] = null_space_part
    if m + given < k:
        known = V[:, :m] if not given else np.hstack([V[:, :m], V[:, k - given :]])
        V[:, m : k - given] = orthogonal_complement(known)
    return U, sigma, V


def gram_svd_tall(A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Thin ``U``, ``σ`` (descending) and ``V`` of a tall ``A`` from ``eigh(Aᵀ A)``.

    ``Aᵀ A = V Σ² Vᵀ``, ``U = A V Σ⁻¹``; ``None`` unless the condition number is at most
    :data:`GRAM_CONDITION_LIMIT` (see :func:`gram_svd`): then no singular value is at the
    rounding floor, and none is within ``ε κ²`` (relative) of any other threshold but by
    a coincidence the damping's continuity at ``1/B`` makes harmless.
    """
    eigenvalues, eigenvectors = symmetric_eigen(A.T @ A)
    if not eigenvalues[0] >= eigenvalues[-1] / GRAM_CONDITION_LIMIT**2:  # also NaN
        return None
    sigma = np.sqrt(eigenvalues[::-1])
    V = np.ascontiguousarray(eigenvectors[:, ::-1])  # descending; BLAS needs positive strides
    return (A @ V) / sigma, sigma, V


def orthogonal_complement(V: np.ndarray) -> np.ndarray:
    """An orthonormal basis ``(k, k − m)`` of the complement of ``V``'s orthonormal columns.

    The last columns of ``Q`` in the Householder QR of ``V`` (LAPACK ``geqrf``, then ``ormqr``
    applied to ``[0; I]``), without forming all of ``Q``.
    """
    k, m = V.shape
    factors, tau, _, _ = _lapack.dgeqrf(V)
    identity = np.zeros((k, k - m), order="F")
    identity[m:] = np.eye(k - m)
    complement, _, _ = _lapack.dormqr("L", "N", factors, tau, identity, lwork=64 * k)
    return complement
