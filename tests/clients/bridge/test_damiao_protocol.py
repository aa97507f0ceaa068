"""Damiao DM-J frames: feedback (status nibble, temperatures), specials, 0x7FF register
frames and their replies, the TIMEOUT unit; golden bytes worked out by hand."""

import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from clients.bridge.actuator import ZERO_COMMAND
from clients.bridge.protocols.damiao import (
    DAMIAO_MOTOR_MODELS,
    DamiaoMotor,
    DamiaoRegister,
    DamiaoSpecial,
    DamiaoStatus,
    RegisterOp,
    make_feedback,
    make_register_frame,
    make_register_read,
    make_register_write,
    make_save_parameters,
    parse_feedback,
    parse_register_frame,
    register_is_uint32,
    timeout_from_register,
    timeout_to_register,
)
from clients.bridge.protocols.mit import (
    MalformedFrame,
    NonFiniteValue,
    make_command,
    make_special,
    quantum,
)

J4310 = DAMIAO_MOTOR_MODELS["DM-J4310"]  # ±12.5 rad, ±30 rad/s, ±10 N·m


def test_commands_are_mit_frames():
    assert make_command(ZERO_COMMAND, J4310) == bytes.fromhex("7F FF 7F F0 00 00 07 FF")


@pytest.mark.parametrize(
    ("code", "last"),
    [
        (DamiaoSpecial.ENABLE, "FC"),
        (DamiaoSpecial.DISABLE, "FD"),
        (DamiaoSpecial.SAVE_ZERO, "FE"),
        (DamiaoSpecial.CLEAR_ERROR, "FB"),
    ],
)
def test_special_frames(code, last):
    assert make_special(code) == bytes.fromhex("FF FF FF FF FF FF FF " + last)


def test_feedback_golden_bytes_enabled():
    frame = make_feedback(1, DamiaoStatus.ENABLED, 0.0, 0.0, 0.0, 30.0, 35.0, J4310)
    assert frame == bytes.fromhex("11 7F FF 7F F7 FF 1E 23")
    decoded = parse_feedback(frame, J4310)
    assert decoded.motor_id_low == 1
    assert decoded.status == DamiaoStatus.ENABLED
    assert decoded.mos_temperature_C == 30.0
    assert decoded.rotor_temperature_C == 35.0
    feedback = decoded.feedback
    assert feedback.temperature_C == 35.0  # the hotter
    assert (feedback.fault, feedback.fault_code) == ("", 0)
    assert feedback.position_rad == pytest.approx(32767 * 25 / 65535 - 12.5)
    assert feedback.velocity_rad_s == pytest.approx(2047 * 60 / 4095 - 30)
    assert feedback.torque_Nm == pytest.approx(2047 * 20 / 4095 - 10)


def test_feedback_with_an_error_nibble_is_a_fault():
    # id 0x12 (low nibble 2), status B; p 0xC000, v 0x400, τ 0xC00; MOS 90 °C, rotor 60 °C
    frame = bytes.fromhex("B2 C0 00 40 0C 00 5A 3C")
    decoded = parse_feedback(frame, J4310)
    assert decoded.motor_id_low == 2
    assert decoded.status == DamiaoStatus.MOS_OVER_TEMPERATURE
    assert decoded.feedback.fault_code == 0xB
    assert decoded.feedback.fault == "MOSFET over-temperature"
    assert decoded.feedback.temperature_C == 90.0
    assert decoded.feedback.position_rad == pytest.approx(0xC000 * 25 / 65535 - 12.5)
    assert decoded.feedback.velocity_rad_s == pytest.approx(0x400 * 60 / 4095 - 30)
    assert decoded.feedback.torque_Nm == pytest.approx(0xC00 * 20 / 4095 - 10)


@pytest.mark.parametrize("status", list(DamiaoStatus))
def test_every_status(status):
    frame = make_feedback(3, status, 0.0, 0.0, 0.0, 25.0, 25.0, J4310)
    assert frame[0] == (int(status) << 4) | 3
    feedback = parse_feedback(frame, J4310).feedback
    if status in (DamiaoStatus.DISABLED, DamiaoStatus.ENABLED):
        assert (feedback.fault, feedback.fault_code) == ("", 0)
    else:
        assert feedback.fault_code == int(status)
        assert feedback.fault == status.description != ""


def test_an_unknown_status_is_a_fault_with_its_code():
    feedback = parse_feedback(bytes.fromhex("51 7F FF 7F F7 FF 1E 1E"), J4310).feedback
    assert (feedback.fault_code, feedback.fault) == (5, "unknown fault code 0x5")


@pytest.mark.parametrize("length", [0, 6, 7])
def test_short_feedback_is_malformed(length):
    with pytest.raises(MalformedFrame):
        parse_feedback(bytes(length), J4310)


