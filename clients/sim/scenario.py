"""Scenario files: what to simulate, validated by pydantic.

A scenario is a TOML file naming the model, the controller and its
parameters, the backend, friction, duration, control and physics rates,
the initial pose, the pushes and timed parameter changes (a motion clip
starting, a weight shift, a foot leaving the supports, point targets
dragged). Built-in scenarios (thesis ch. 7) live in
``clients/sim/scenarios/`` and load by name.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from clients.sim.backend import Push

__all__ = ["SCENARIO_DIR", "ParamChange", "PushSpec", "Scenario", "load_scenario"]

SCENARIO_DIR = Path(__file__).parent / "scenarios"


class PushSpec(BaseModel):
    """An external push (thesis ch. 7.1)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    body: str = Field(description="MJCF body the force acts on, e.g. `chest`.")
    force_in_world_N: tuple[float, float, float] = Field(description="Force (N), world axes.")
    point_in_body_m: tuple[float, float, float] = Field(
        default=(0.0, 0.0, 0.0), description="Application point in the body frame (m)."
    )
    start_s: float = Field(ge=0.0, description="Start time (s).")
    duration_s: float = Field(gt=0.0, le=10.0, description="Duration (s).")

    def to_push(self) -> Push:
        """The backend's push."""
        return Push(
            self.force_in_world_N, self.body, self.point_in_body_m, self.start_s, self.duration_s
        )


class ParamChange(BaseModel):
    """Controller parameters sent (``set_params``) at the first control tick at or after a time."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    time_s: float = Field(ge=0.0, description="When (s of simulated time).")
    params: dict[str, Any] = Field(description="Parameters to set, as in `set_params`.")


class Scenario(BaseModel):
    """One simulated run."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = Field(description="Scenario name (report and plot titles).")
    description: str = Field(default="", description="What it shows.")
    model: str = Field(default="thesis_humanoid", description="Built-in model or MJCF path.")
    controller: str = Field(default="momentum", description="Server controller.")
    params: dict[str, Any] = Field(default_factory=dict, description="Controller parameters.")
    backend: Literal["reference", "mujoco"] = Field(default="reference")
    friction_coefficient: float = Field(default=0.8, gt=0.0, le=5.0)
    duration_s: float = Field(default=3.0, gt=0.0, le=600.0)
    control_rate_hz: float = Field(default=1000.0, gt=0.0, le=10_000.0)
    physics_rate_hz: float = Field(default=1000.0, gt=0.0, le=100_000.0)
    command_delay_ticks: Literal[0, 1] = Field(
        default=0,
        description="0: lockstep, each state's command drives the physics from that tick. "
        "1: pipelined, the command for the state of tick k drives the physics from tick k + 1, "
        "and the simulator steps while the server computes (one control period of latency, as "
        "between sensing and actuation on hardware); the state sent is then the one predicted "
        "for tick k + 1 with the accelerations of the command acting meanwhile.",
    )
    diagnostics_period_ticks: int = Field(
        default=1,
        ge=1,
        le=1000,
        description="Diagnostics with every N-th command (hello.diagnostics_period_ticks); "
        "the metrics and plots use the ticks that have them.",
    )
    ground_force_mode: Literal["distributed", "measured"] = Field(default="distributed")
    support_force_threshold_N: float = Field(
        default=20.0,
        ge=0.0,
        description="A touching foot becomes a support once its normal force exceeds this (N); "
        "it stays one until it lifts off.",
    )
    initial_joint_position: dict[str, list[float]] = Field(
        default_factory=dict, description="Joint name → position (rad; ball: xyzw) at t = 0."
    )
    pushes: list[PushSpec] = Field(default_factory=list)
    param_changes: list[ParamChange] = Field(
        default_factory=list, description="Run-time parameter changes, in time order."
    )

    @model_validator(mode="after")
    def _rates(self) -> Scenario:
        ratio = self.physics_rate_hz / self.control_rate_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(
                f"physics_rate_hz ({self.physics_rate_hz}) must be a whole multiple of "
                f"control_rate_hz ({self.control_rate_hz})"
            )
        return self

    @model_validator(mode="after")
    def _changes_in_order(self) -> Scenario:
        times = [change.time_s for change in self.param_changes]
        if times != sorted(times):
            raise ValueError(f"param_changes must be in time order, got times {times}")
        return self

    @property
    def physics_steps_per_control_tick(self) -> int:
        """Physics steps between two control ticks (zero-order hold of the torques)."""
        return round(self.physics_rate_hz / self.control_rate_hz)


def load_scenario(name_or_path: str | Path, **overrides: Any) -> Scenario:
    """Load a scenario by built-in name or TOML path, with field overrides."""
    path = Path(name_or_path)
    if not path.suffix:
        path = SCENARIO_DIR / f"{name_or_path}.toml"
    if not path.is_file():
        available = sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))
        raise FileNotFoundError(f"no scenario {str(name_or_path)!r}; built in: {available}")
    data = tomllib.loads(path.read_text())
    data.update(overrides)
    return Scenario.model_validate(data)
