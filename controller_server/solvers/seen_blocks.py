"""What one priority level sees of the freedom the levels above left (Algorithm 1's ``C̄``).

de Lasa et al.'s reparameterization keeps the optimal set of the levels solved so far as
``x = C̄ w + d̄``. The solver keeps ``C̄`` as blocks of orthonormal columns; a level whose
rows are exactly zero on a block leaves it out of its SVD and passes it down unchanged
(:mod:`~controller_server.solvers.prioritized`, "Blocks").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SeenBlocks"]


@dataclass(frozen=True)
class SeenBlocks:
    """One level's view of ``C̄`` (:mod:`~.prioritized`'s docstring, "Blocks").

    Attributes:
        A_bar: ``Ā = A C̄`` on the blocks the level sees, ``(m, k)``.
        D_seen: ``D C̄`` on those blocks, ``(p, k)``.
        D_unseen: ``D C̄`` on the blocks on which ``A`` is exactly zero, ``(p, k_u)``.
        seen: The seen blocks' bases side by side, ``(n, k)`` (``None``: ``C̄ = I``).
        unseen: The unseen blocks, ``(basis, D basis)``.
    """

    A_bar: np.ndarray
    D_seen: np.ndarray
    D_unseen: np.ndarray
    seen: np.ndarray | None
    unseen: list[tuple[np.ndarray, np.ndarray]]

    @staticmethod
    def of(
        A: np.ndarray, D: np.ndarray, blocks: list[tuple[np.ndarray, np.ndarray]] | None
    ) -> SeenBlocks:
        """Split ``C̄``'s blocks into those ``A`` sees and those it is exactly zero on."""
        if blocks is None:
            return SeenBlocks(A, D, D[:, :0], None, [])
        seen: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        unseen: list[tuple[np.ndarray, np.ndarray]] = []
        for basis, D_basis in blocks:
            product = A @ basis
            if product.any():
                seen.append((basis, D_basis, product))
            else:
                unseen.append((basis, D_basis))
        if len(unseen) > 1:
            D_unseen = np.hstack([D_basis for _, D_basis in unseen])
        else:
            D_unseen = unseen[0][1] if unseen else D[:, :0]
        if len(seen) == 1:
            basis, D_basis, product = seen[0]
            return SeenBlocks(product, D_basis, D_unseen, basis, unseen)
        if not seen:
            return SeenBlocks(A[:, :0], D[:, :0], D_unseen, np.zeros((A.shape[1], 0)), unseen)
        return SeenBlocks(
            np.hstack([product for _, _, product in seen]),
            np.hstack([D_basis for _, D_basis, _ in seen]),
            D_unseen,
            np.hstack([basis for basis, _, _ in seen]),
            unseen,
        )

    def to_x(self, w: np.ndarray, w_unseen: np.ndarray | None) -> np.ndarray:
        """A step in ``x`` from its coordinates on the seen and the unseen blocks."""
        move = w if self.seen is None else self.seen @ w
        if w_unseen is not None:
            start = 0
            for basis, _ in self.unseen:
                end = start + basis.shape[1]
                move = move + basis @ w_unseen[start:end]
                start = end
        return move

    def null_blocks(
        self, null_parts: list[tuple[np.ndarray, np.ndarray | None]]
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """``C̄ null(Ā)`` as blocks: the level's null space in the seen part, then the unseen."""
        blocks = [
            (
                part if self.seen is None else self.seen @ part,
                self.D_seen @ part if D_part is None else D_part,
            )
            for part, D_part in null_parts
            if part.shape[1]
        ]
        return blocks + self.unseen
