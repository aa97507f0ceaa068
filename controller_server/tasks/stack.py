"""The task stack: the tasks a controller solves, by name, each with a weight and a level.

One stack type serves both controllers (TSID's ``addMotionTask(task, weight, level)``).
The weighted controller (Macchietto 2008, eq. 4.1) sums every task's rows with its weight
and ignores levels; the prioritized controller (de Lasa et al. 2010, Algorithm 1) groups
the tasks by level, weighs them within it (eq. 37) and solves the levels in order.

Tasks are added, removed, re-weighted and re-ranked at run time by name. A controller
keeps the weights and levels of its own tasks equal to its ``weight_<name>`` and
``priority_<name>`` parameters (:meth:`TaskStack.follow`), so ``set_params`` addresses
the tasks by name; a task added at run time (a point target) brings its own weight.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller_server.features import Objective
from controller_server.tasks.task import Task, Tick

__all__ = ["Slot", "SolvedTask", "TaskStack"]


@dataclass
class Slot:
    """A task on the stack: its weight α (eq. 16, 37; β of eq. 5.1) and its priority level."""

    task: Task
    weight: float = 1.0
    level: int = 1


@dataclass(frozen=True)
class SolvedTask:
    """One task's rows at one tick, with the slot it came from.

    ``active``: whether any row has a positive weight (an inactive task is reported, not solved).
    """

    slot: Slot
    objective: Objective
    active: bool

    @property
    def name(self) -> str:
        """The task's name."""
        return self.slot.task.name


class TaskStack:
    """Tasks by name, in the order they were added (the order their rows are stacked in)."""

    def __init__(self, slots: Mapping[str, Slot] | None = None):
        self._slots: dict[str, Slot] = dict(slots or {})

    def add(self, task: Task, weight: float = 1.0, level: int = 1) -> None:
        """Add ``task``, or replace the task of the same name in its place."""
        self._slots[task.name] = Slot(task, float(weight), int(level))

    def remove(self, name: str) -> None:
        """Remove the task ``name`` (nothing if there is none)."""
        self._slots.pop(name, None)

    def reweight(self, name: str, weight: float) -> None:
        """Set the weight of task ``name`` (0: reported but not solved)."""
        self._slots[name].weight = float(weight)

    def rerank(self, name: str, level: int) -> None:
        """Move task ``name`` to priority ``level`` (1 is the highest)."""
        self._slots[name].level = int(level)

    def follow(self, params: Mapping[str, Any]) -> None:
        """Take every weight and level that ``params`` gives by name."""
        for name, slot in self._slots.items():
            weight, level = params.get(f"weight_{name}"), params.get(f"priority_{name}")
            if weight is not None:
                slot.weight = float(weight)
            if level is not None:
                slot.level = int(level)

    def reset(self) -> None:
        """Every task forgets what it derived from the parameters (they changed)."""
        for slot in self._slots.values():
            slot.task.reset()

    def __contains__(self, name: object) -> bool:
        return name in self._slots

    def __getitem__(self, name: str) -> Slot:
        return self._slots[name]

    def __iter__(self) -> Iterator[Slot]:
        return iter(self._slots.values())

    def __len__(self) -> int:
        return len(self._slots)

    def names(self) -> list[str]:
        """The tasks' names, in stack order."""
        return list(self._slots)

    def solve_rows(self, tick: Tick, block: str | None = None) -> list[SolvedTask]:
        """Every task's rows at ``tick`` (over ``block``, if given), in stack order.

        A task with no rows this tick is left out; one whose rows all weigh 0 is kept,
        inactive, for its residual.
        """
        solved = []
        for slot in self._slots.values():
            task = slot.task
            if block is not None and task.block != block:
                continue
            objective = task.rows(tick, slot.weight)
            if objective is None:
                continue
            active = slot.weight > 0 if task.uniform else bool(np.any(objective.weight > 0))
            solved.append(SolvedTask(slot, objective, active))
        return solved
