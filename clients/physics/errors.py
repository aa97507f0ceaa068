"""Errors of the simulated robot and of the scenario files that say what to simulate."""

from __future__ import annotations

from protocol.errors import PoiseError

__all__ = ["ScenarioError", "ScenarioNotFound", "SimulationDiverged", "UnsupportedModel"]


class ScenarioError(PoiseError, ValueError):
    """A scenario a user wrote cannot run; the one-line message says what to change."""


class ScenarioNotFound(ScenarioError, FileNotFoundError):
    """No built-in scenario of that name and no such file; the message lists the built-ins."""


class UnsupportedModel(PoiseError, ValueError):
    """A model file uses something a backend cannot simulate; the message says what."""


class SimulationDiverged(PoiseError, FloatingPointError):
    """A step produced a non-finite (or, in MuJoCo, huge) state.

    Attributes:
        backend: Which backend diverged.
        time_s: Simulation time at the start of the failed step (s).
    """

    def __init__(self, backend: str, time_s: float, detail: str):
        self.backend = backend
        self.time_s = time_s
        super().__init__(f"{backend}: the state diverged in the step at {time_s=:.4f}; {detail}")
