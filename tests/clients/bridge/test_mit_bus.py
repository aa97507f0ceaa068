"""MitBus and DamiaoBus against their emulators on a python-can ``virtual`` bus.

One Bus instance drives, another serves the emulated devices from a
CanDeviceHost thread; each test has its own channel.
"""

import itertools
import math
import time
from contextlib import contextmanager

import can
import pytest

from clients.bridge.actuator import ZERO_COMMAND, ActuatorBus, BusError, MotorCommand
from clients.bridge.emulators.damiao import EmulatedDamiao
from clients.bridge.emulators.mit import EmulatedMitActuator
from clients.bridge.emulators.motor import CanDeviceHost, EmulatedMotor
from clients.bridge.protocols.can_io import DamiaoBus, MitBus, RegisterWriteError
from clients.bridge.protocols.damiao import (
    DAMIAO_MOTOR_MODELS,
    DamiaoMotor,
    DamiaoRegister,
    DamiaoStatus,
)
from clients.bridge.protocols.mit import MIT_MOTOR_MODELS, NonFiniteValue, quantum

AK80_9 = MIT_MOTOR_MODELS["AK80-9"]
J4310 = DAMIAO_MOTOR_MODELS["DM-J4310"]
TIMEOUT_S = 0.05  # generous for a loaded machine; exchanges end as soon as all answered
_channels = itertools.count()


def torque_step(ranges):
    return quantum(-ranges.torque_max_Nm, ranges.torque_max_Nm, 12)


def damper_tolerance(ranges, kd, velocity):
    """How far −kd·v can be off: zero velocity itself quantizes to −V_MAX/4095 (so the
    damper brakes toward that speed), kd and the zero torque to one step each."""
    v_step = quantum(-ranges.velocity_max_rad_s, ranges.velocity_max_rad_s, 12)
    kd_step = quantum(0.0, ranges.kd_max_Nm_s_per_rad, 12)
    return kd * v_step + abs(velocity) * kd_step + torque_step(ranges) + 1e-9


@pytest.fixture
def channel(request):
    return f"poise-{request.node.name}-{next(_channels)}-{time.monotonic_ns()}"


def virtual(channel):
    return can.Bus(interface="virtual", channel=channel, receive_own_messages=False)


@contextmanager
def serving(channel, devices):
    with virtual(channel) as device_bus, CanDeviceHost(device_bus, devices):
        yield


def kinds(motor):
    return [received.kind for received in motor.received]


@pytest.mark.parametrize("bus_class", [MitBus, DamiaoBus])
def test_buses_offer_every_verb_of_the_actuator_bus(bus_class):
    verbs = {name for name in vars(ActuatorBus) if not name.startswith("_")}
    verbs |= set(ActuatorBus.__annotations__)
    assert verbs == {
        "name",
        "actuator_ids",
        "exchange",
        "enable",
        "arm_watchdog",
        "hold_safe",
        "clear_faults",
        "disable",
        "close",
    }
    for verb in verbs - {"name", "actuator_ids"}:
        assert callable(getattr(bus_class, verb)), verb


# --- MIT ----------------------------------------------------------------------------------


@contextmanager
def mit_rig(channel, motors, options=None):
    """MitBus over emulated AK80-9s with the given ids (options: emulator keywords by id)."""
    devices = [
        EmulatedMitActuator(i, motor, AK80_9, **(options or {}).get(i, {}))
        for i, motor in motors.items()
    ]
    with serving(channel, devices):
        ranges = dict.fromkeys(motors, AK80_9)
        with MitBus(virtual(channel), ranges, name="legs", reply_timeout_s=TIMEOUT_S) as bus:
            yield bus


def test_mit_zero_command_reads_positions_before_enabling(channel):
    motors = {1: EmulatedMotor(torque_limit_Nm=18.0), 2: EmulatedMotor(torque_limit_Nm=18.0)}
    motors[1].sense(0.7, -3.0)
    motors[2].sense(-2.25, 1.5)
    with mit_rig(channel, motors) as bus:
        assert bus.actuator_ids == (1, 2)
        feedback = bus.exchange(dict.fromkeys(motors, ZERO_COMMAND))
    p_step = quantum(-12.5, 12.5, 16)
    v_step = quantum(-50.0, 50.0, 12)
    for i, (position, velocity) in ((1, (0.7, -3.0)), (2, (-2.25, 1.5))):
        assert feedback[i] is not None
        assert feedback[i].position_rad == pytest.approx(position, abs=p_step)
        assert feedback[i].velocity_rad_s == pytest.approx(velocity, abs=v_step)
        assert feedback[i].torque_Nm == pytest.approx(0.0, abs=torque_step(AK80_9))
        assert feedback[i].temperature_C is None  # 6-byte bgkatz reply
        assert not motors[i].enabled
        assert kinds(motors[i]) == []  # outside motor mode the command is ignored


