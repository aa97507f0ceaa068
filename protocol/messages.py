"""Message models of the Poise wire protocol.

One pydantic model per message ``type``. Every message carries ``version``
(:data:`PROTOCOL_VERSION`) and ``seq``; every reply echoes the ``seq`` of its
request. Conventions (docs/architecture.md): SI units, world frame z up, base pose
in world, quaternions scalar-last ``[x, y, z, w]``, joint order as announced
in ``welcome``. Every field declares its shape, unit and frame, and
``docs/protocol.md`` is generated from them (``python -m protocol.docgen``).
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StringConstraints,
    WithJsonSchema,
    model_validator,
)

from protocol.arrays import (
    MAX_ABS_ACCELERATION,
    MAX_ABS_JOINT_POSITION,
    MAX_ABS_POSITION_M,
    MAX_ABS_TIME_S,
    MAX_ABS_VELOCITY,
    MAX_ABS_WRENCH,
    Acceleration3,
    FloatArray,
    JointPositionArray,
    Position3,
    QuaternionXYZW,
    Vector3,
    Velocity3,
    VelocityArray,
    WrenchArray,
)
from protocol.errors import ErrorCode

__all__ = [
    "BASE_POSE_FIELDS",
    "MAX_ABS_ACCELERATION",
    "MAX_ABS_JOINT_POSITION",
    "MAX_ABS_POSITION_M",
    "MAX_ABS_TIME_S",
    "MAX_ABS_VELOCITY",
    "MAX_ABS_WRENCH",
    "MAX_CONTACTS",
    "MAX_CONTACT_POINTS",
    "MAX_MODEL_FILES",
    "MAX_POINTS_PER_CONTACT",
    "MESSAGE_TYPES",
    "PROTOCOL_VERSION",
    "Asset",
    "AssetReceived",
    "BaseEstimateDiagnostics",
    "Bye",
    "Command",
    "ContactSpec",
    "Diagnostics",
    "Error",
    "Hello",
    "ImuSample",
    "JointInfo",
    "Message",
    "Params",
    "PrioritizedDiagnostics",
    "PriorityLevelReport",
    "SessionStats",
    "SetParams",
    "Sha256Hex",
    "State",
    "Stats",
    "WeightedDiagnostics",
    "Welcome",
    "wire_field",
]

PROTOCOL_VERSION = 2
"""Version of this wire contract; a message with another version is refused.

An addition that leaves every message of the version valid (a new optional key, a new
message type, a new error code) keeps the version; a change that makes an old message
invalid or mean something else takes the next one."""

MAX_MODEL_FILES = 512
"""Files a ``hello`` may name with its model, inline and by hash together."""

MAX_CONTACTS = 16
"""Contacts of one session (a ``hello``'s, or found in its model): feet, hands, knees."""
MAX_POINTS_PER_CONTACT = 32
"""Points of one contact: a sole polygon (real feet take 4–8)."""
MAX_CONTACT_POINTS = 64
"""Points of all the contacts of one session together.

Each point adds force unknowns to every tick's QPs, whose cost grows faster than
the points: on the 28-DoF built-in robot a ``momentum`` tick took 1.3 ms standing at
2 × 16 points, 7.5 ms at 2 × 32 (25 ms on other states), 38 ms at 2 × 64 (0.17–1 s
on other states) and over 5 s at 2 × 5,000 (docs/serving.md)."""

ParamValue = float | int | bool | str | list[float] | dict[str, float | str | list[float]] | None
"""A controller parameter: a number, flag, name, vector, a small record
(e.g. a point target), or ``null`` (remove, e.g. a point target)."""


LoggedBytes = Annotated[bytes, WithJsonSchema({"type": "string", "contentEncoding": "base64"})]
"""A file's bytes: binary on the wire (msgpack), base64 in a JSON log (protocol.recording)."""

Sha256Hex = Annotated[str, StringConstraints(pattern=r"^[0-9a-f]{64}$")]
"""A SHA-256 digest as 64 lowercase hexadecimal characters (``hashlib``'s ``hexdigest``)."""


def wire_field(
    description: str, *, shape: str = "", unit: str = "", frame: str = "", **kwargs: Any
) -> Any:
    """A pydantic ``Field`` that also records shape, unit and frame for the docs."""
    return Field(
        description=description,
        json_schema_extra={"shape": shape, "unit": unit, "frame": frame},
        **kwargs,
    )


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)


