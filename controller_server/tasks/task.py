"""A task: one objective's reference, gains and rows, and the tick it reads them from.

A task is an objective of the papers as an object, as TSID's tasks and pink's are: it
turns the state of one tick (:class:`Tick`) into weighted least-squares rows ``(A, b, w)``
over one block of the unknowns (:class:`~controller_server.features.Objective`; Macchietto
2008, eq. 4.1; de Lasa et al. 2010, eq. 16). The rows themselves come from the feature
library (:mod:`controller_server.features`); a task adds where its reference comes from
(parameters, a behaviour's targets, the support) and whether it has rows this tick.

Which tasks a controller solves, with which weight and at which priority, is its
:class:`~controller_server.tasks.stack.TaskStack`'s business, not the task's.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol

import numpy as np
import pinocchio as pin

from controller_server.behaviors import Targets
from controller_server.dynamics import DynamicsTerms
from controller_server.features import Objective
from controller_server.models import RobotModel

__all__ = ["LoadedPoints", "Task", "Tick"]


class LoadedPoints(Protocol):
    """The sole points of one tick, as the prioritized controller's layout holds them.

    Attributes:
        point_jacobian: ``(3 p, nv)`` linear Jacobians of the planted sole points, stacked.
        point_drift: ``(3 p,)`` their ``J̇ q̇``.
        point_positions: ``(p, 3)`` their positions in world (m).
        support_positions: ``(s, 3)`` the points that support the body (m).
        support_polygon: ``(k, 2)`` convex hull of the support points on the ground (m).
        smallest_friction_coefficient: the smallest μ of the supporting contacts.
    """

    point_jacobian: np.ndarray
    point_drift: np.ndarray
    point_positions: np.ndarray
    support_positions: np.ndarray
    support_polygon: np.ndarray
    smallest_friction_coefficient: float

    def contact_row_basis(self) -> np.ndarray | None:
        """Orthonormal columns spanning the planted points' rows, if fewer than the rows."""
        ...


@dataclass
class Tick:
    """What the tasks read at one tick, built once by the controller.

    Attributes:
        robot: The robot model.
        data: Pinocchio data, with this state's kinematics (frame placements).
        q: Configuration ``(nq,)``.
        v: Velocity ``(nv,)``.
        time_s: The state's time (s).
        terms: This state's dynamics terms.
        params: The parameters in force (the client's, a behaviour's over them).
        supports: Per contact, whether it supports the body.
        gravity: ``‖g‖`` of the model (m/s²).
        targets: The hosted behaviour's targets for this tick, if any.
        loaded: The sole points (prioritized controller), if the controller has them.
        support_polygon_xy: ``(k, 2)`` support polygon (weighted controller), if built.
        contact_wrench_in_world: ``(n_contacts, 6)`` ground wrenches the COP and CMP are of.
        reports: What tasks computed for the diagnostics (desired momentum rates, …).
        shared: Quantities two tasks compute once (memo by name).
    """

    robot: RobotModel
    data: pin.Data
    q: np.ndarray
    v: np.ndarray
    time_s: float
    terms: DynamicsTerms
    params: Mapping[str, Any]
    supports: tuple[bool, ...]
    gravity: float
    targets: Targets | None = None
    loaded: LoadedPoints | None = None
    support_polygon_xy: np.ndarray | None = None
    contact_wrench_in_world: np.ndarray | None = None
    reports: dict[str, Any] = field(default_factory=dict)
    shared: dict[str, Any] = field(default_factory=dict)


class Task(ABC):
    """One objective over a block of the unknowns, by name.

    Attributes:
        name: The task's name: its weight and priority are ``weight_<name>`` and
            ``priority_<name>``, its residual in the diagnostics is keyed by it.
        block: The block of the unknowns its rows cover: ``"acceleration"`` (``q̈``, every
            controller) or ``"torque"`` (``τ``, the prioritized controller's ``x``).
        uniform: Whether every row has the stack's weight (else the task weighs its rows).
    """

    block: ClassVar[str] = "acceleration"
    uniform: ClassVar[bool] = True

    def __init__(self, name: str):
        self.name = name

    @abstractmethod
    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """The task's rows this tick with ``weight`` folded in, or ``None`` when it has none."""

    def row_basis(self, tick: Tick) -> np.ndarray | None:
        """Orthonormal columns spanning the rows, when they span fewer dimensions than they are."""
        return None

    def reset(self) -> None:  # noqa: B027 (a hook: most tasks keep nothing between ticks)
        """Forget what was derived from the parameters (they changed)."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"
