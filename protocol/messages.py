"""Message models of the Poise wire protocol.

One pydantic model per message ``type``. Every message carries ``version``
(:data:`PROTOCOL_VERSION`) and ``seq``; every reply echoes the ``seq`` of its
request. Conventions (ARCHITECTURE.md): SI units, world frame z up, base pose
in world, quaternions scalar-last ``[x, y, z, w]``, joint order as announced
in ``welcome``. ``docs/protocol.md`` tables every key; it is generated from
these models' field descriptions (``python -m protocol.docgen``).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from protocol.arrays import FiniteArray, FloatArray, QuaternionXYZW, Vector3
from protocol.errors import ErrorCode

__all__ = [
    "MESSAGE_TYPES",
    "PROTOCOL_VERSION",
    "Bye",
    "Command",
    "ContactSpec",
    "Diagnostics",
    "Error",
    "Hello",
    "JointInfo",
    "Message",
    "Params",
    "SessionStats",
    "SetParams",
    "State",
    "Stats",
    "Welcome",
]

PROTOCOL_VERSION = 1
"""Version of this wire contract; a message with another version is refused."""

ParamValue = float | int | bool | str | list[float]

Seq = Annotated[int, Field(ge=0, le=2**63 - 1, description="Request sequence number.")]


class Message(BaseModel):
    """Fields every message carries."""

    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)

    type: str = Field(description="Message type name.")
    version: int = Field(
        default=PROTOCOL_VERSION, description="Protocol version; must equal the server's."
    )
    seq: Seq = 0


class ContactSpec(BaseModel):
    """A foot (or other support) and the points through which it touches the ground."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = Field(description="Contact name, e.g. `left_foot`.")
    frame: str = Field(description="Model frame the points are expressed in, e.g. `left_sole`.")
    points_in_frame: list[tuple[float, float, float]] = Field(
        min_length=1,
        description="Contact points (m) in `frame`; the corners of the sole rectangle.",
    )
    friction_coefficient: float = Field(
        default=0.8, gt=0.0, le=10.0, description="Coulomb friction coefficient μ (1)."
    )

    @model_validator(mode="after")
    def _finite_points(self) -> ContactSpec:
        for point in self.points_in_frame:
            if not all(abs(c) < 1e6 for c in point):
                raise ValueError(f"contact points must be finite and < 1e6 m, got {point}")
        return self


class Hello(Message):
    """Open a session: pick the robot model and the controller."""

    type: Literal["hello"] = "hello"
    model: str | None = Field(
        default=None,
        description="Built-in model name (`thesis_humanoid`, …) or a path on the server.",
    )
    model_text: str | None = Field(
        default=None, max_length=8_000_000, description="Model file text sent by the client."
    )
    model_format: Literal["mjcf", "urdf"] = Field(
        default="mjcf", description="Format of `model_text` (and of `model` if a path)."
    )
    contacts: list[ContactSpec] | None = Field(
        default=None,
        description="Contact definitions; default: every `*_sole` box site of an MJCF model.",
    )
    controller: str = Field(default="tracking", description="Controller name.")
    params: dict[str, ParamValue] = Field(
        default_factory=dict, description="Initial controller parameters (see `params`)."
    )
    expected_model_hash: str | None = Field(
        default=None, description="If set, the server refuses a model with another hash."
    )
    client_name: str = Field(default="", max_length=200, description="Free text for logs.")

    @model_validator(mode="after")
    def _one_model_source(self) -> Hello:
        if (self.model is None) == (self.model_text is None):
            raise ValueError("give exactly one of `model` (name or path) and `model_text`")
        return self