class Message(_Strict):
    """Fields every message carries."""

    type: str = wire_field("Message type name.")
    version: int = wire_field(
        "Protocol version; must equal the server's.", default=PROTOCOL_VERSION
    )
    seq: int = wire_field(
        "Request sequence number; replies echo it.", default=0, ge=0, le=2**63 - 1, strict=True
    )


class ContactSpec(_Strict):
    """A foot (or other support) and the points through which it touches the ground."""

    name: str = wire_field("Contact name, e.g. `left_foot`.", max_length=200)
    frame: str = wire_field(
        "Model frame the points are expressed in, e.g. `left_sole`.", max_length=200
    )
    points_in_frame: list[tuple[float, float, float]] | None = wire_field(
        "Contact points: the corners of the sole rectangle. In `hello`, leave it out to have "
        "the server find the sole from the collision geometry of the frame's body and its "
        "descendants (docs/models.md); `welcome` always gives the points. At most "
        f"{MAX_POINTS_PER_CONTACT} per contact, {MAX_CONTACT_POINTS} over all contacts.",
        shape="k × 3",
        unit="m",
        frame="`frame`",
        default=None,
        min_length=1,
        max_length=MAX_POINTS_PER_CONTACT,
    )
    friction_coefficient: float = wire_field(
        "Coulomb friction coefficient μ.", unit="1", default=0.8, gt=0.0, le=10.0
    )

    @model_validator(mode="after")
    def _finite_points(self) -> ContactSpec:
        for point in self.points_in_frame or ():
            if not all(abs(c) < 1e6 for c in point):
                raise ValueError(f"contact points must be finite and < 1e6 m, got {point}")
        return self


