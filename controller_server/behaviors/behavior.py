"""What a behaviour is to the controller that hosts it: ``update(observation) → Targets``.

de Lasa et al. build jumps and walks on the balance controller by changing its objectives'
references, weights and priorities from a state machine (§5–6). Here a behaviour observes
the tick (:class:`~controller_server.behaviors.observation.Observation`) and answers its
:class:`Targets` for that tick: parameter values of its host (task references, gains,
weights, priorities, and ``support_mask``, the support plan) and the references of the tasks
that only a behaviour drives (a CM acceleration, a swing foot, the feet in flight). The host
applies them over the parameters in force for that tick only: what a client reads back are
its own parameters, and ending the behaviour (another ``behavior``) leaves them as they were.

A behaviour declares the parameters it reads (:attr:`Behavior.PARAMETERS`, merged into its
hosts' tables) and which controllers can host it (:attr:`Behavior.HOSTS`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from controller_server.behaviors.observation import Observation
from controller_server.features.swing_foot import SwingTarget
from controller_server.params import ParamSpec

if TYPE_CHECKING:
    from controller_server.models import RobotModel

__all__ = ["Behavior", "FeetFromCom", "Targets"]


@dataclass(frozen=True)
class FeetFromCom:
    """The reference of ``ankle`` (E_ankle, de Lasa §5): each foot held at an offset from the CM.

    Attributes:
        offsets_in_world: ``(contacts, 3)`` each contact frame's offset from the CM (m);
            ``None``: the orientations only (the feet have not left the ground yet).
        rotations_in_world: ``(contacts, 3, 3)`` each contact frame's rotation to hold.
    """

    offsets_in_world: np.ndarray | None
    rotations_in_world: np.ndarray


@dataclass(frozen=True)
class Targets:
    """What a behaviour asks of its host for one tick.

    Attributes:
        params: Host parameters by name, over the client's for this tick only. Validated
            as a ``set_params`` would be, once per :attr:`revision`.
        revision: Changes whenever :attr:`params` does.
        com_acceleration_xy: The CM acceleration ``com`` asks instead of its setpoint (m/s²,
            world x and y; still limited to what the supports can push), or ``None``.
        com_height_changes: How many times the behaviour has asked for a new ``com_height``
            to be reached by a target objective (eq. 6–7; a count, so that the host starts
            one at each new request, even for the height it holds).
        swing: The reference of ``swing`` (a swing foot's path), or ``None``.
        feet_from_com: The reference of ``ankle``, or ``None``.
        state: The behaviour's state (``stand``, ``compress`` … ``done``).
    """

    params: Mapping[str, Any]
    revision: int
    state: str
    com_height_changes: int = 0
    com_acceleration_xy: np.ndarray | None = None
    swing: SwingTarget | None = None
    feet_from_com: FeetFromCom | None = None


class Behavior(ABC):
    """A state machine that drives its host's tasks (one per session, from its first tick).

    Args:
        robot: The robot: what the behaviour derives from its model (its legs, spine, arms).

    Subclasses keep the parameter values they set in :attr:`overrides` (through
    :meth:`_set` and :meth:`_unset`, which count :attr:`revision`), count the CM heights
    they ask to reach in :attr:`com_height_changes`, and return both in every
    :class:`Targets` (:meth:`_targets`).
    """

    name: ClassVar[str]
    SUMMARY: ClassVar[str]
    """One line for the ``behavior`` parameter's documentation."""
    PARAMETERS: ClassVar[dict[str, ParamSpec]]
    HOSTS: ClassVar[tuple[str, ...]]
    """The controllers that can host it (their ``name``)."""

    def __init__(self, robot: RobotModel):
        self.robot = robot
        self.gravity = float(np.linalg.norm(robot.model.gravity.linear))
        """``g`` (m/s²), from the robot's model."""
        self.state = "stand"
        self.overrides: dict[str, Any] = {}
        self.revision = 0
        self.com_height_changes = 0

    @abstractmethod
    def update(self, observation: Observation, params: Mapping[str, Any]) -> Targets:
        """This tick's targets, from the tick and the parameters in force (its own included)."""

    def _set(self, **values: Any) -> None:
        """Set host parameters from this tick on (until changed or unset)."""
        if values:
            self.overrides.update(values)
            self.revision += 1

    def _unset(self, *names: str) -> None:
        """Give parameters back to the client's values."""
        if any(name in self.overrides for name in names):
            for name in names:
                self.overrides.pop(name, None)
            self.revision += 1

    def _targets(self, **references: Any) -> Targets:
        return Targets(
            self.overrides, self.revision, self.state, self.com_height_changes, **references
        )