def test_mit_enable_then_torque_is_applied_within_one_12_bit_step(channel):
    motor = EmulatedMotor(torque_limit_Nm=18.0)
    with mit_rig(channel, {1: motor}) as bus:
        bus.exchange({1: ZERO_COMMAND})
        bus.enable()
        assert motor.enabled
        feedback = bus.exchange({1: MotorCommand(torque_Nm=4.321)})
    assert motor.torque_Nm() == pytest.approx(4.321, abs=torque_step(AK80_9))
    assert kinds(motor) == ["enable", "command"]
    assert feedback[1] is not None
    assert feedback[1].torque_Nm == pytest.approx(4.321, abs=2 * torque_step(AK80_9))


def test_mit_hold_safe_is_a_damper(channel):
    motor = EmulatedMotor(torque_limit_Nm=18.0)
    motor.sense(0.3, 2.0)
    with mit_rig(channel, {1: motor}) as bus:
        bus.enable()
        feedback = bus.hold_safe({1: 1.5})
        assert feedback[1] is not None
        tolerance = damper_tolerance(AK80_9, 1.5, 2.0)
        assert motor.torque_Nm() == pytest.approx(-1.5 * 2.0, abs=tolerance)
        assert motor.received[-1].kind == "safe"
        bus.hold_safe({1: 50.0})  # beyond KD_MAX: clamped to 5
        assert motor.command.kd_Nm_s_per_rad == pytest.approx(5.0)
        assert motor.torque_Nm() == pytest.approx(-5.0 * 2.0, abs=damper_tolerance(AK80_9, 5, 2))


def test_mit_silent_and_malformed_actuators_read_as_none(channel):
    motors = {i: EmulatedMotor(torque_limit_Nm=18.0) for i in (1, 2, 3)}
    motors[2].silent = True
    with mit_rig(channel, motors, {3: {"malformed_reply": 7}}) as bus:
        feedback = bus.exchange(dict.fromkeys(motors, ZERO_COMMAND))
        assert feedback[1] is not None
        assert feedback[2] is None
        assert feedback[3] is None  # a 7-byte reply is no reply
        motors[2].silent = False
        assert bus.exchange({2: ZERO_COMMAND})[2] is not None


def test_mit_cubemars_reply_reports_temperature_and_error(channel):
    motor = EmulatedMotor(torque_limit_Nm=18.0, temperature_C=61.4)
    motor.fault_code = 1
    with mit_rig(channel, {1: motor}, {1: {"reply_length": 8}}) as bus:
        feedback = bus.exchange({1: ZERO_COMMAND})[1]
    assert feedback is not None
    assert feedback.temperature_C == 61.0
    assert (feedback.fault_code, feedback.fault) == (1, "motor over-temperature")


def test_mit_disable_watchdog_and_clear_faults(channel):
    motor = EmulatedMotor(torque_limit_Nm=18.0)
    with mit_rig(channel, {1: motor}) as bus:
        bus.enable()
        bus.arm_watchdog(0.05)  # nothing to arm on bgkatz firmware
        bus.clear_faults()
        assert motor.watchdog_timeout_s == 0.0
        bus.disable()
        assert not motor.enabled
        bus.exchange({1: MotorCommand(torque_Nm=3.0)})
        assert motor.torque_Nm() == 0.0
    assert kinds(motor) == ["enable", "disable"]