class Hello(Message):
    """Open a session: pick the robot model and the controller."""

    type: Literal["hello"] = "hello"
    model: str | None = wire_field(
        "Built-in model name (`thesis_humanoid`, `revolute_humanoid`, `dino_biped`) or a "
        "file in one of the server's model directories (`poise serve --model-dir`), by its "
        "path or its name relative to the directory.",
        default=None,
    )
    model_text: str | None = wire_field(
        "Model file text sent by the client (instead of `model`).",
        default=None,
        max_length=8_000_000,
    )
    model_format: Literal["mjcf", "urdf"] = wire_field(
        "Format of `model_text` (a `model` path ending in `.urdf` is URDF).", default="mjcf"
    )
    model_assets: dict[str, LoggedBytes] | None = wire_field(
        "Files `model_text` names (`<include>`d MJCF, meshes), by the path it names them "
        'with, relative to its directory, e.g. `{"robot.xml": …, "assets/foot.stl": …}`. '
        "A sent model reads no other file.",
        default=None,
        max_length=MAX_MODEL_FILES,
    )
    model_asset_hashes: dict[str, Sha256Hex] | None = wire_field(
        "Files `model_text` names, as `model_assets` but by the SHA-256 of their bytes "
        '(lowercase hex), e.g. `{"assets/foot.stl": "9f86d0…"}`: the server takes them from '
        "its asset cache, where this client put them with `asset`. Unknown ones get "
        "`ASSETS_MISSING` listing them. So the hello stays small whatever the files' size, "
        "and a file is sent once per server. A path is in at most one of the two maps; "
        f"together at most {MAX_MODEL_FILES} files.",
        default=None,
        max_length=MAX_MODEL_FILES,
    )
    contacts: list[ContactSpec] | None = wire_field(
        "Contact definitions (see ContactSpec), at most "
        f"{MAX_CONTACTS} with {MAX_CONTACT_POINTS} points together. Default: every `*_sole` "
        "box site of an MJCF, else the feet found from the collision geometry (docs/models.md).",
        default=None,
        max_length=MAX_CONTACTS,
    )
    keyframe: str | None = wire_field(
        "MJCF keyframe (`<key name>`) of the standing pose: it sets the standing base pose and "
        "joints, the reference pose and the CM height. Default: the file's pose.",
        default=None,
        max_length=200,
    )
    controller: str = wire_field(
        "Controller: `momentum` (default; Macchietto 2008, every objective), `prioritized` "
        "(de Lasa 2010) or `tracking` (tracking only, the ablation baseline).",
        default="momentum",
    )
    params: dict[str, ParamValue] = wire_field(
        "Initial controller parameters (see the parameter table).", default_factory=dict
    )
    expected_model_hash: str | None = wire_field(
        "If set, the server refuses a model whose hash differs.", default=None
    )
    client_name: str = wire_field("Free text for the server's logs.", default="", max_length=200)
    diagnostics_period_ticks: int = wire_field(
        "Diagnostics come with the command of every N-th state of the session (the first "
        "included); the commands between carry none, and the server skips computing them.",
        default=1,
        ge=1,
        le=10_000,
    )
    imu_frame: str | None = wire_field(
        "Model frame (a body or any frame of the model) the IMU of `state.imu` is fixed to; "
        "it must be rigidly attached to the root body. Default: the root body.",
        default=None,
        max_length=200,
    )
    imu_position_in_frame: tuple[float, float, float] = wire_field(
        "IMU origin in `imu_frame`, each |x| ≤ 10.",
        shape="3",
        unit="m",
        frame="`imu_frame`",
        default=(0.0, 0.0, 0.0),
    )
    imu_orientation_in_frame_xyzw: tuple[float, float, float, float] = wire_field(
        "IMU axes in `imu_frame`, quaternion scalar last (normalised; norm within 10 % of 1).",
        shape="4",
        frame="`imu_frame`",
        default=(0.0, 0.0, 0.0, 1.0),
    )

    @model_validator(mode="after")
    def _imu_mount(self) -> Hello:
        if not all(math.isfinite(x) and abs(x) <= 10.0 for x in self.imu_position_in_frame):
            raise ValueError(
                f"imu_position_in_frame must be finite and within 10 m, got "
                f"{list(self.imu_position_in_frame)}"
            )
        norm = math.sqrt(sum(c * c for c in self.imu_orientation_in_frame_xyzw))
        if not abs(norm - 1.0) <= 0.1:
            raise ValueError(
                f"imu_orientation_in_frame_xyzw must be a unit quaternion xyzw, got "
                f"{list(self.imu_orientation_in_frame_xyzw)} (norm {norm:.3g})"
            )
        return self

    @model_validator(mode="after")
    def _contact_points(self) -> Hello:
        total = sum(len(c.points_in_frame or ()) for c in self.contacts or ())
        if total > MAX_CONTACT_POINTS:
            raise ValueError(
                f"contacts have {total} points together; at most {MAX_CONTACT_POINTS} (each "
                "point adds unknowns to every tick's QPs)"
            )
        return self

    @model_validator(mode="after")
    def _one_model_source(self) -> Hello:
        if (self.model is None) == (self.model_text is None):
            raise ValueError("give exactly one of `model` (name or path) and `model_text`")
        return self

    @model_validator(mode="after")
    def _files_named_once(self) -> Hello:
        by_hash = self.model_asset_hashes or {}
        if by_hash and self.model_text is None:
            raise ValueError(
                "model_asset_hashes are files of a sent `model_text`; a `model` by name reads "
                "the server's own files"
            )
        both = sorted(set(by_hash) & set(self.model_assets or {}))
        if both:
            raise ValueError(f"{both[0]!r} is in both model_assets and model_asset_hashes")
        if len(by_hash) + len(self.model_assets or {}) > MAX_MODEL_FILES:
            raise ValueError(
                f"more than {MAX_MODEL_FILES} files in model_assets and model_asset_hashes together"
            )
        return self


