"""The actuator map: which actuator drives which joint, and how (TOML, validated by pydantic).

A bridge file has three parts (example: ``examples/bridge/revolute_humanoid_mit.toml``;
every key: ``docs/bridge.md``):

- ``[bridge]``: the server session (model, controller, parameters), the loop
  rate, the host watchdog, and the safety settings;
- ``[buses.NAME]``: one CAN channel or Dynamixel port and the protocol its
  actuators speak;
- ``[joints.NAME]``: per joint of the robot, its bus, actuator id, motor
  model, gearing (ratio, direction, zero offset) and limits.

An optional ``[imu]`` says where the IMU sits when ``base_state = "imu"``
(the server then estimates the base from it), and an optional
``[emulation]`` how ``poise bridge --emulate`` simulates the robot behind
emulated actuators. The map is checked against the server's announced
joints at start (:func:`check_against_welcome`).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pinocchio as pin
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from clients.explain import explain
from clients.physics.backend import PushSpec
from clients.physics.imu import ImuSpec
from clients.physics.model_file import body_names, describe_model, resolve_model_path
from protocol.errors import PoiseError, did_you_mean
from protocol.messages import Welcome

__all__ = [
    "BridgeConfig",
    "BridgeConfigError",
    "BridgeSettings",
    "BusSpec",
    "EmulationSpec",
    "ImuSettings",
    "JointActuator",
    "check_against_welcome",
    "imu_mount_on_root_body",
    "load_bridge_config",
]

Protocol = Literal["mit", "damiao", "odrive", "dynamixel"]
CAN_PROTOCOLS = ("mit", "damiao", "odrive")


class BridgeConfigError(PoiseError, ValueError):
    """A bridge file cannot be used; the one-line message says what to change."""


class _Record(BaseModel):
    # NaN and infinity are never a setting: refused by name, like a value out of range
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class BridgeSettings(_Record):
    """The ``[bridge]`` table: session, loop and safety settings."""

    model: str = Field(default="revolute_humanoid", description="Server model (built-in or path).")
    controller: str = Field(default="momentum", description="Server controller.")
    params: dict[str, Any] = Field(default_factory=dict, description="Controller parameters.")
    rate_hz: float = Field(default=500.0, ge=200.0, le=1000.0, description="Loop rate (Hz).")
    duration_s: float = Field(
        default=0.0, ge=0.0, description="Stop after this long (s); 0 runs until stopped."
    )
    watchdog_s: float = Field(
        default=0.05,
        gt=0.0,
        le=1.0,
        description="No valid command from the server for this long (s) latches the safe state.",
    )
    actuator_watchdog_s: float = Field(
        default=0.2,
        ge=0.0,
        le=2.5,
        description="The actuators' own watchdogs (s; 0: not armed); longer than watchdog_s.",
    )
    safe_damping_Nm_s_per_rad: float = Field(
        default=2.0,
        ge=0.0,
        description="Joint-side damping of the MIT/Damiao safe state (kp = 0, τ = 0).",
    )
    max_missed_replies: int = Field(
        default=5, ge=1, description="An actuator silent this many ticks in a row latches safe."
    )
    position_margin_rad: float = Field(
        default=0.05,
        ge=0.0,
        description="A joint beyond its position limits by more than this latches safe (rad).",
    )
    torque_scale: float = Field(
        default=1.0, gt=0.0, le=1.0, description="Scales every torque (bring-up on a stand)."
    )
    base_state: Literal["simulator", "fixed", "imu"] = Field(
        default="fixed",
        description="Where the base pose and twist come from: `simulator` (ground truth, "
        "--emulate only), `fixed` (at rest at the standing pose: a robot on a stand) or "
        "`imu` (the server estimates them from the IMU of `[imu]`, the joints and the "
        "contact flags).",
    )
    support_force_threshold_N: float = Field(
        default=20.0, ge=0.0, description="Simulator base state: a foot supports above this (N)."
    )

    @model_validator(mode="after")
    def _watchdogs(self) -> BridgeSettings:
        if self.actuator_watchdog_s and self.actuator_watchdog_s <= self.watchdog_s:
            raise ValueError(
                f"actuator_watchdog_s ({self.actuator_watchdog_s}) must exceed watchdog_s "
                f"({self.watchdog_s}): the host watchdog acts first, the actuators' own last"
            )
        return self


class BusSpec(_Record):
    """One ``[buses.NAME]`` table: a CAN channel or a Dynamixel serial port."""

    protocol: Protocol = Field(description="What its actuators speak.")
    interface: str = Field(default="socketcan", description="python-can interface (CAN).")
    channel: str = Field(default="can0", description="python-can channel (CAN).")
    bitrate: int = Field(default=1_000_000, gt=0, description="CAN bit rate (bit/s).")
    port: str = Field(default="/dev/ttyUSB0", description="Serial port (Dynamixel).")
    baudrate: int = Field(default=1_000_000, gt=0, description="Serial baud rate (Dynamixel).")
    reply_timeout_s: float = Field(
        default=0.002, gt=0.0, le=0.1, description="Wait for actuator replies per tick (s)."
    )

    @property
    def is_can(self) -> bool:
        """Whether it is a CAN bus (python-can)."""
        return self.protocol in CAN_PROTOCOLS


class JointActuator(_Record):
    """One ``[joints.NAME]`` table: the actuator of a joint, and the joint's limits.

    The motor side relates to the joint side by
    ``q_joint = direction · q_motor / gear_ratio + zero_offset_rad``, so
    ``τ_motor = direction · τ_joint / gear_ratio`` (lossless gearing).
    """

    bus: str = Field(description="Name of its `[buses.NAME]` table.")
    id: int = Field(ge=0, le=0x7FF, description="Actuator id on the bus (CAN id, node, servo).")
    motor: str = Field(default="", description="Motor model (its protocol's catalogue).")
    master_id: int | None = Field(
        default=None, ge=0, le=0x7FF, description="Damiao: the id it replies on."
    )
    gear_ratio: float = Field(default=1.0, gt=0.0, description="Motor turns per joint turn.")
    direction: Literal[-1, 1] = Field(default=1, description="+1 or −1.")
    zero_offset_rad: float = Field(default=0.0, description="Joint angle at motor zero (rad).")
    torque_limit_Nm: float | None = Field(
        default=None, gt=0.0, description="Joint side (N·m); default: the model's limit."
    )
    position_limit_rad: tuple[float, float] | None = Field(
        default=None, description="Joint [lower, upper] (rad); default: the model's limits."
    )
    velocity_limit_rad_s: float = Field(default=20.0, gt=0.0, description="Joint side (rad/s).")
    derate_above_C: float = Field(
        default=70.0, description="Torque limit falls linearly from here (°C) …"
    )
    temperature_limit_C: float = Field(default=90.0, description="… to 0 here (°C): safe state.")

    @model_validator(mode="after")
    def _ranges(self) -> JointActuator:
        if self.position_limit_rad is not None:
            lower, upper = self.position_limit_rad
            if not lower < upper:
                raise ValueError(f"position_limit_rad [{lower}, {upper}]: lower ≥ upper")
        if not self.derate_above_C < self.temperature_limit_C:
            raise ValueError(
                f"derate_above_C ({self.derate_above_C}) must be below temperature_limit_C "
                f"({self.temperature_limit_C})"
            )
        return self


_IMU_MOUNT_KEYS = ("body", "position_in_body_m", "orientation_in_body_xyzw")
"""The keys of a simulated IMU's spec that ``[imu]`` gives instead (its mount)."""


