"""ODriveBus against emulated ODrives on a python-can virtual bus."""

from __future__ import annotations

import itertools
import math
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass

import can
import pytest

from clients.bridge.actuator import ZERO_COMMAND, ActuatorBus, BusError, MotorCommand
from clients.bridge.emulators.motor import CanDevice, CanDeviceHost, EmulatedMotor
from clients.bridge.emulators.odrive import EmulatedODrive
from clients.bridge.protocols.odrive import (
    AxisError,
    AxisError05,
    AxisState,
    Command,
    ControlMode,
    Firmware,
    Heartbeat,
    InvalidCommand,
    make_encoder_estimates,
    make_heartbeat,
    split_arbitration_id,
)
from clients.bridge.protocols.odrive_bus import ODriveBus

REPLY_TIMEOUT_S = 0.05  # generous: the machine is shared; complete exchanges return early
_channels = itertools.count()


def f32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


@dataclass
class Rig:
    bus: ODriveBus
    motors: dict[int, EmulatedMotor]
    drives: dict[int, EmulatedODrive]


def open_rig(
    node_ids=(1, 2),
    *,
    firmware=Firmware.V0_6,
    extra_devices=(),
    **bus_options,
) -> Iterator[Rig]:
    channel = f"odrive-test-{next(_channels)}-{time.monotonic_ns()}"
    motors = {node: EmulatedMotor(torque_limit_Nm=5.0) for node in node_ids}
    drives = {node: EmulatedODrive(node, motors[node], firmware=firmware) for node in node_ids}
    device_bus = can.Bus(interface="virtual", channel=channel)
    try:
        with CanDeviceHost(device_bus, [*drives.values(), *extra_devices]):
            driver_bus = can.Bus(interface="virtual", channel=channel)
            all_ids = tuple(node_ids) + tuple(getattr(d, "node_id", ()) for d in extra_devices)
            options = {"reply_timeout_s": REPLY_TIMEOUT_S, "name": "test", **bus_options}
            with ODriveBus(driver_bus, all_ids, firmware=firmware, **options) as bus:
                yield Rig(bus, motors, drives)
    finally:
        device_bus.shutdown()


@pytest.fixture
def rig() -> Iterator[Rig]:
    yield from open_rig()


def _is_an_actuator_bus(bus: ODriveBus) -> ActuatorBus:
    return bus  # mypy checks ODriveBus against the protocol


def test_implements_the_actuator_bus_verbs(rig):
    for verb in ActuatorBus.__dict__:
        if not verb.startswith("_") and callable(getattr(ActuatorBus, verb)):
            assert callable(getattr(rig.bus, verb)), verb
    assert rig.bus.name == "test" and rig.bus.actuator_ids == (1, 2)


def zero(bus: ODriveBus) -> dict:
    return bus.exchange(dict.fromkeys(bus.actuator_ids, ZERO_COMMAND))


def torque(bus: ODriveBus, torque_Nm: float) -> dict:
    return bus.exchange(dict.fromkeys(bus.actuator_ids, MotorCommand(torque_Nm=torque_Nm)))


def enable(rig: Rig) -> None:
    zero(rig.bus)
    rig.bus.enable()
    zero(rig.bus)  # takes in the heartbeats of the state change


def test_zero_command_reads_positions(rig):
    rig.motors[1].sense(1.25, -3.0)
    rig.motors[2].sense(-0.5, 0.75)
    feedback = zero(rig.bus)
    assert feedback[1].position_rad == pytest.approx(1.25, rel=1e-6)
    assert feedback[1].velocity_rad_s == pytest.approx(-3.0, rel=1e-6)
    assert feedback[2].position_rad == pytest.approx(-0.5, rel=1e-6)
    assert feedback[2].velocity_rad_s == pytest.approx(0.75, rel=1e-6)
    assert feedback[1].torque_Nm == 0.0 and feedback[1].fault == "" and feedback[1].fault_code == 0
    assert feedback[1].temperature_C == pytest.approx(25.0)
    # Not enabled yet: the ODrive stores the torque but makes none.
    assert rig.motors[1].torque_Nm() == 0.0
    assert rig.drives[1].axis_state == AxisState.IDLE


def test_enable_then_torque_command(rig):
    enable(rig)
    assert rig.drives[1].control_mode == ControlMode.TORQUE_CONTROL
    assert rig.drives[1].axis_state == AxisState.CLOSED_LOOP_CONTROL
    feedback = torque(rig.bus, 0.3)
    for node in (1, 2):
        assert rig.motors[node].torque_Nm() == f32(0.3)
        assert feedback[node].torque_Nm == f32(0.3)  # Get_Torques estimate
        assert feedback[node].fault == ""
    assert rig.motors[1].received[-1].kind == "command"
    assert rig.motors[1].received[-1].command.torque_Nm == f32(0.3)


def test_torque_without_torques_request_reports_the_command():
    for rig in open_rig(request_torques=False):
        enable(rig)
        assert torque(rig.bus, -0.7)[1].torque_Nm == f32(-0.7)
        assert rig.motors[1].torque_Nm() == f32(-0.7)