class JointInfo(_Strict):
    """One actuated joint, in wire order."""

    name: str = wire_field("Joint name from the model file.")
    kind: Literal["revolute", "prismatic", "ball"] = wire_field("Joint kind.")
    nq: int = wire_field("Entries in `joint_position` (ball: 4, a quaternion xyzw).")
    nv: int = wire_field("Entries in `joint_velocity` and `joint_torque` (ball: 3).")
    torque_limit: list[float] = wire_field(
        "Symmetric torque limit per DoF.", shape="nv", unit="N·m (N)"
    )
    position_lower: list[float] | None = wire_field(
        "Lower position limit; `null` for ball joints.", shape="nq", unit="rad (m)"
    )
    position_upper: list[float] | None = wire_field(
        "Upper position limit; `null` for ball joints.", shape="nq", unit="rad (m)"
    )


class Welcome(Message):
    """Reply to ``hello``: what the server will control, so mismatches fail now."""

    type: Literal["welcome"] = "welcome"
    session_id: str = wire_field("Server-chosen session identifier.")
    model_name: str = wire_field("Model name.")
    model_hash: str = wire_field("SHA-256 of the model file text and the contact definitions.")
    total_mass: float = wire_field("Total mass.", unit="kg")
    standing_position_base_in_world: tuple[float, float, float] = wire_field(
        "Base position of the standing pose (`hello.keyframe`, else the file's pose), its "
        "lowest contact point on z = 0.",
        shape="3",
        unit="m",
        frame="world",
    )
    standing_orientation_base_in_world_xyzw: tuple[float, float, float, float] = wire_field(
        "Base orientation of the standing pose, quaternion scalar last.",
        shape="4",
        frame="world",
        default=(0.0, 0.0, 0.0, 1.0),
    )
    standing_joint_position: list[float] | None = wire_field(
        "Joint positions of the standing pose, wire order (ball joints: xyzw).",
        shape="nq",
        unit="rad, m",
        default=None,
    )
    joints: list[JointInfo] = wire_field("Actuated joints in wire order (see JointInfo).")
    contacts: list[ContactSpec] = wire_field("Contacts in `contact_flags` order.")
    controller: str = wire_field("Controller serving this session.")
    params: dict[str, ParamValue] = wire_field("Controller parameters in force.")


BASE_POSE_FIELDS = (
    "position_base_in_world",
    "orientation_base_in_world_xyzw",
    "linear_velocity_base_in_world",
    "angular_velocity_base_in_base",
)
"""The fields of a ``state`` that give the base directly; the other form is ``imu``."""


class ImuSample(_Strict):
    """One IMU reading, in the IMU frame announced in ``hello`` (``imu_frame`` and offset).

    Send the newest sample with each state; the server integrates it over the time since
    the previous state's ``time_s`` (a sample held over several states is integrated as held).
    """

    angular_velocity_imu_in_imu: Velocity3 = wire_field(
        "Gyroscope reading, each |ω| ≤ 1000.", shape="3", unit="rad/s", frame="IMU"
    )
    linear_acceleration_imu_in_imu: Acceleration3 = wire_field(
        f"Accelerometer reading: specific force a − g of the IMU point (+9.81 up at rest), "
        f"each |f| ≤ {MAX_ABS_ACCELERATION:g}.",
        shape="3",
        unit="m/s²",
        frame="IMU",
    )
    orientation_imu_in_world_xyzw: QuaternionXYZW | None = wire_field(
        "Optional orientation from the IMU's own filter (AHRS), scalar last; the estimator "
        "starts from it (and restarts from it after a reset); without it, it levels on the "
        "accelerometer with yaw zero.",
        shape="4",
        frame="world",
        default=None,
    )