def test_register_request_golden_bytes():
    assert make_register_read(1, DamiaoRegister.TIMEOUT) == bytes.fromhex("01 00 33 09 00000000")
    # 50 ms = 1000 units of 50 µs = 0x3E8, uint32 little-endian
    assert make_register_write(1, DamiaoRegister.TIMEOUT, 1000) == bytes.fromhex(
        "01 00 55 09 E8 03 00 00"
    )
    # 12.5 = float32 0x41480000, little-endian
    assert make_register_write(1, DamiaoRegister.PMAX, 12.5) == bytes.fromhex(
        "01 00 55 15 00 00 48 41"
    )
    assert make_register_write(0x102, DamiaoRegister.MST_ID, 0x11) == bytes.fromhex(
        "02 01 55 07 11 00 00 00"
    )
    assert make_save_parameters(1) == bytes.fromhex("01 00 AA 01 00 00 00 00")


def test_register_replies_decode_by_type():
    reply = parse_register_frame(bytes.fromhex("01 00 55 09 E8 03 00 00"))
    assert (reply.motor_id, reply.op, reply.register, reply.value) == (
        1,
        RegisterOp.WRITE,
        DamiaoRegister.TIMEOUT,
        1000,
    )
    reply = parse_register_frame(bytes.fromhex("01 00 33 16 00 00 F0 41"))  # VMAX = 30.0
    assert (reply.op, reply.register, reply.value) == (RegisterOp.READ, DamiaoRegister.VMAX, 30.0)
    with pytest.raises(MalformedFrame, match="byte 2"):
        parse_register_frame(bytes.fromhex("01 00 44 09 00 00 00 00"))
    with pytest.raises(MalformedFrame, match="7 bytes"):
        parse_register_frame(bytes(7))


def test_register_types():
    uint32 = {7, 8, 9, 10, 13, 14, 15, 16, 35, 36}
    assert {r for r in range(82) if register_is_uint32(r)} == uint32
    with pytest.raises(ValueError, match="not an integer"):
        make_register_write(1, DamiaoRegister.TIMEOUT, 1.5)
    with pytest.raises(ValueError, match="out of"):
        make_register_write(1, DamiaoRegister.TIMEOUT, -1)
    with pytest.raises(NonFiniteValue):
        make_register_write(1, DamiaoRegister.PMAX, math.nan)


def test_timeout_unit_is_50_microseconds():
    assert timeout_to_register(0.05) == 1000
    assert timeout_to_register(1.0) == 20_000
    assert timeout_to_register(0.0) == 0  # off
    assert timeout_to_register(1e-6) == 1  # never rounded down to "off"
    assert timeout_from_register(1000) == pytest.approx(0.05)
    for bad in (-0.1, math.nan, math.inf):
        with pytest.raises(ValueError):
            timeout_to_register(bad)


def test_motor_validates_its_master_id():
    DamiaoMotor(J4310, master_id=0x11)
    with pytest.raises(ValueError, match="master_id"):
        DamiaoMotor(J4310, master_id=0x800)


models = st.sampled_from(sorted(DAMIAO_MOTOR_MODELS)).map(DAMIAO_MOTOR_MODELS.__getitem__)
wide = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False, allow_infinity=False)


@given(
    models,
    st.integers(1, 0x7FE),
    st.sampled_from(list(DamiaoStatus)),
    wide,
    wide,
    wide,
    st.floats(0, 150),
    st.floats(0, 150),
)
def test_feedback_round_trip(ranges, motor_id, status, p, v, t, mos, rotor):
    decoded = parse_feedback(make_feedback(motor_id, status, p, v, t, mos, rotor, ranges), ranges)
    assert decoded.motor_id_low == motor_id & 0xF
    assert decoded.status == status
    assert decoded.mos_temperature_C == round(mos)
    assert decoded.rotor_temperature_C == round(rotor)
    for value, got, top, bits in (
        (p, decoded.feedback.position_rad, ranges.position_max_rad, 16),
        (v, decoded.feedback.velocity_rad_s, ranges.velocity_max_rad_s, 12),
        (t, decoded.feedback.torque_Nm, ranges.torque_max_Nm, 12),
    ):
        clamped = min(max(value, -top), top)
        assert -1e-9 <= clamped - got <= quantum(-top, top, bits) * (1 + 1e-9)


@given(
    st.integers(0, 0x7FF),
    st.sampled_from([RegisterOp.READ, RegisterOp.WRITE]),
    st.sampled_from(list(DamiaoRegister)),
    st.integers(0, 0xFFFF_FFFF),
    st.floats(width=32, allow_nan=False, allow_infinity=False),
)
def test_register_frame_round_trip(motor_id, op, register, integer, real):
    value = integer if register_is_uint32(register) else real
    frame = parse_register_frame(make_register_frame(motor_id, op, register, value))
    assert (frame.motor_id, frame.op, frame.register) == (motor_id, op, register)
    assert frame.value == value
    assert struct.pack("<I" if register_is_uint32(register) else "<f", frame.value) == bytes(
        make_register_frame(motor_id, op, register, value)[4:]
    )
