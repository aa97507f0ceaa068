"""The interface every physics backend of the simulator client implements.

A backend integrates one robot on flat ground (z = ``ground_height_m``,
normal +z, gravity −z) and speaks the wire conventions of
``docs/protocol.md``: base pose in world, quaternions scalar-last,
``linear_velocity_base_in_world``, ``angular_velocity_base_in_base``, joints
in Pinocchio/MJCF tree order (the order the server announces in
``welcome``; ball joints as quaternions xyzw of child in parent, their
velocities in the child frame). Two backends implement it: the reference
simulator (Pinocchio ABA with penalty contact) and MuJoCo.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from clients.state import RobotState
from protocol.messages import ContactSpec

__all__ = [
    "ContactPoint",
    "PhysicsBackend",
    "Push",
    "PushSpec",
    "StepReport",
    "physics_backend",
]


@dataclass(frozen=True)
class ContactPoint:
    """A foot contact point: the frame (MJCF site) it is fixed to and its offset there."""

    contact: str
    frame: str
    point_in_frame: tuple[float, float, float]


@dataclass(frozen=True)
class Push:
    """An external force on a body for a while (thesis ch. 7.1).

    Attributes:
        force_in_world_N: Force vector (N).
        body: MJCF body name it acts on.
        point_in_body_m: Application point in the body frame (m).
        start_s: Simulation time it starts (s).
        duration_s: How long it lasts (s).
    """

    force_in_world_N: tuple[float, float, float]
    body: str
    point_in_body_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    start_s: float = 0.0
    duration_s: float = 0.1

    def active(self, time_s: float) -> bool:
        """Whether the push acts at ``time_s``."""
        return self.start_s <= time_s < self.start_s + self.duration_s


class PushSpec(BaseModel):
    """An external push (thesis ch. 7.1)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    body: str = Field(
        description="Body the force acts on, e.g. `chest`; `trunk` is the robot's heaviest "
        "segment outside the legs and `root` its root body (as are `chest`, `torso`, "
        "`abdomen` and `pelvis` on a robot without a body of that name)."
    )
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


@dataclass
class StepReport:
    """What happened in one physics step (for metrics)."""

    contact_flags: list[bool] = field(default_factory=list)
    non_foot_contact: bool = False


class PhysicsBackend(Protocol):
    """One robot, one flat ground, fixed time step."""

    name: str
    time_s: float
    timestep_s: float
    conversions: list[str]
    """What the backend changed in the model file to simulate what the server controls."""

    def reset(self, state: RobotState) -> None:
        """Put the robot in ``state`` at time 0 (velocities included)."""

    def state(self) -> RobotState:
        """Current state in wire conventions."""

    def contact_flags(self) -> list[bool]:
        """Per contact (welcome order): does any of its points touch the ground."""

    def contact_wrenches_in_world(self) -> np.ndarray:
        """``(contacts, 6)`` ground force and torque about each contact frame origin (N, N·m)."""

    def step(self, joint_torque: np.ndarray, pushes: list[Push]) -> StepReport:
        """Advance one time step with these joint torques (wire order) and active pushes."""


def physics_backend(
    backend: str,
    model: str,
    physics_rate_hz: float,
    friction_coefficient: float,
    *,
    contacts: list[ContactSpec] | None = None,
    keyframe: str | None = None,
    mujoco_contact_time_constant_s: float | None = None,
) -> PhysicsBackend:
    """A backend by name (``reference`` or ``mujoco``) for ``model``, at a rate and friction.

    ``mujoco_contact_time_constant_s`` is MuJoCo's floor contact time constant (``None``: the
    model's); the reference simulator has its own penalty contact and ignores it.
    """
    options: dict[str, Any] = {
        "friction_coefficient": friction_coefficient,
        "timestep_s": 1.0 / physics_rate_hz,
        "contacts": contacts,
        "keyframe": keyframe,
    }
    if backend == "mujoco":
        from clients.physics.mujoco_backend import MujocoBackend

        return MujocoBackend(
            model, contact_time_constant_s=mujoco_contact_time_constant_s, **options
        )
    from clients.physics.reference import ReferenceBackend

    return ReferenceBackend(model, **options)