class ImuSettings(_Record):
    """The ``[imu]`` table: where the IMU of ``base_state = "imu"`` sits, and what reads it.

    The mount goes to the server in ``hello`` (``imu_frame`` and offset); the
    frame must be rigid on the root body.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    frame: str = Field(
        default="",
        description="Model frame the IMU is fixed to, rigid on the root body; empty: the root "
        "body.",
    )
    position_in_frame: tuple[float, float, float] = Field(
        default=(0.0, 0.0, 0.0), description="IMU origin in `frame` (m)."
    )
    orientation_in_frame_xyzw: tuple[float, float, float, float] = Field(
        default=(0.0, 0.0, 0.0, 1.0),
        description="IMU axes in `frame`, quaternion x y z w (normalised on load).",
    )
    source: Literal["emulated", "external"] = Field(
        default="emulated",
        description="`emulated`: the simulated robot's IMU (--emulate only); `external`: an "
        "`ImuSource` a program passes to `run_bridge` (real hardware).",
    )
    max_sample_age_s: float = Field(
        default=0.02,
        gt=0.0,
        le=1.0,
        description="The same IMU sample (gyroscope and accelerometer unchanged) for longer "
        "than this latches the safe state: a stalled driver would have the server integrate "
        "a stale reading. Longer than the IMU's sample period.",
    )

    @field_validator("position_in_frame")
    @classmethod
    def _within_reach(cls, value: tuple[float, float, float]) -> tuple[float, float, float]:
        if not all(abs(x) <= 10.0 for x in value):
            raise ValueError(f"the IMU must sit within 10 m of its frame, got {list(value)}")
        return value

    @field_validator("orientation_in_frame_xyzw")
    @classmethod
    def _unit_quaternion(
        cls, value: tuple[float, float, float, float]
    ) -> tuple[float, float, float, float]:
        norm = math.sqrt(sum(c * c for c in value))
        if not norm > 1e-9:
            raise ValueError(f"a rotation needs a non-zero quaternion x y z w, got {list(value)}")
        x, y, z, w = (c / norm for c in value)
        return (x, y, z, w)


class EmulationSpec(_Record):
    """The ``[emulation]`` table: the simulated robot behind ``poise bridge --emulate``."""

    backend: Literal["reference", "mujoco"] = Field(default="reference")
    physics_rate_hz: float = Field(default=2000.0, gt=0.0, le=100_000.0)
    friction_coefficient: float = Field(default=0.8, gt=0.0, le=5.0)
    pushes: list[PushSpec] = Field(default_factory=list)
    imu: ImuSpec = Field(
        default_factory=ImuSpec,
        description='The emulated IMU\'s rate and errors (`base_state = "imu"`, '
        '`source = "emulated"`): the keys of `clients.physics.imu.ImuSpec` but its mount, '
        "which `[imu]` gives. Default: a BMI088 at 1 kHz with an orientation output.",
    )

    @model_validator(mode="after")
    def _imu(self) -> EmulationSpec:
        mount = [key for key in _IMU_MOUNT_KEYS if key in self.imu.model_fields_set]
        if mount:
            raise ValueError(
                f"emulation.imu.{mount[0]}: the IMU's mount is [imu]'s frame, "
                "position_in_frame and orientation_in_frame_xyzw"
            )
        if self.imu.rate_hz > self.physics_rate_hz:
            raise ValueError(
                f"emulation.imu.rate_hz ({self.imu.rate_hz:g}) must not exceed "
                f"physics_rate_hz ({self.physics_rate_hz:g}): a sample per physics step at most"
            )
        return self


class BridgeConfig(_Record):
    """A whole bridge file."""

    bridge: BridgeSettings = Field(default_factory=BridgeSettings)
    buses: dict[str, BusSpec] = Field(description="Buses by name.")
    joints: dict[str, JointActuator] = Field(description="Actuators by joint name.")
    imu: ImuSettings | None = Field(
        default=None, description='The IMU of `base_state = "imu"` (default: `ImuSettings()`).'
    )
    emulation: EmulationSpec = Field(default_factory=EmulationSpec)

    @property
    def imu_settings(self) -> ImuSettings:
        """The ``[imu]`` table, or its defaults (an emulated IMU at the root body's origin)."""
        return self.imu if self.imu is not None else ImuSettings()

    @model_validator(mode="after")
    def _imu_table(self) -> BridgeConfig:
        steps = self.emulation.physics_rate_hz / self.bridge.rate_hz
        if abs(steps - round(steps)) > 1e-9 or round(steps) < 1:
            raise ValueError(
                f"emulation.physics_rate_hz ({self.emulation.physics_rate_hz:g}) must be a whole "
                f"multiple of bridge.rate_hz ({self.bridge.rate_hz:g}): physics steps per tick"
            )
        if self.imu is not None and self.bridge.base_state != "imu":
            raise ValueError(
                f'an [imu] table is for base_state = "imu" (this map has base_state = '
                f'"{self.bridge.base_state}"): set base_state = "imu", or remove [imu]'
            )
        return self

    @model_validator(mode="after")
    def _references(self) -> BridgeConfig:
        seen: dict[tuple[str, int], str] = {}
        for joint, actuator in self.joints.items():
            if actuator.bus not in self.buses:
                raise ValueError(
                    f"joints.{joint}.bus = {actuator.bus!r}: no such bus; buses: "
                    f"{', '.join(self.buses) or '(none)'}"
                )
            key = (actuator.bus, actuator.id)
            if key in seen:
                raise ValueError(
                    f"joints.{joint} and joints.{seen[key]} share id {actuator.id} on bus "
                    f"{actuator.bus!r}"
                )
            seen[key] = joint
            if self.buses[actuator.bus].protocol == "damiao" and actuator.master_id is None:
                raise ValueError(f"joints.{joint}: a Damiao actuator needs master_id")
        return self

    def joints_on(self, bus: str) -> dict[str, JointActuator]:
        """The joints whose actuators are on ``bus``, in file order."""
        return {name: actuator for name, actuator in self.joints.items() if actuator.bus == bus}


def load_bridge_config(path: str | Path) -> BridgeConfig:
    """Read and validate a bridge file.

    Raises:
        BridgeConfigError: No such file, not text, not TOML, an unknown key
            (with the closest known one), a value out of range or not finite,
            a physics rate that is not a whole multiple of the loop's, a joint
            on a bus that does not exist, or two actuators with one id on one bus.
    """
    path = Path(path)
    if not path.is_file():
        raise BridgeConfigError(f"no bridge file {str(path)!r}")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise BridgeConfigError(f"bridge file {str(path)!r} is not valid TOML: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise BridgeConfigError(
            f"bridge file {str(path)!r} is not text (byte {exc.start} is not UTF-8): "
            "give the TOML map (see examples/bridge/)"
        ) from None
    try:
        return BridgeConfig.model_validate(data)
    except ValidationError as exc:
        raise BridgeConfigError(f"bridge file {str(path)!r}: {explain(exc, BridgeConfig)}") from exc


def check_against_welcome(config: BridgeConfig, welcome: Welcome) -> None:
    """Refuse a map that does not match the joints the server announced.

    Every announced joint must have an actuator, every mapped joint must
    exist, and every one must be a one-DoF joint (a ball joint has no single
    actuator).

    Raises:
        BridgeConfigError: Naming the unmapped, unknown or multi-DoF joints.
    """
    announced = [joint.name for joint in welcome.joints]
    problems = []
    unmapped = [name for name in announced if name not in config.joints]
    if unmapped:
        problems.append(f"no actuator for {', '.join(unmapped)}")
    unknown = [name for name in config.joints if name not in announced]
    if unknown:
        problems.append(f"{welcome.model_name} has no joint {', '.join(unknown)}")
    multi = [joint.name for joint in welcome.joints if joint.nv != 1]
    if multi:
        problems.append(f"{', '.join(multi)} have several DoF (one actuator drives one DoF)")
    if problems:
        raise BridgeConfigError(
            f"the actuator map does not match {welcome.model_name}: {'; '.join(problems)} "
            f"(its joints: {', '.join(announced)})"
        )


def imu_mount_on_root_body(config: BridgeConfig) -> tuple[str, pin.SE3]:
    """Where ``[imu]`` mounts the IMU, in the root body's frame (checked before connecting).

    ``frame`` may be any frame of the model rigid on the root body, as for the
    server (``hello.imu_frame``); empty, the offset is in the root body's own
    frame. A simulated IMU is fixed to an MJCF body: there, the root body.

    Returns:
        The root body's name, and the IMU's placement in its frame.

    Raises:
        BridgeConfigError: The frame is not one of the model's (the message
            suggests the closest), or it moves relative to the root body.
    """
    settings = config.imu_settings
    path = resolve_model_path(config.bridge.model)
    model = describe_model(config.bridge.model).model
    offset = pin.SE3(
        pin.Quaternion(np.array(settings.orientation_in_frame_xyzw)).toRotationMatrix(),
        np.array(settings.position_in_frame, dtype=float),
    )
    mount_in_joint = offset  # no frame: the root body's axes, as the server takes them
    if settings.frame:
        names = [frame.name for frame in model.frames]
        if settings.frame not in names:
            hint = did_you_mean(settings.frame, names)
            raise BridgeConfigError(
                f"[imu] frame = {settings.frame!r}: {path.name} has no such frame; {hint}"
                "frames on the root body: "
                + ", ".join(f.name for f in model.frames if f.parentJoint == 1)
            )
        frame = model.frames[model.getFrameId(settings.frame)]
        if frame.parentJoint != 1:
            raise BridgeConfigError(
                f"[imu] frame = {settings.frame!r} moves relative to the root body (joint "
                f"{model.names[frame.parentJoint]!r} between them): mount the IMU on the root body"
            )
        mount_in_joint = frame.placement * offset
    root = body_names(config.bridge.model)[0]
    body = next(f for f in model.frames if f.type == pin.FrameType.BODY and f.name == root)
    return root, body.placement.inverse() * mount_in_joint
