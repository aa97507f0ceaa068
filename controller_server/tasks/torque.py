"""``torque``: the least torque on selected joints (de Lasa et al. 2010, eq. 15)."""

from __future__ import annotations

import numpy as np

from controller_server.features import Objective
from controller_server.tasks.task import Task, Tick

__all__ = ["TorqueTask"]


class TorqueTask(Task):
    """``Σ sᵢ τᵢ²`` on the joints of ``torque_selection``, over the ``τ`` block.

    Rows weighted α where ``sᵢ > 0``, 0 elsewhere; kept until the parameters or the weight change.
    """

    block = "torque"
    uniform = False

    def __init__(self, name: str = "torque"):
        super().__init__(name)
        self._rows: Objective | None = None
        self._weight = 0.0

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """Rows ``√sᵢ τᵢ`` toward 0."""
        if self._rows is None or weight != self._weight:
            self._weight = weight
            selection = np.asarray(tick.params["torque_selection"], dtype=float)
            self._rows = Objective(
                self.name,
                np.diag(np.sqrt(selection)),
                np.zeros(selection.size),
                np.full(selection.size, weight) * (selection > 0),
            )
        return self._rows

    def reset(self) -> None:
        """Forget the rows' weights (the parameters changed)."""
        self._rows = None