class State(Message):
    """Robot state measured by the client at ``time_s``."""

    type: Literal["state"] = "state"
    time_s: float = wire_field(
        f"Client time, |t| ≤ {MAX_ABS_TIME_S:g}.",
        unit="s",
        allow_inf_nan=False,
        ge=-MAX_ABS_TIME_S,
        le=MAX_ABS_TIME_S,
    )
    joint_position: JointPositionArray = wire_field(
        "Joint positions in wire order, each |q| ≤ 1000; a ball joint is a quaternion xyzw of "
        "child in parent, unit length within 10 % (normalised by the server).",
        shape="Σ nq",
        unit="rad (m)",
        frame="joint",
    )
    joint_velocity: VelocityArray = wire_field(
        "Joint velocities in wire order, each |v| ≤ 1000; a ball joint's is in its child frame.",
        shape="Σ nv",
        unit="rad/s (m/s)",
        frame="joint",
    )
    position_base_in_world: Position3 | None = wire_field(
        "Base (root body) origin, each |x| ≤ 10⁴. The base is given either by this and the "
        "next three fields, or by `imu` (then these four are absent).",
        shape="3",
        unit="m",
        frame="world",
        default=None,
    )
    orientation_base_in_world_xyzw: QuaternionXYZW | None = wire_field(
        "Base orientation, scalar last; unit length within 10 %, normalised by the server.",
        shape="4",
        frame="world",
        default=None,
    )
    linear_velocity_base_in_world: Velocity3 | None = wire_field(
        "Velocity of the base origin, each |v| ≤ 1000.",
        shape="3",
        unit="m/s",
        frame="world",
        default=None,
    )
    angular_velocity_base_in_base: Velocity3 | None = wire_field(
        "Base angular velocity, each |ω| ≤ 1000.",
        shape="3",
        unit="rad/s",
        frame="base",
        default=None,
    )
    imu: ImuSample | None = wire_field(
        "Instead of the four base fields: the IMU reading at `time_s` (see the ImuSample "
        "table); the server estimates the base from it, the joints and `contact_flags`.",
        default=None,
    )
    contact_flags: list[bool] = wire_field(
        "Per contact (welcome order): is it a support this tick.", shape="contacts"
    )
    contact_wrench_in_world: WrenchArray | None = wire_field(
        "Measured ground wrench per contact (force, then torque about the contact frame "
        "origin), each entry ≤ 10⁶ in size; required in `ground_force_mode` `measured`.",
        shape="contacts × 6",
        unit="N, N·m",
        frame="world",
        default=None,
    )


class PriorityLevelReport(_Strict):
    """One priority level of the prioritized controller (de Lasa 2010, Algorithm 1)."""

    objectives: list[str] = wire_field("Objectives combined in this level (eq. 37).")
    status: str = wire_field(
        "`solved`, `infeasible` (the QP had no solution: the levels above are returned), "
        "`not reached` (no freedom left, or after an infeasible level) or `empty`."
    )
    residual: float = wire_field(
        "‖W^½ (A x − b)‖ at the returned x, the level scaled to ‖W^½ A‖_F = 1 "
        "(per objective, in its own units: `objective_residuals`)."
    )
    rank: int = wire_field(
        "Directions of A C̄ this level used: σ ≥ max(1/B, rounding floor), the level scaled."
    )
    null_space_dimension: int = wire_field("Freedom left to the levels below.")
    damping: float = wire_field("Damping λ of the level's solve (Maciejewski eq. 15).")
    used_qp: bool = wire_field("Whether an inequality was active, so a QP was solved.")


class WeightedDiagnostics(_Strict):
    """The weighted controllers' own diagnostics (`momentum`, `tracking`): App. D's solve."""

    optimizer_ran: bool = wire_field(
        "Whether the optimizer ran this tick (else the last accelerations were reused)."
    )
    angular_momentum_weight: float = wire_field(
        "β_ba = β_0 + γ ‖p − g‖ used this tick (eq. 5.17): p and g of the state's measured "
        "`contact_wrench_in_world` when it carries one, else of the previous command's "
        "wrench (then they are this table's `center_of_pressure` and `centroidal_moment_pivot` "
        "of the previous tick)."
    )
    objective_condition_number: float = wire_field(
        "Condition number of the damped objective Hessian M (App. D), LAPACK's 1-norm estimate.",
        unit="1",
    )
    schur_condition_number: float = wire_field(
        "Condition number of C M⁻¹ Cᵀ before damping (App. D, eq. D.7): LAPACK's 1-norm "
        "estimate, or the eigenvalue ratio when damped.",
        unit="1",
    )
    objective_damping: float = wire_field("Damping λ on the objective stack (Maciejewski eq. 15).")
    constraint_damping: float = wire_field(
        "Damping λ on the Schur complement (Maciejewski eq. 15)."
    )


