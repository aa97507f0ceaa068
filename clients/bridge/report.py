"""What a bridge run reports: its tick timing, each actuator's link quality, why it stopped.

The loop (:mod:`clients.bridge.loop`) fills a :class:`BridgeReport` tick by tick; ``poise
bridge`` prints its status lines from it and writes it as ``report.json``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from clients.bridge.actuator import MotorFeedback

__all__ = ["BridgeReport", "JointLink", "LoopTiming"]


@dataclass
class LoopTiming:
    """Tick periods measured on the wall clock (``time.perf_counter``)."""

    ticks: int = 0
    overruns: int = 0
    period_sum_s: float = 0.0
    period_squares_s2: float = 0.0
    period_max_s: float = 0.0
    work_max_s: float = 0.0

    def add(self, period_s: float, work_s: float) -> None:
        """One tick: time since the previous tick's start, and its own work."""
        self.ticks += 1
        self.period_sum_s += period_s
        self.period_squares_s2 += period_s * period_s
        self.period_max_s = max(self.period_max_s, period_s)
        self.work_max_s = max(self.work_max_s, work_s)

    @property
    def period_mean_s(self) -> float:
        """Mean period."""
        return self.period_sum_s / self.ticks if self.ticks else math.nan

    @property
    def jitter_s(self) -> float:
        """Standard deviation of the period."""
        if self.ticks < 2:
            return math.nan
        mean = self.period_mean_s
        return math.sqrt(max(0.0, self.period_squares_s2 / self.ticks - mean * mean))


@dataclass
class JointLink:
    """Link quality of one joint's actuator."""

    joint: str
    bus: str
    id: int
    replies: int = 0
    missed: int = 0
    faults: int = 0
    last_fault: str = ""
    temperature_C: float = math.nan
    temperature_max_C: float = math.nan

    def add(self, reply: MotorFeedback | None) -> None:
        """Count one tick's reply."""
        if reply is None:
            self.missed += 1
            return
        self.replies += 1
        if reply.fault:
            self.faults += 1
            self.last_fault = reply.fault
        if reply.temperature_C is not None:
            self.temperature_C = reply.temperature_C
            self.temperature_max_C = np.fmax(self.temperature_max_C, reply.temperature_C)


@dataclass
class BridgeReport:
    """What a run did: ticks, timing, link quality, and why it stopped or latched."""

    timing: LoopTiming = field(default_factory=LoopTiming)
    links: list[JointLink] = field(default_factory=list)
    commands: int = 0
    invalid_commands: int = 0
    server_timeouts: int = 0
    clamped_torques: int = 0
    latches: list[str] = field(default_factory=list)
    """Every reason the safe state latched, in order."""
    stopped: str = ""
    """Why the run ended: ``"duration"``, ``"quit"``, ``"estop"``, ``"interrupted"``."""

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready summary (``report.json``)."""
        timing = self.timing
        return {
            "ticks": timing.ticks,
            "period_mean_ms": _finite(1e3 * timing.period_mean_s),
            "jitter_ms": _finite(1e3 * timing.jitter_s),
            "period_max_ms": 1e3 * timing.period_max_s,
            "work_max_ms": 1e3 * timing.work_max_s,
            "overruns": timing.overruns,
            "commands": self.commands,
            "invalid_commands": self.invalid_commands,
            "server_timeouts": self.server_timeouts,
            "clamped_torques": self.clamped_torques,
            "latches": self.latches,
            "stopped": self.stopped,
            "links": [
                {key: None if value != value else value for key, value in vars(link).items()}
                for link in self.links
            ],  # NaN (no temperature reported) → null
        }


def _finite(value: float) -> float | None:
    """``value``, or ``None`` when it is not finite (JSON has no NaN)."""
    return value if math.isfinite(value) else None