class JointInfo(BaseModel):
    """One actuated joint, in wire order."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = Field(description="Joint name from the model file.")
    kind: Literal["revolute", "prismatic", "ball"] = Field(description="Joint kind.")
    nq: int = Field(description="Entries in `joint_position` (ball: 4, quaternion xyzw).")
    nv: int = Field(description="Entries in `joint_velocity`, `joint_torque` (ball: 3).")
    torque_limit: list[float] = Field(
        description="Symmetric torque limit per DoF (N·m or N), length `nv`."
    )
    position_lower: list[float] | None = Field(
        description="Lower position limit (rad or m), `null` for ball joints."
    )
    position_upper: list[float] | None = Field(
        description="Upper position limit (rad or m), `null` for ball joints."
    )


class Welcome(Message):
    """Reply to ``hello``: what the server will control, so mismatches fail now."""

    type: Literal["welcome"] = "welcome"
    session_id: str = Field(description="Server-chosen session identifier.")
    model_name: str = Field(description="Model name.")
    model_hash: str = Field(description="SHA-256 of the model text and contact definitions.")
    total_mass: float = Field(description="Total mass (kg).")
    standing_position_base_in_world: tuple[float, float, float] = Field(
        description="Base position (m) at which the neutral pose stands on z = 0."
    )
    joints: list[JointInfo] = Field(description="Actuated joints in wire order.")
    contacts: list[ContactSpec] = Field(description="Contacts in `contact_flags` order.")
    controller: str = Field(description="Controller serving this session.")
    params: dict[str, ParamValue] = Field(description="Controller parameters in force.")


class State(Message):
    """Robot state measured by the client at ``time_s``."""

    type: Literal["state"] = "state"
    time_s: float = Field(allow_inf_nan=False, description="Client time (s).")
    joint_position: FiniteArray = Field(
        description="Joint positions (rad, m; ball: quaternion xyzw), wire order, Σ nq."
    )
    joint_velocity: FiniteArray = Field(
        description="Joint velocities (rad/s, m/s; ball: in child frame), Σ nv."
    )
    position_base_in_world: Vector3 = Field(description="Base (root body) origin in world (m).")
    orientation_base_in_world_xyzw: QuaternionXYZW = Field(
        description="Base orientation in world, scalar last (normalised by the server)."
    )
    linear_velocity_base_in_world: Vector3 = Field(
        description="Velocity of the base origin, in world axes (m/s)."
    )
    angular_velocity_base_in_base: Vector3 = Field(
        description="Base angular velocity, in base axes (rad/s)."
    )
    contact_flags: list[bool] = Field(
        description="Per contact (welcome order): is it a support this tick."
    )


class Diagnostics(BaseModel):
    """What the controller did this tick (for logs and plots)."""

    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)

    compute_time_s: float = Field(description="Server time spent on this tick (s).")
    position_com_in_world: Vector3 = Field(description="Centre of mass (m).")
    kkt_condition_number: float = Field(
        description="Condition number of the KKT Schur complement (1)."
    )
    root_wrench_residual: float = Field(
        description="Norm of the root wrench the contact forces could not balance (N, N·m)."
    )
    saturated_joints: int = Field(description="DoFs whose torque hit its limit.")


class Command(Message):
    """Reply to ``state``: accelerations and torques for that state."""

    type: Literal["command"] = "command"
    joint_acceleration: FloatArray = Field(description="Joint accelerations (rad/s², m/s²), Σ nv.")
    base_linear_acceleration_in_world: FloatArray = Field(
        description="Acceleration of the base origin, world axes (m/s²), 3."
    )
    base_angular_acceleration_in_base: FloatArray = Field(
        description="Base angular acceleration, base axes (rad/s²), 3."
    )
    joint_torque: FloatArray = Field(description="Joint torques (N·m, N), Σ nv.")
    contact_force_in_world: FloatArray = Field(
        description="Force at each contact point (N), world axes, contacts × points × 3."
    )
    diagnostics: Diagnostics = Field(description="See the diagnostics table.")


class SetParams(Message):
    """Change controller parameters of this session at run time."""

    type: Literal["set_params"] = "set_params"
    params: dict[str, ParamValue] = Field(description="Parameter name → new value.")


class Params(Message):
    """Reply to ``set_params``: every parameter now in force."""

    type: Literal["params"] = "params"
    params: dict[str, ParamValue] = Field(description="Parameter name → value in force.")


class SessionStats(BaseModel):
    """Per-session counters in a ``stats`` reply."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    session_id: str = Field(description="Session identifier.")
    model_name: str = Field(description="Model of the session.")
    controller: str = Field(description="Controller of the session.")
    ticks: int = Field(description="`state` messages answered with a `command`.")
    errors: int = Field(description="Requests answered with an `error`.")
    compute_time_p50_s: float = Field(description="Median compute time, last 1000 ticks (s).")
    compute_time_p99_s: float = Field(description="99th-percentile compute time (s).")
    idle_s: float = Field(description="Time since the last request (s).")


class Stats(Message):
    """Request (no ``sessions``) or reply (with ``sessions``) of server statistics."""

    type: Literal["stats"] = "stats"
    sessions: list[SessionStats] | None = Field(
        default=None, description="Reply only: one entry per live session."
    )


class Bye(Message):
    """Close this client's session; the server answers ``bye``."""

    type: Literal["bye"] = "bye"


class Error(Message):
    """Reply to a request the server could not serve."""

    type: Literal["error"] = "error"
    seq: int = Field(default=-1, ge=-1, description="Seq of the bad request, -1 if unreadable.")
    code: ErrorCode = Field(description="`ErrorCode` value (see the error table).")
    field: str = Field(default="", description="Dotted path of the offending key.")
    detail: str = Field(description="What is wrong, with the bad value.")


MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.model_fields["type"].default: cls
    for cls in (Hello, Welcome, State, Command, SetParams, Params, Stats, Bye, Error)
}
"""Message classes by their ``type`` string."""
