"""Damped least squares with a guaranteed gain bound (Maciejewski 1990).

For a linear system with singular values σᵢ, the damped least-squares
solution (Maciejewski 1990, eq. 15–16)::

    x = Σᵢ σᵢ / (σᵢ² + λ²) · vᵢ uᵢᵀ b

scales each component by at most ``1 / (2λ)`` (eq. 18, reached at σᵢ = λ),
and goes continuously to zero as σᵢ → 0 (eq. 19) instead of blowing up as
the pseudo-inverse does. Here the damping factor λ is chosen from the
smallest singular value so that the gain ``maxᵢ σᵢ / (σᵢ² + λ²)`` never
exceeds a bound ``B`` while leaving well-conditioned systems undamped:

* σ_min ≥ 1/B: λ = 0 (plain solve, gain 1/σ_min ≤ B);
* 1/(2B) ≤ σ_min < 1/B: λ² = σ_min/B − σ_min² (gain exactly B at σ_min);
* σ_min < 1/(2B): λ = 1/(2B) (gain ≤ 1/(2λ) = B by eq. 18).

λ is a continuous function of σ_min, so solutions vary continuously along
a path through a singularity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

__all__ = ["DampedFactor", "damped_cholesky", "damped_solve_psd", "damping_for_gain_bound"]


def damping_for_gain_bound(sigma_min: float, gain_bound: float) -> float:
    """Smallest damping λ keeping ``σ/(σ² + λ²) ≤ gain_bound`` for all σ ≥ σ_min.

    Args:
        sigma_min: Smallest singular value of the system (≥ 0).
        gain_bound: ``B > 0``, the largest allowed ‖x‖ / ‖b‖.
    """
    if sigma_min >= 1.0 / gain_bound:
        return 0.0
    if sigma_min >= 0.5 / gain_bound:
        return math.sqrt(max(sigma_min / gain_bound - sigma_min**2, 0.0))
    return 0.5 / gain_bound


def damped_solve_psd(
    gram: np.ndarray, rhs: np.ndarray, gain_bound: float
) -> tuple[np.ndarray, float, float]:
    """Solve ``(G + λ² I) y = r`` for a Gram matrix ``G = K Kᵀ`` with damping from ``B``.

    ``G``'s eigenvalues are the squared singular values of ``K``; λ follows
    :func:`damping_for_gain_bound`, so ``‖Kᵀ y‖ ≤ B ‖r‖``.

    Args:
        gram: Symmetric positive semi-definite ``(m, m)``.
        rhs: ``(m,)`` or ``(m, k)``.
        gain_bound: ``B``.

    Returns:
        ``(y, λ, condition number of G)`` (condition ``inf`` when singular).
    """
    eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (gram + gram.T))
    eigenvalues = np.maximum(eigenvalues, 0.0)
    sigma_min = math.sqrt(eigenvalues[0])
    damping = damping_for_gain_bound(sigma_min, gain_bound)
    denominator = eigenvalues + damping**2
    condition = float(eigenvalues[-1] / eigenvalues[0]) if eigenvalues[0] > 0 else math.inf
    if denominator[0] <= 0.0:  # exactly singular and undamped cannot happen with B < ∞
        denominator = np.where(denominator > 0, denominator, np.inf)
    coefficients = (eigenvectors.T @ rhs) / (denominator if rhs.ndim == 1 else denominator[:, None])
    return eigenvectors @ coefficients, damping, condition


@dataclass(frozen=True)
class DampedFactor:
    """Cholesky factor of ``G + λ² I`` with λ from a gain bound (see :func:`damped_cholesky`).

    Attributes:
        lower: Lower-triangular ``L`` with ``L Lᵀ = G + λ² I``.
        damping: λ.
        norm_1: 1-norm of ``G + λ² I`` (for the condition estimate).
    """

    lower: np.ndarray
    damping: float
    norm_1: float

    @property
    def damped_condition(self) -> float:
        """Condition number of ``G + λ² I``, LAPACK's 1-norm estimate (``dpocon``).

        Estimated on demand: only diagnostics read it, and it costs as much as the factor.
        """
        reciprocal, _ = lapack.dpocon(self.lower, self.norm_1, uplo="L")
        return float(max(1.0 / reciprocal, 1.0)) if reciprocal > 0 else math.inf

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``(G + λ² I)⁻¹ rhs`` for ``(m,)`` or ``(m, k)`` right-hand sides."""
        solution, _ = lapack.dpotrs(self.lower, rhs, lower=1)
        return solution


def _shifted(gram: np.ndarray, shift: float) -> np.ndarray:
    """``G + shift · I`` as a new array."""
    shifted = np.array(gram, dtype=float)
    shifted.flat[:: len(shifted) + 1] += shift
    return shifted


def _positive_definite_after_shift(gram: np.ndarray, shift: float) -> bool:
    """Whether ``G − shift · I`` has a Cholesky factor, i.e. every eigenvalue exceeds ``shift``."""
    _, info = lapack.dpotrf(_shifted(gram, -shift), lower=1, clean=0, overwrite_a=1)
    return info == 0


def damped_cholesky(gram: np.ndarray, gain_bound: float) -> DampedFactor | None:
    """Factor ``G + λ² I`` with λ from :func:`damping_for_gain_bound`, mostly without eigenvalues.

    ``G``'s eigenvalues are σᵢ²; a Cholesky factorization of ``G − s² I``
    succeeds exactly when σ_min > s. Two such tests place σ_min in the three
    bands of the damping rule; only the middle band (1/(2B) ≤ σ_min < 1/B),
    where λ depends on σ_min's value, needs the eigenvalues. Same λ as
    :func:`damped_solve_psd`, several times cheaper for the small dense
    systems of one control tick.

    Args:
        gram: Symmetric positive semi-definite ``(m, m)``.
        gain_bound: ``B``.

    Returns:
        The factor, or ``None`` if ``G + λ² I`` is not finite or not positive definite.
    """
    band_edges = (gain_bound**-2, (0.5 / gain_bound) ** 2)  # σ_min² at the band edges
    if _positive_definite_after_shift(gram, band_edges[1]):  # σ_min > 1/(2B)
        if _positive_definite_after_shift(gram, band_edges[0]):  # σ_min > 1/B: undamped
            damping = 0.0
        else:  # 1/(2B) < σ_min ≤ 1/B: λ depends on σ_min
            sigma_min = math.sqrt(max(float(np.linalg.eigvalsh(gram)[0]), 0.0))
            damping = damping_for_gain_bound(sigma_min, gain_bound)
    else:  # σ_min ≤ 1/(2B)
        damping = 0.5 / gain_bound
    damped = _shifted(gram, damping**2) if damping else gram
    lower, info = lapack.dpotrf(damped, lower=1, clean=1)
    if info != 0 or not np.all(np.isfinite(lower)):
        return None
    return DampedFactor(lower, damping, float(np.abs(damped).sum(axis=0).max()))