def test_torque_is_clamped_to_the_configured_limit():
    for rig in open_rig(torque_limit_Nm={1: 0.5}):
        enable(rig)
        torque(rig.bus, 2.0)
        assert rig.motors[1].torque_Nm() == 0.5
        assert rig.motors[2].torque_Nm() == 2.0  # no limit for node 2
        torque(rig.bus, -9.0)
        assert rig.motors[1].torque_Nm() == -0.5
        assert rig.motors[2].torque_Nm() == -5.0  # the motor's own limit


def test_hold_safe_idles_and_still_reads(rig):
    enable(rig)
    torque(rig.bus, 0.4)
    rig.motors[1].sense(0.3, 0.0)
    feedback = rig.bus.hold_safe({1: 0.5, 2: 0.5})
    assert rig.motors[1].torque_Nm() == 0.0
    assert rig.drives[1].axis_state == AxisState.IDLE
    assert feedback[1].position_rad == pytest.approx(0.3, rel=1e-6)
    feedback = rig.bus.hold_safe({1: 0.5, 2: 0.5})
    assert feedback[1].fault == "" and feedback[1].torque_Nm == 0.0


def test_disable_idles(rig):
    enable(rig)
    torque(rig.bus, 0.4)
    rig.bus.disable()
    feedback = zero(rig.bus)
    assert rig.motors[2].torque_Nm() == 0.0
    assert rig.drives[2].axis_state == AxisState.IDLE
    assert feedback[2].fault == ""


def test_silent_node_is_none(rig):
    rig.motors[2].silent = True
    started = time.monotonic()
    feedback = zero(rig.bus)
    assert feedback[2] is None
    assert feedback[1] is not None
    assert time.monotonic() - started < 1.0


def test_axis_error_is_reported_then_cleared(rig):
    enable(rig)
    torque(rig.bus, 0.2)
    rig.motors[1].fault_code = AxisError.MOTOR_OVER_TEMP
    feedback = torque(rig.bus, 0.2)
    assert feedback[1].fault == "axis IDLE, error MOTOR_OVER_TEMP"
    assert feedback[1].fault_code == AxisError.MOTOR_OVER_TEMP
    assert feedback[1].torque_Nm == 0.0
    assert rig.motors[1].torque_Nm() == 0.0
    assert feedback[2].fault == ""
    rig.bus.clear_faults()
    feedback = zero(rig.bus)
    assert feedback[1].fault == "" and feedback[1].fault_code == 0
    assert rig.motors[1].fault_code == 0
    enable(rig)
    torque(rig.bus, 0.2)
    assert rig.motors[1].torque_Nm() == f32(0.2)


def test_closed_loop_is_refused_while_an_error_is_latched(rig):
    rig.motors[1].fault_code = AxisError.DRV_FAULT
    enable(rig)
    feedback = torque(rig.bus, 0.2)
    assert rig.drives[1].axis_state == AxisState.IDLE
    assert rig.motors[1].torque_Nm() == 0.0
    assert feedback[1].fault == "axis IDLE, error DRV_FAULT"


def test_estop(rig):
    enable(rig)
    torque(rig.bus, 0.3)
    rig.bus.estop()
    feedback = torque(rig.bus, 0.3)
    assert rig.motors[1].torque_Nm() == 0.0
    assert feedback[1].fault == "error ESTOP_REQUESTED"
    assert feedback[1].fault_code == AxisError.ESTOP_REQUESTED


def test_watchdog_stops_the_motor_without_commands(rig):
    enable(rig)
    rig.bus.arm_watchdog(0.05)
    torque(rig.bus, 0.3)  # its replies come after the emulator took the RxSdo writes
    assert rig.drives[1].watchdog_enabled
    assert rig.motors[1].watchdog_timeout_s == f32(0.05)
    # Fed by the commands: still running after several timeouts' worth of ticks.
    for _ in range(15):
        torque(rig.bus, 0.3)
        time.sleep(0.01)
    assert rig.motors[1].torque_Nm() == f32(0.3)
    time.sleep(0.1)
    assert rig.motors[1].torque_Nm() == 0.0  # stopped by itself
    feedback = torque(rig.bus, 0.3)
    assert feedback[1].fault == "axis IDLE, error WATCHDOG_TIMER_EXPIRED"
    assert feedback[1].fault_code == AxisError.WATCHDOG_TIMER_EXPIRED
    assert rig.motors[1].torque_Nm() == 0.0
    rig.bus.arm_watchdog(0.0)
    zero(rig.bus)
    assert not rig.drives[1].watchdog_enabled
    assert rig.motors[1].watchdog_timeout_s == 0.0