class PrioritizedDiagnostics(_Strict):
    """The prioritized controller's own diagnostics: Algorithm 1's levels, the inequalities."""

    priority_levels: list[PriorityLevelReport] = wire_field(
        "One report per level, highest priority first (level 0 is the equations of motion)."
    )
    inequality_violation: float = wire_field(
        "max(0, −(D x + f)) over λ ≥ 0, non-penetration, torque and joint limits."
    )


class BaseEstimateDiagnostics(_Strict):
    """The base state the server estimated from ``state.imu`` (contact-aided invariant EKF).

    Roll, pitch, velocity and height are observable while a foot is in stance; yaw and
    horizontal position are not, and drift (their standard deviations grow to show it).
    """

    position_base_in_world: FloatArray = wire_field(
        "Estimated base origin; height relative to the ground under the stance feet when "
        "the estimator started.",
        shape="3",
        unit="m",
        frame="world",
    )
    orientation_base_in_world_xyzw: FloatArray = wire_field(
        "Estimated base orientation, scalar last.", shape="4", frame="world"
    )
    linear_velocity_base_in_world: FloatArray = wire_field(
        "Estimated base origin velocity.", shape="3", unit="m/s", frame="world"
    )
    angular_velocity_base_in_base: FloatArray = wire_field(
        "Gyroscope less its estimated bias, in base axes.", shape="3", unit="rad/s", frame="base"
    )
    gyro_bias_in_imu: FloatArray = wire_field(
        "Estimated gyroscope bias.", shape="3", unit="rad/s", frame="IMU"
    )
    accel_bias_in_imu: FloatArray = wire_field(
        "Estimated accelerometer bias.", shape="3", unit="m/s²", frame="IMU"
    )
    covariance: FloatArray = wire_field(
        "Covariance of the errors [δθ, δv, δp, δb_g, δb_a] (orientation error in world axes, "
        "so δθ_z is yaw; velocity and position of the base origin, world; biases, IMU), "
        "row-major.",
        shape="15 × 15",
        unit="rad, m/s, m, rad/s, m/s²",
    )
    stance_contacts: list[str] = wire_field(
        "Contacts whose foot position the filter holds this tick (in stance)."
    )