def test_mit_set_zero_shifts_positions_both_ways(channel):
    motor = EmulatedMotor(torque_limit_Nm=18.0)
    motor.sense(1.0, 0.0)
    device = EmulatedMitActuator(1, motor, AK80_9)
    with serving(channel, [device]), virtual(channel) as raw:
        raw.send(can.Message(arbitration_id=1, data=b"\xff" * 7 + b"\xfe", is_extended_id=False))
        reply = raw.recv(timeout=1.0)
    assert reply is not None and reply.arbitration_id == 0
    assert device.zero_offset_rad == 1.0
    with serving(channel, [device]):
        with MitBus(virtual(channel), {1: AK80_9}, reply_timeout_s=TIMEOUT_S) as bus:
            assert bus.exchange({1: ZERO_COMMAND})[1].position_rad == pytest.approx(0.0, abs=1e-3)
            bus.enable()
            bus.exchange({1: MotorCommand(position_rad=0.5)})
    assert motor.command.position_rad == pytest.approx(1.5, abs=1e-3)


def test_mit_bus_errors_and_bad_commands(channel):
    motor = EmulatedMotor(torque_limit_Nm=18.0)
    with mit_rig(channel, {1: motor}) as bus:
        with pytest.raises(NonFiniteValue):
            bus.exchange({1: MotorCommand(torque_Nm=math.nan)})
        assert kinds(motor) == []
        with pytest.raises(ValueError, match="no actuator"):
            bus.exchange({9: ZERO_COMMAND})
        bus.close()
        with pytest.raises(BusError, match="legs"):
            bus.exchange({1: ZERO_COMMAND})
    with virtual(channel) as raw, pytest.raises(ValueError, match="1–255"):
        MitBus(raw, {0x100: AK80_9})


# --- Damiao -------------------------------------------------------------------------------


@contextmanager
def damiao_rig(channel, motors, options=None):
    """DamiaoBus over emulated DM-J4310s: id i answers on master id 0x10 + i."""
    devices = [
        EmulatedDamiao(i, motor, J4310, master_id=0x10 + i, **(options or {}).get(i, {}))
        for i, motor in motors.items()
    ]
    with serving(channel, devices):
        config = {i: DamiaoMotor(J4310, master_id=0x10 + i) for i in motors}
        with DamiaoBus(virtual(channel), config, name="arm", reply_timeout_s=TIMEOUT_S) as bus:
            yield bus


def test_damiao_zero_command_reads_positions_disabled(channel):
    motors = {1: EmulatedMotor(torque_limit_Nm=10.0), 2: EmulatedMotor(torque_limit_Nm=10.0)}
    motors[1].sense(-1.2, 4.0)
    motors[2].sense(3.3, 0.0)
    with damiao_rig(channel, motors) as bus:
        feedback = bus.exchange(dict.fromkeys(motors, ZERO_COMMAND))
    for i, (position, velocity) in ((1, (-1.2, 4.0)), (2, (3.3, 0.0))):
        assert feedback[i] is not None
        assert feedback[i].position_rad == pytest.approx(position, abs=quantum(-12.5, 12.5, 16))
        assert feedback[i].velocity_rad_s == pytest.approx(velocity, abs=quantum(-30, 30, 12))
        assert (feedback[i].fault, feedback[i].fault_code) == ("", 0)  # status 0: disabled
        assert feedback[i].temperature_C == pytest.approx(25.0, abs=0.5)
        assert kinds(motors[i]) == []


def test_damiao_enable_torque_and_hold_safe(channel):
    motor = EmulatedMotor(torque_limit_Nm=10.0)
    motor.sense(0.0, -1.0)
    with damiao_rig(channel, {1: motor}) as bus:
        bus.enable()
        bus.exchange({1: MotorCommand(torque_Nm=-2.5)})
        assert motor.torque_Nm() == pytest.approx(-2.5, abs=torque_step(J4310))
        feedback = bus.hold_safe({1: 2.0})[1]
        assert feedback is not None and feedback.fault_code == 0
        tolerance = damper_tolerance(J4310, 2.0, -1.0)
        assert motor.torque_Nm() == pytest.approx(2.0, abs=tolerance)  # −kd·v, v = −1
    assert kinds(motor) == ["enable", "command", "safe"]


def test_damiao_fault_is_reported_then_cleared(channel):
    motor = EmulatedMotor(torque_limit_Nm=10.0)
    with damiao_rig(channel, {1: motor}) as bus:
        bus.enable()
        motor.fault_code = DamiaoStatus.MOS_OVER_TEMPERATURE
        feedback = bus.exchange({1: MotorCommand(torque_Nm=1.0)})[1]
        assert (feedback.fault_code, feedback.fault) == (0xB, "MOSFET over-temperature")
        assert motor.torque_Nm() == 0.0
        bus.clear_faults()
        assert motor.fault_code == 0
        feedback = bus.exchange({1: ZERO_COMMAND})[1]
        assert (feedback.fault_code, feedback.fault) == (0, "")
        assert not motor.enabled  # cleared, still disabled until enabled again
        bus.enable()
        bus.exchange({1: MotorCommand(torque_Nm=1.0)})
        assert motor.torque_Nm() == pytest.approx(1.0, abs=torque_step(J4310))