class BrokenODrive(CanDevice):
    """Answers encoder requests with a truncated, then a NaN, payload."""

    node_id = 9

    def __init__(self):
        self.answers = [bytes(3), struct.pack("<ff", math.nan, 0.0)]

    def on_frame(self, message):
        node, command = split_arbitration_id(message.arbitration_id)
        if node != self.node_id or command != Command.GET_ENCODER_ESTIMATES:
            return []
        data = self.answers.pop(0) if self.answers else None
        if data is None:
            return [make_encoder_estimates(self.node_id, 0.25, 0.0)]
        frame = make_encoder_estimates(self.node_id, 0.0, 0.0)
        frame.data = bytearray(data)
        frame.dlc = len(data)
        return [frame]


def test_malformed_frame_is_a_missed_reply():
    for rig in open_rig(node_ids=(1,), extra_devices=(BrokenODrive(),), request_torques=False):
        for _ in range(2):
            feedback = zero(rig.bus)
            assert feedback[9] is None
            assert feedback[1] is not None
        assert rig.bus.malformed_frames == 2
        assert zero(rig.bus)[9].position_rad == pytest.approx(0.5 * math.pi)


class SlowArmingODrive(CanDevice):
    """Stays IDLE (no error) for a few requests after Set_Axis_State, like an axis still arming."""

    node_id = 7

    def __init__(self, requests_to_arm: int | None):
        self.requests_to_arm = requests_to_arm
        self.state = AxisState.IDLE
        self.countdown: int | None = None

    def on_frame(self, message):
        node, command = split_arbitration_id(message.arbitration_id)
        if node != self.node_id:
            return []
        if command == Command.SET_AXIS_STATE:
            self.countdown = self.requests_to_arm
            return [make_heartbeat(node, Heartbeat(0, self.state))]
        if command != Command.GET_ENCODER_ESTIMATES:
            return []
        if self.countdown is not None:
            self.countdown -= 1
            if self.countdown <= 0:
                self.state = AxisState.CLOSED_LOOP_CONTROL
                self.countdown = None
        return [
            make_heartbeat(node, Heartbeat(0, self.state)),
            make_encoder_estimates(node, 0.0, 0.0),
        ]


def test_an_axis_still_arming_is_no_fault_until_the_arm_timeout():
    device = SlowArmingODrive(requests_to_arm=3)
    for rig in open_rig(
        node_ids=(), extra_devices=(device,), arm_timeout_s=0.5, request_torques=False
    ):
        rig.bus.enable()
        faults = [zero(rig.bus)[7].fault for _ in range(4)]
        assert faults == ["", "", "", ""]
        assert device.state == AxisState.CLOSED_LOOP_CONTROL
        device.state = AxisState.IDLE  # leaves closed loop with no error
        assert zero(rig.bus)[7].fault == "axis IDLE"


def test_an_axis_that_never_arms_is_a_fault_after_the_arm_timeout():
    device = SlowArmingODrive(requests_to_arm=None)
    for rig in open_rig(
        node_ids=(), extra_devices=(device,), arm_timeout_s=0.05, request_torques=False
    ):
        rig.bus.enable()
        assert zero(rig.bus)[7].fault == ""
        time.sleep(0.06)
        assert zero(rig.bus)[7].fault == "axis IDLE"


def test_bad_commands_raise_before_sending(rig):
    with pytest.raises(InvalidCommand, match="kp"):
        rig.bus.exchange({1: ZERO_COMMAND, 2: MotorCommand(kp_Nm_per_rad=1.0)})
    with pytest.raises(InvalidCommand, match="NaN"):
        rig.bus.exchange({1: MotorCommand(torque_Nm=math.nan)})
    with pytest.raises(InvalidCommand, match="not on bus"):
        rig.bus.exchange({5: ZERO_COMMAND})
    time.sleep(0.02)
    assert not rig.motors[1].received


def test_bus_failure_is_a_bus_error():
    for rig in open_rig():
        rig.bus.close()
        with pytest.raises(BusError, match="'test'"):
            zero(rig.bus)


def test_firmware_05():
    for rig in open_rig(firmware=Firmware.V0_5):
        enable(rig)
        feedback = torque(rig.bus, 0.3)
        assert feedback[1].torque_Nm == f32(0.3)  # the command: 0.5 has no Get_Torques
        assert feedback[1].temperature_C is None
        rig.bus.estop()
        feedback = zero(rig.bus)
        assert feedback[1].fault == "error ESTOP_REQUESTED"
        assert feedback[1].fault_code == AxisError05.ESTOP_REQUESTED
        with pytest.raises(InvalidCommand, match="USB"):
            rig.bus.arm_watchdog(0.1)


def test_constructor_validates():
    bus = can.Bus(interface="virtual", channel=f"odrive-ctor-{time.monotonic_ns()}")
    try:
        with pytest.raises(InvalidCommand):
            ODriveBus(bus, [64])
        with pytest.raises(InvalidCommand):
            ODriveBus(bus, [1, 1])
        with pytest.raises(InvalidCommand):
            ODriveBus(bus, [1], torque_limit_Nm={2: 1.0})
        with pytest.raises(InvalidCommand):
            ODriveBus(bus, [1], torque_limit_Nm=-1.0)
        with pytest.raises(InvalidCommand):
            ODriveBus(bus, [1], reply_timeout_s=0.0)
    finally:
        bus.shutdown()