class Diagnostics(_Strict):
    """What the controller did this tick (for logs and plots).

    What every controller reports, and one section of its own (``weighted`` or
    ``prioritized``).
    """

    compute_time_s: float = wire_field("Server time spent on this tick.", unit="s")
    position_com_in_world: Vector3 = wire_field(
        "Centre of mass.", shape="3", unit="m", frame="world"
    )
    velocity_com_in_world: FloatArray = wire_field(
        "Centre-of-mass velocity.", shape="3", unit="m/s", frame="world"
    )
    linear_momentum: FloatArray = wire_field(
        "Linear momentum L.", shape="3", unit="kg·m/s", frame="world"
    )
    angular_momentum: FloatArray = wire_field(
        "Angular momentum H about the CM.", shape="3", unit="kg·m²/s", frame="world"
    )
    linear_momentum_rate_desired: FloatArray = wire_field(
        "L̇_des of eq. 5.9, limited to what the feet can push (z NaN: not controlled; "
        "all NaN when the objective is off).",
        shape="3",
        unit="N",
        frame="world",
    )
    linear_momentum_rate_achieved: FloatArray = wire_field(
        "L̇ = R q̈ + r_bias for the returned q̈.", shape="3", unit="N", frame="world"
    )
    angular_momentum_rate_desired: FloatArray = wire_field(
        "Ḣ_des = −k_H H (eq. 5.15 is k_H = 0); NaN when the objective is off.",
        shape="3",
        unit="N·m",
        frame="world",
    )
    angular_momentum_rate_achieved: FloatArray = wire_field(
        "Ḣ = S q̈ + s_bias for the returned q̈.", shape="3", unit="N·m", frame="world"
    )
    center_of_pressure: FloatArray = wire_field(
        "COP of the ground forces in use (eq. 3.3–3.6); NaN without ground force.",
        shape="3",
        unit="m",
        frame="world",
    )
    centroidal_moment_pivot: FloatArray = wire_field(
        "CMP (eq. 3.9–3.10); NaN without ground force.", shape="3", unit="m", frame="world"
    )
    supports: list[bool] = wire_field(
        "Contacts used as supports this tick: `contact_flags` and the `support_mask` parameter.",
        shape="contacts",
    )
    support_polygon_xy: FloatArray = wire_field(
        "Convex hull of the supporting contact points, counter-clockwise x, y pairs.",
        shape="2 × vertices",
        unit="m",
        frame="world",
    )
    objective_residuals: dict[str, float] = wire_field(
        "Per objective, the weighted residual ‖W (A q̈ − b)‖ at the returned q̈."
    )
    constraint_residual: float = wire_field(
        "‖J_sup q̈ + J̇_sup q̇‖ of the returned q̈ (weighted controllers: non-zero only when "
        "damped; prioritized: whatever the contact level could not meet).",
        unit="m/s², rad/s²",
    )
    root_wrench_residual: float = wire_field(
        "Norm of the root wrench the contact forces could not balance.", unit="N, N·m"
    )
    saturated_joints: int = wire_field("Number of DoFs whose torque hit its limit.")
    weighted: WeightedDiagnostics | None = wire_field(
        "`momentum` and `tracking`: see the WeightedDiagnostics table; absent otherwise.",
        default=None,
    )
    prioritized: PrioritizedDiagnostics | None = wire_field(
        "`prioritized`: see the PrioritizedDiagnostics table; absent otherwise.",
        default=None,
    )
    base_estimate: BaseEstimateDiagnostics | None = wire_field(
        "When the state carried `imu`: the estimated base (see the BaseEstimateDiagnostics "
        "table); absent otherwise.",
        default=None,
    )


class Command(Message):
    """Reply to ``state``: accelerations and torques for that state."""

    type: Literal["command"] = "command"
    joint_acceleration: FloatArray = wire_field(
        "Joint accelerations in wire order.", shape="Σ nv", unit="rad/s² (m/s²)", frame="joint"
    )
    base_linear_acceleration_in_world: FloatArray = wire_field(
        "Acceleration of the base origin.", shape="3", unit="m/s²", frame="world"
    )
    base_angular_acceleration_in_base: FloatArray = wire_field(
        "Base angular acceleration.", shape="3", unit="rad/s²", frame="base"
    )
    joint_torque: FloatArray = wire_field(
        "Joint torques in wire order, within the limits.",
        shape="Σ nv",
        unit="N·m (N)",
        frame="joint",
    )
    contact_force_in_world: FloatArray = wire_field(
        "Distributed force at each contact point (contacts in welcome order, points in "
        "order); zero at contacts that are not supports and in `measured` mode.",
        shape="Σ k × 3",
        unit="N",
        frame="world",
    )
    contact_wrench_in_world: FloatArray = wire_field(
        "Ground wrench per contact used by the inverse dynamics (force, then torque about "
        "the contact frame origin): distributed, or the measured one echoed.",
        shape="contacts × 6",
        unit="N, N·m",
        frame="world",
    )
    diagnostics: Diagnostics | None = wire_field(
        "See the Diagnostics table; absent between diagnostics ticks "
        "(`hello.diagnostics_period_ticks`).",
        default=None,
    )


class SetParams(Message):
    """Change controller parameters of this session at run time (all or nothing)."""

    type: Literal["set_params"] = "set_params"
    params: dict[str, ParamValue] = wire_field("Parameter name → new value.")


class Params(Message):
    """Reply to ``set_params``: every parameter now in force."""

    type: Literal["params"] = "params"
    params: dict[str, ParamValue] = wire_field("Parameter name → value in force.")