def test_damiao_watchdog_stops_the_motor_and_reports_lost_communication(channel):
    motor = EmulatedMotor(torque_limit_Nm=10.0)
    with damiao_rig(channel, {1: motor}) as bus:
        bus.arm_watchdog(0.05)
        assert motor.watchdog_timeout_s == pytest.approx(0.05)
        assert bus.read_register(DamiaoRegister.TIMEOUT) == {1: 1000}
        bus.enable()
        bus.exchange({1: MotorCommand(torque_Nm=3.0)})
        # (the command log, not the live torque: a stalled test could outlast 50 ms here)
        assert motor.received[-1].kind == "command"
        assert motor.received[-1].command.torque_Nm == pytest.approx(3.0, abs=torque_step(J4310))
        time.sleep(0.08)  # no commands for longer than the timeout
        assert motor.torque_Nm() == 0.0
        assert motor.received[-1].kind == "watchdog"
        feedback = bus.exchange({1: MotorCommand(torque_Nm=3.0)})[1]
        assert feedback.fault_code == DamiaoStatus.COMMUNICATION_LOST
        assert feedback.fault.startswith("communication lost")
        assert motor.torque_Nm() == 0.0
        bus.clear_faults()
        assert bus.exchange({1: ZERO_COMMAND})[1].fault_code == 0


def test_damiao_watchdog_not_confirmed_raises_with_the_silent_motor(channel):
    motors = {1: EmulatedMotor(torque_limit_Nm=10.0), 2: EmulatedMotor(torque_limit_Nm=10.0)}
    motors[2].silent = True
    with damiao_rig(channel, motors) as bus:
        with pytest.raises(RegisterWriteError) as caught:
            bus.arm_watchdog(0.1)
        assert caught.value.motor_ids == (2,)
        assert isinstance(caught.value, BusError)
        assert motors[1].watchdog_timeout_s == pytest.approx(0.1)


def test_damiao_reads_its_ranges_back(channel):
    with damiao_rig(channel, {1: EmulatedMotor(torque_limit_Nm=10.0)}) as bus:
        assert bus.read_register(DamiaoRegister.PMAX) == {1: 12.5}
        assert bus.read_register(DamiaoRegister.VMAX) == {1: 30.0}
        assert bus.read_register(DamiaoRegister.TMAX) == {1: 10.0}
        assert bus.read_register(DamiaoRegister.MST_ID) == {1: 0x11}


def test_damiao_silent_and_malformed_read_as_none(channel):
    motors = {i: EmulatedMotor(torque_limit_Nm=10.0) for i in (1, 2, 3)}
    motors[2].silent = True
    with damiao_rig(channel, motors, {3: {"malformed_reply": 6}}) as bus:
        feedback = bus.exchange(dict.fromkeys(motors, ZERO_COMMAND))
    assert feedback[1] is not None
    assert feedback[2] is None
    assert feedback[3] is None


def test_damiao_motors_sharing_a_master_id(channel):
    motors = {1: EmulatedMotor(torque_limit_Nm=10.0), 2: EmulatedMotor(torque_limit_Nm=10.0)}
    motors[1].sense(1.0, 0.0)
    motors[2].sense(-1.0, 0.0)
    devices = [EmulatedDamiao(i, m, J4310, master_id=0) for i, m in motors.items()]
    config = {i: DamiaoMotor(J4310, master_id=0) for i in motors}
    with (
        serving(channel, devices),
        DamiaoBus(virtual(channel), config, reply_timeout_s=TIMEOUT_S) as bus,
    ):
        feedback = bus.exchange(dict.fromkeys(motors, ZERO_COMMAND))
    assert feedback[1].position_rad == pytest.approx(1.0, abs=1e-3)
    assert feedback[2].position_rad == pytest.approx(-1.0, abs=1e-3)
    with virtual(channel) as raw, pytest.raises(ValueError, match="low nibble"):
        DamiaoBus(raw, {1: config[1], 0x11: config[2]})
