"""DynamixelBus (through dynamixel-sdk) against emulated X-series servos on a pty."""

from __future__ import annotations

import itertools
import math
import time

import pytest

from clients.bridge.actuator import ZERO_COMMAND, BusError, MotorCommand
from clients.bridge.emulators.dynamixel import DynamixelEmulator
from clients.bridge.protocols.dynamixel import (
    ALERT_BIT,
    DYNAMIXEL_MODELS,
    POSITION_UNIT_RAD,
    VELOCITY_UNIT_RAD_S,
    CommandError,
    ControlTable,
    HardwareError,
    OperatingMode,
    PacketReader,
    StatusError,
    goal_current_from_torque,
    make_read,
    make_write,
    torque_from_current,
)
from clients.bridge.protocols.dynamixel_bus import DynamixelBus

SERVOS = {1: "XM430-W350", 2: "XH430-W350", 3: "XM540-W270", 4: "XH540-W270"}


@pytest.fixture
def rig():
    with DynamixelEmulator(SERVOS, return_delay_s=100e-6) as emulator:
        bus = DynamixelBus(emulator.port, SERVOS, name="dxl", reply_timeout_s=0.05)
        try:
            yield emulator, bus
        finally:
            bus.close()


def one_unit_torque_Nm(model_name: str) -> float:
    model = DYNAMIXEL_MODELS[model_name]
    table = model.torque_table
    slope = max((t1 - t0) / (i1 - i0) for (i0, t0), (i1, t1) in itertools.pairwise(table))
    return slope * model.current_unit_A


def test_zero_command_reads_positions_velocities_temperatures(rig):
    emulator, bus = rig
    for servo_id, motor in emulator.motors.items():
        motor.sense(0.3 * servo_id - 0.7, -0.2 * servo_id)
        motor.temperature_C = 30.0 + servo_id
    assert bus.actuator_ids == (1, 2, 3, 4)
    feedback = bus.exchange(dict.fromkeys(bus.actuator_ids, ZERO_COMMAND))
    for servo_id, reading in feedback.items():
        assert reading is not None
        assert reading.position_rad == pytest.approx(0.3 * servo_id - 0.7, abs=POSITION_UNIT_RAD)
        assert reading.velocity_rad_s == pytest.approx(-0.2 * servo_id, abs=VELOCITY_UNIT_RAD_S)
        assert reading.torque_Nm == 0.0
        assert reading.temperature_C == 30.0 + servo_id
        assert (reading.fault, reading.fault_code) == ("", 0)
    # Torque off: a zero command reaches no motor.
    assert all(not motor.enabled and not motor.received for motor in emulator.motors.values())


def test_enable_then_torque_commands(rig):
    emulator, bus = rig
    bus.exchange({})
    bus.enable()
    for servo in emulator.servos.values():
        assert servo.get(ControlTable.OPERATING_MODE) == OperatingMode.CURRENT
        assert servo.torque_on and servo.motor.enabled
    torques = {1: 1.5, 2: -2.0, 3: 7.25, 4: -0.3}
    feedback = bus.exchange({i: MotorCommand(torque_Nm=t) for i, t in torques.items()})
    for servo_id, torque_Nm in torques.items():
        model = SERVOS[servo_id]
        made = emulator.motors[servo_id].torque_Nm()
        assert made == pytest.approx(torque_Nm, abs=one_unit_torque_Nm(model))
        units = goal_current_from_torque(model, torque_Nm)
        assert emulator.servos[servo_id].get(ControlTable.GOAL_CURRENT) == units
        assert feedback[servo_id].torque_Nm == pytest.approx(made, abs=one_unit_torque_Nm(model))
        assert emulator.motors[servo_id].received[-1].kind == "command"


def test_commands_clamp_to_stall_torque(rig):
    emulator, bus = rig
    bus.enable()
    bus.exchange({i: MotorCommand(torque_Nm=-100.0) for i in SERVOS})
    for servo_id, name in SERVOS.items():
        stall = DYNAMIXEL_MODELS[name].stall_torque_Nm
        assert emulator.motors[servo_id].torque_Nm() == pytest.approx(
            -stall, abs=one_unit_torque_Nm(name)
        )