class SessionStats(_Strict):
    """Per-session counters in a ``stats`` reply."""

    session_id: str = wire_field("Session identifier.")
    model_name: str = wire_field("Model of the session.")
    controller: str = wire_field("Controller of the session.")
    ticks: int = wire_field("`state` messages answered with a `command`.")
    errors: int = wire_field("Requests of this client answered with an `error`.")
    compute_time_p50_s: float = wire_field(
        "Median compute time over the last 1000 ticks.", unit="s"
    )
    compute_time_p99_s: float = wire_field("99th-percentile compute time, same window.", unit="s")
    idle_s: float = wire_field("Time since the session's last request.", unit="s")


class Stats(Message):
    """Request (no ``sessions``) or reply (with ``sessions``) of server statistics."""

    type: Literal["stats"] = "stats"
    sessions: list[SessionStats] | None = wire_field(
        "Reply only: one entry per live session (see SessionStats).", default=None
    )


class Asset(Message):
    """Upload a file a model names into the server's asset cache, one chunk per message.

    Chunks go in order: the first at offset 0, each next one at the `received_bytes` of
    the last reply, each message within the server's `max_message_bytes` (stated in
    `ASSETS_MISSING`). Once the whole file has arrived and its SHA-256 is checked, it is
    in the cache (shared by the server's workers, bounded by `poise serve
    --asset-cache-bytes`, least recently used out) and a `hello` of this client may name
    it in `model_asset_hashes`. A file is at most `--max-model-bytes`; a client's
    unfinished uploads total at most `--max-upload-bytes-per-client`, and one idle longer
    than `--session-timeout` is dropped. No session is needed.
    """

    type: Literal["asset"] = "asset"
    sha256: Sha256Hex = wire_field("SHA-256 of the whole file, 64 lowercase hex characters.")
    size_bytes: int = wire_field(
        "Size of the whole file (the same in every chunk of an upload).",
        unit="byte",
        ge=0,
        le=2**40,
        strict=True,
    )
    offset_bytes: int = wire_field(
        "Where `data` starts in the file: 0 starts (or restarts) the upload, else the "
        "`received_bytes` of the last reply.",
        unit="byte",
        default=0,
        ge=0,
        le=2**40,
        strict=True,
    )
    data: LoggedBytes = wire_field(
        "The file's bytes from `offset_bytes` on; it must not reach past `size_bytes`.",
        strict=True,
    )


class AssetReceived(Message):
    """Reply to ``asset``: how much of the file the server holds."""

    type: Literal["asset_received"] = "asset_received"
    sha256: Sha256Hex = wire_field("SHA-256 of the file, as in the request.")
    received_bytes: int = wire_field(
        "Bytes of the file received so far: the next chunk's `offset_bytes`.",
        unit="byte",
        ge=0,
        strict=True,
    )
    complete: bool = wire_field(
        "The whole file is in the cache, its SHA-256 checked (also when it was there "
        "already: the rest need not be sent)."
    )


class Bye(Message):
    """Close this client's session; the server answers ``bye``."""

    type: Literal["bye"] = "bye"


class Error(Message):
    """Reply to a request the server could not serve."""

    type: Literal["error"] = "error"
    seq: int = wire_field(
        "Seq of the bad request, -1 if it was unreadable.", default=-1, ge=-1, strict=True
    )
    code: ErrorCode = wire_field("Error code (see the error table).")
    field: str = wire_field(
        'Dotted path of the offending key, `""` for the whole message.', default=""
    )
    detail: str = wire_field("What is wrong, with the bad value.")
    missing_asset_hashes: list[str] | None = wire_field(
        "With `ASSETS_MISSING`: the SHA-256 of each file of `hello.model_asset_hashes` to "
        "upload with `asset` before repeating the hello.",
        default=None,
    )
    max_message_bytes: int | None = wire_field(
        "With `ASSETS_MISSING` and with a message refused for its size (`LIMIT_EXCEEDED`): "
        "the largest message the server accepts (`poise serve --max-message-bytes`); each "
        "`asset` chunk must fit in it.",
        unit="byte",
        default=None,
    )


MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.model_fields["type"].default: cls
    for cls in (
        Hello,
        Welcome,
        State,
        Command,
        SetParams,
        Params,
        Stats,
        Asset,
        AssetReceived,
        Bye,
        Error,
    )
}
"""Message classes by their ``type`` string."""
