"""Open the buses of an actuator map: one :class:`~clients.bridge.actuator.ActuatorBus` each.

Each protocol's motor models come from its catalogue
(:data:`~clients.bridge.protocols.mit.MIT_MOTOR_MODELS`,
:data:`~clients.bridge.protocols.damiao.DAMIAO_MOTOR_MODELS`,
:data:`~clients.bridge.protocols.dynamixel.DYNAMIXEL_MODELS`; an ODrive's
motor is whatever it was calibrated with, so its ``motor`` is free text).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import can

from clients.bridge.actuator import ActuatorBus, BusError
from clients.bridge.config import BridgeConfig, BridgeConfigError, BusSpec, JointActuator
from clients.bridge.protocols.can_io import DamiaoBus, MitBus
from clients.bridge.protocols.damiao import DAMIAO_MOTOR_MODELS, DamiaoMotor
from clients.bridge.protocols.dynamixel import DYNAMIXEL_MODELS
from clients.bridge.protocols.dynamixel_bus import DynamixelBus
from clients.bridge.protocols.mit import MIT_MOTOR_MODELS
from clients.bridge.protocols.odrive_bus import ODriveBus
from protocol.errors import did_you_mean

__all__ = [
    "bus_time_per_tick_s",
    "check_motors",
    "motor_catalogue",
    "motor_peak_torque_Nm",
    "open_buses",
]

CAN_FRAME_BITS = 130
"""An 8-byte standard CAN frame on the wire: 111 bits, plus stuff bits and the gap."""
CAN_FRAMES_PER_ACTUATOR = {"mit": 2, "damiao": 2, "odrive": 5}
"""Frames per actuator and tick: command and reply; ODrive's torque, two requests, two replies."""
DYNAMIXEL_STATUS_BYTES = 32
"""One servo's status packet in the sync read (11 bytes of frame, 21 of registers)."""


def motor_catalogue(protocol: str) -> Mapping[str, Any] | None:
    """The motor models a protocol knows, by name (``None``: any name goes)."""
    return {
        "mit": MIT_MOTOR_MODELS,
        "damiao": DAMIAO_MOTOR_MODELS,
        "dynamixel": DYNAMIXEL_MODELS,
    }.get(protocol)


def check_motors(config: BridgeConfig) -> None:
    """Refuse a motor model its protocol's catalogue lacks (with the closest one).

    Raises:
        BridgeConfigError: Naming the joint, the model and the known ones.
    """
    for joint, actuator in config.joints.items():
        protocol = config.buses[actuator.bus].protocol
        catalogue = motor_catalogue(protocol)
        if catalogue is None or actuator.motor in catalogue:
            continue
        hint = did_you_mean(actuator.motor, catalogue)
        raise BridgeConfigError(
            f"joints.{joint}.motor = {actuator.motor!r}: not a {protocol} motor model; "
            f"{hint}known: {', '.join(catalogue)}"
        )


def motor_peak_torque_Nm(protocol: str, actuator: JointActuator) -> float:
    """The most torque the motor can make (motor side; ODrive: unknown, infinite)."""
    catalogue = motor_catalogue(protocol)
    if catalogue is None:
        return math.inf
    model = catalogue[actuator.motor]
    if protocol == "dynamixel":
        return float(model.stall_torque_Nm)
    return float(model.torque_max_Nm)


def bus_time_per_tick_s(spec: BusSpec, actuators: int) -> float:
    """The bus time one tick's exchange takes at least (s): the frames on the wire.

    CAN: :data:`CAN_FRAMES_PER_ACTUATOR` frames of :data:`CAN_FRAME_BITS` at
    ``bitrate``. Dynamixel: the sync write (14 + 3 bytes per servo), the sync
    read (14 + 1) and one status packet per servo, 10 bits a byte at
    ``baudrate`` (Return Delay Time not counted).
    """
    if spec.protocol == "dynamixel":
        byte_count = 14 + 3 * actuators + 14 + actuators + DYNAMIXEL_STATUS_BYTES * actuators
        return 10 * byte_count / spec.baudrate
    return CAN_FRAMES_PER_ACTUATOR[spec.protocol] * actuators * CAN_FRAME_BITS / spec.bitrate


def open_buses(
    config: BridgeConfig, overrides: Mapping[str, Mapping[str, Any]] | None = None
) -> dict[str, ActuatorBus]:
    """Open every bus of the map.

    Args:
        config: The map (motors checked with :func:`check_motors`).
        overrides: Per bus, fields replacing the map's (``interface``,
            ``channel``, ``port``): how emulation points the buses at its
            emulators.

    Raises:
        BusError: A CAN interface or serial port cannot be opened (the
            message names the bus and what to check).
    """
    buses: dict[str, ActuatorBus] = {}
    try:
        for name, spec in config.buses.items():
            spec = spec.model_copy(update=dict((overrides or {}).get(name, {})))
            buses[name] = _open(name, spec, config.joints_on(name))
    except BaseException:
        for bus in buses.values():
            bus.close()
        raise
    return buses


def _open(name: str, spec: BusSpec, joints: Mapping[str, JointActuator]) -> ActuatorBus:
    if spec.protocol == "dynamixel":
        return DynamixelBus(
            spec.port,
            {actuator.id: actuator.motor for actuator in joints.values()},
            baudrate=spec.baudrate,
            name=name,
            reply_timeout_s=spec.reply_timeout_s,
        )
    try:
        can_bus = can.Bus(interface=spec.interface, channel=spec.channel, bitrate=spec.bitrate)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise BusError(
            name,
            f"cannot open CAN interface {spec.interface!r} channel {spec.channel!r}: {exc} "
            f"(is the interface up, e.g. `ip link set {spec.channel} up type can bitrate "
            f"{spec.bitrate}`?)",
        ) from exc
    if spec.protocol == "mit":
        return MitBus(
            can_bus,
            {a.id: MIT_MOTOR_MODELS[a.motor] for a in joints.values()},
            name=name,
            reply_timeout_s=spec.reply_timeout_s,
        )
    if spec.protocol == "damiao":
        return DamiaoBus(
            can_bus,
            {
                a.id: DamiaoMotor(DAMIAO_MOTOR_MODELS[a.motor], a.master_id or 0)
                for a in joints.values()
            },
            name=name,
            reply_timeout_s=spec.reply_timeout_s,
        )
    return ODriveBus(
        can_bus,
        [a.id for a in joints.values()],
        name=name,
        reply_timeout_s=spec.reply_timeout_s,
    )