def test_hold_safe_zeroes_goal_current(rig):
    emulator, bus = rig
    bus.enable()
    bus.exchange({i: MotorCommand(torque_Nm=1.0) for i in SERVOS})
    feedback = bus.hold_safe(dict.fromkeys(SERVOS, 0.5))
    assert all(reading is not None for reading in feedback.values())
    for motor in emulator.motors.values():
        assert motor.torque_Nm() == 0.0
        assert motor.received[-1].kind == "safe"


def test_gains_and_non_finite_torques_are_refused_before_sending(rig):
    emulator, bus = rig
    bus.enable()
    before = [len(motor.received) for motor in emulator.motors.values()]
    with pytest.raises(CommandError, match="torque only") as gains:
        bus.exchange({1: MotorCommand(torque_Nm=1.0), 2: MotorCommand(kp_Nm_per_rad=5.0)})
    assert gains.value.servo_id == 2
    with pytest.raises(CommandError, match="not finite") as nan:
        bus.exchange({3: MotorCommand(torque_Nm=math.nan)})
    assert nan.value.servo_id == 3
    with pytest.raises(CommandError, match="not on bus"):
        bus.exchange({9: ZERO_COMMAND})
    assert [len(motor.received) for motor in emulator.motors.values()] == before


def test_silent_servo_is_none_others_answer(rig):
    emulator, bus = rig
    bus.enable()
    emulator.motors[2].silent = True
    feedback = bus.exchange({i: MotorCommand(torque_Nm=0.5) for i in SERVOS})
    assert feedback[2] is None
    assert all(feedback[i] is not None for i in (1, 3, 4))
    assert emulator.motors[3].torque_Nm() == pytest.approx(0.5, abs=one_unit_torque_Nm(SERVOS[3]))


def test_corrupted_reply_is_a_missed_reply(rig):
    emulator, bus = rig
    emulator.servos[3].corrupt_replies = True
    feedback = bus.exchange({})
    assert feedback[3] is None
    assert all(feedback[i] is not None for i in (1, 2, 4))
    emulator.servos[3].corrupt_replies = False
    assert bus.exchange({})[3] is not None


def test_hardware_error_is_reported_and_reboot_clears_it(rig):
    emulator, bus = rig
    bus.enable()
    motor = emulator.motors[4]
    motor.fault_code = HardwareError.OVERHEATING | HardwareError.OVERLOAD
    feedback = bus.exchange({i: MotorCommand(torque_Nm=1.0) for i in SERVOS})
    assert feedback[4].fault == "overheating error, overload error"
    assert feedback[4].fault_code == 0x24
    assert not emulator.servos[4].torque_on and motor.torque_Nm() == 0.0
    assert feedback[1].fault == ""
    # Latched: still reported, without re-reading the register each tick.
    assert bus.exchange({})[4].fault_code == 0x24
    bus.clear_faults()
    assert motor.fault_code == 0
    assert emulator.servos[4].get(ControlTable.HARDWARE_ERROR_STATUS) == 0
    assert bus.exchange({})[4].fault == ""
    bus.enable()
    bus.exchange({4: MotorCommand(torque_Nm=2.0)})
    assert motor.torque_Nm() == pytest.approx(2.0, abs=one_unit_torque_Nm(SERVOS[4]))


def test_bus_watchdog_stops_the_servo_until_cleared(rig):
    emulator, bus = rig
    bus.enable()
    bus.arm_watchdog(0.04)
    servo = emulator.servos[1]
    assert servo.get(ControlTable.BUS_WATCHDOG) == 2  # 2 × 20 ms
    bus.exchange({1: MotorCommand(torque_Nm=1.0)})
    assert servo.motor.torque_Nm() > 0.9
    time.sleep(0.1)  # no commands for longer than the watchdog
    assert servo.motor.torque_Nm() == 0.0
    assert servo.motor.received[-1].kind == "watchdog"
    bus.exchange({})  # a read lets the emulator latch the register
    assert servo.get(ControlTable.BUS_WATCHDOG) == -1
    assert servo.torque_on  # torque stays on; goals are refused
    bus.exchange({1: MotorCommand(torque_Nm=1.0)})
    assert servo.motor.torque_Nm() == 0.0
    bus.arm_watchdog(0.0)  # writing 0 clears the watchdog error
    bus.exchange({1: MotorCommand(torque_Nm=1.0)})
    assert servo.motor.torque_Nm() == pytest.approx(1.0, abs=one_unit_torque_Nm(SERVOS[1]))


def test_disable_turns_torque_off(rig):
    emulator, bus = rig
    bus.enable()
    bus.arm_watchdog(0.5)
    bus.disable()
    for servo in emulator.servos.values():
        assert not servo.torque_on and not servo.motor.enabled
        assert servo.get(ControlTable.BUS_WATCHDOG) == 0


def test_enable_fails_loudly_when_a_servo_is_missing(rig):
    emulator, bus = rig
    emulator.motors[3].silent = True
    with pytest.raises(BusError, match="servo 3 did not acknowledge"):
        bus.enable()


def test_closed_or_missing_port_raises_bus_error(rig):
    _, bus = rig
    bus.close()
    with pytest.raises(BusError):
        bus.exchange({})
    with pytest.raises(BusError, match="cannot open"):
        DynamixelBus("/dev/does-not-exist", SERVOS, name="nowhere")
    with pytest.raises(CommandError, match="not one of"):
        DynamixelBus("/dev/null", {1: "MX-28"})


# ----------------------------------------------------------------- emulator details


def _reply(emulator, request: bytes):
    (packet,) = PacketReader().feed(request)
    replies = emulator.handle(packet)
    return [PacketReader().feed(reply)[0] for _, reply in replies]


def test_emulator_eeprom_locked_with_torque_on_and_read_only_registers():
    with DynamixelEmulator({1: "XM430-W350"}) as emulator:
        mode = ControlTable.OPERATING_MODE
        (ok,) = _reply(emulator, make_write(1, mode, bytes([OperatingMode.CURRENT])))
        assert ok.status_error is StatusError.NONE
        _reply(emulator, make_write(1, ControlTable.TORQUE_ENABLE, b"\x01"))
        (locked,) = _reply(emulator, make_write(1, mode, bytes([OperatingMode.POSITION])))
        assert locked.status_error is StatusError.ACCESS
        (read_only,) = _reply(emulator, make_write(1, ControlTable.PRESENT_POSITION, bytes(4)))
        assert read_only.status_error is StatusError.ACCESS
        limit = emulator.servos[1].get(ControlTable.CURRENT_LIMIT) + 1
        goal = limit.to_bytes(2, "little", signed=True)
        (too_big,) = _reply(emulator, make_write(1, ControlTable.GOAL_CURRENT, goal))
        assert too_big.status_error is StatusError.DATA_LIMIT
        (model,) = _reply(emulator, make_read(1, ControlTable.MODEL_NUMBER, 2))
        assert int.from_bytes(model.params, "little") == 1020


def test_emulator_answers_crc_error_and_alert_bit():
    with DynamixelEmulator({5: "XM540-W270"}) as emulator:
        bad = bytearray(make_read(5, ControlTable.PRESENT_POSITION, 4))
        bad[-1] ^= 0x55
        (reply,) = _reply(emulator, bytes(bad))
        assert reply.packet_id == 5 and reply.status_error is StatusError.CRC
        emulator.motors[5].fault_code = HardwareError.INPUT_VOLTAGE
        emulator.servos[5].update()
        (alert,) = _reply(emulator, make_read(5, ControlTable.HARDWARE_ERROR_STATUS, 1))
        assert alert.error == ALERT_BIT and alert.params == b"\x01"


def test_emulator_return_delay_and_close():
    emulator = DynamixelEmulator({1: "XM430-W350"})
    assert emulator.servos[1].return_delay_s == pytest.approx(500e-6)  # X default 250 × 2 µs
    emulator.close()
    emulator.close()


def test_feedback_torque_is_the_datasheet_map(rig):
    _emulator, bus = rig
    bus.enable()
    bus.exchange({3: MotorCommand(torque_Nm=10.6)})
    reading = bus.exchange({})[3]
    units = goal_current_from_torque("XM540-W270", 10.6)
    assert reading.torque_Nm == pytest.approx(torque_from_current("XM540-W270", units * 2.69e-3))
