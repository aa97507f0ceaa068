"""MIT-mode frames: golden bytes (worked out by hand from the firmware's formulas), clamping,
NaN refusal, specials, both reply layouts, and round-trip / no-bleed properties."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from clients.bridge.actuator import ZERO_COMMAND, MotorCommand
from clients.bridge.protocols.mit import (
    MIT_MOTOR_MODELS,
    CubeMarsFault,
    MalformedFrame,
    MitRanges,
    MitSpecial,
    NonFiniteValue,
    clamp_command,
    float_to_uint,
    make_command,
    make_reply,
    make_special,
    parse_command,
    parse_reply,
    parse_special,
    quantum,
    uint_to_float,
    unpack_command_codes,
)

AK80_9 = MIT_MOTOR_MODELS["AK80-9"]  # ±12.5 rad, ±50 rad/s, ±18 N·m, kp 0–500, kd 0–5
FIELDS = ("position_rad", "velocity_rad_s", "kp_Nm_per_rad", "kd_Nm_s_per_rad", "torque_Nm")
# Bits of each field in the frame read as one big-endian 64-bit integer.
MASKS = {
    "position_rad": 0xFFFF << 48,
    "velocity_rad_s": 0xFFF << 36,
    "kp_Nm_per_rad": 0xFFF << 24,
    "kd_Nm_s_per_rad": 0xFFF << 12,
    "torque_Nm": 0xFFF,
}


def limits(ranges: MitRanges) -> dict[str, tuple[float, float]]:
    return {
        "position_rad": (-ranges.position_max_rad, ranges.position_max_rad),
        "velocity_rad_s": (-ranges.velocity_max_rad_s, ranges.velocity_max_rad_s),
        "kp_Nm_per_rad": (0.0, ranges.kp_max_Nm_per_rad),
        "kd_Nm_s_per_rad": (0.0, ranges.kd_max_Nm_s_per_rad),
        "torque_Nm": (-ranges.torque_max_Nm, ranges.torque_max_Nm),
    }


def steps(ranges: MitRanges) -> dict[str, float]:
    return {
        name: quantum(lo, hi, 16 if name == "position_rad" else 12)
        for name, (lo, hi) in limits(ranges).items()
    }


# --- golden bytes -------------------------------------------------------------------------


@pytest.mark.parametrize("model", sorted(MIT_MOTOR_MODELS))
def test_zero_command_is_the_documented_frame_for_every_model(model):
    assert make_command(ZERO_COMMAND, MIT_MOTOR_MODELS[model]) == bytes.fromhex(
        "7F FF 7F F0 00 00 07 FF"
    )


def test_a_mixed_command_packs_msb_first_with_truncation():
    # p: (1+12.5)·65535/25 = 35388.9 → 0x8A3C;  v: (−10+50)·4095/100 = 1638 → 0x666;
    # kp: 50·4095/500 = 409.5 → 0x199;  kd: 1·4095/5 = 819 → 0x333;  τ: 21·4095/36 = 2388.75 → 0x954
    command = MotorCommand(1.0, -10.0, 50.0, 1.0, 3.0)
    assert make_command(command, AK80_9) == bytes.fromhex("8A 3C 66 61 99 33 39 54")


def test_every_field_at_its_maximum_and_minimum():
    top = MotorCommand(12.5, 50.0, 500.0, 5.0, 18.0)
    bottom = MotorCommand(-12.5, -50.0, 0.0, 0.0, -18.0)
    assert make_command(top, AK80_9) == bytes.fromhex("FF FF FF FF FF FF FF FF")
    assert make_command(bottom, AK80_9) == bytes.fromhex("00 00 00 00 00 00 00 00")


@pytest.mark.parametrize("field", FIELDS)
@pytest.mark.parametrize("side", [0, 1])
def test_each_field_clamps_at_and_beyond_its_limit_without_touching_the_others(field, side):
    limit = limits(AK80_9)[field][side]
    beyond = limit + (1.0 if side else -1.0) * 1e6
    at = make_command(MotorCommand(**{field: limit}), AK80_9)
    for value in (beyond, limit + (0.5 if side else -0.5), math.copysign(math.inf, beyond)):
        if math.isinf(value):
            continue  # refused, see below
        frame = make_command(MotorCommand(**{field: value}), AK80_9)
        assert frame == at
    zero = int.from_bytes(make_command(ZERO_COMMAND, AK80_9), "big")
    changed = int.from_bytes(at, "big") ^ zero
    assert changed & ~MASKS[field] == 0
    expected_code = ((1 << (16 if field == "position_rad" else 12)) - 1) if side else 0
    shift = {"position_rad": 48, "velocity_rad_s": 36, "kp_Nm_per_rad": 24}.get(field)
    shift = shift if shift is not None else (12 if field == "kd_Nm_s_per_rad" else 0)
    assert (int.from_bytes(at, "big") & MASKS[field]) >> shift == expected_code


@pytest.mark.parametrize("field", FIELDS)
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_field_is_refused_with_its_name(field, bad):
    with pytest.raises(NonFiniteValue) as caught:
        make_command(MotorCommand(**{field: bad}), AK80_9)
    assert caught.value.field == field
    assert field in str(caught.value)
    assert isinstance(caught.value, ValueError)


def test_a_command_that_would_read_as_a_special_frame_is_moved_one_position_step():
    # All at maximum with τ code 0xFFC packs as FF…FF FC = "enter motor mode".
    torque = uint_to_float(0xFFC, -18.0, 18.0, 12) + 1e-9
    assert float_to_uint(torque, -18.0, 18.0, 12) == 0xFFC
    frame = make_command(MotorCommand(12.5, 50.0, 500.0, 5.0, torque), AK80_9)
    assert frame == bytes.fromhex("FF FE FF FF FF FF FF FC")
    assert parse_special(frame) is None
    assert unpack_command_codes(frame) == (0xFFFE, 0xFFF, 0xFFF, 0xFFF, 0xFFC)


@pytest.mark.parametrize(
    ("code", "frame"),
    [
        (MitSpecial.ENTER_MOTOR_MODE, "FF FF FF FF FF FF FF FC"),
        (MitSpecial.EXIT_MOTOR_MODE, "FF FF FF FF FF FF FF FD"),
        (MitSpecial.SET_ZERO, "FF FF FF FF FF FF FF FE"),
    ],
)
def test_special_frames(code, frame):
    assert make_special(code) == bytes.fromhex(frame)
    assert parse_special(bytes.fromhex(frame)) == code
    with pytest.raises(MalformedFrame):
        parse_command(bytes.fromhex(frame), AK80_9)


def test_not_special_frames():
    assert parse_special(bytes.fromhex("FF FF FF FF FF FF FF FF")) is None
    assert parse_special(bytes.fromhex("FF FF FF FF FF FF FC")) is None
    assert parse_special(bytes.fromhex("FF FF FF FF FF FF FE FC")) is None
    with pytest.raises(ValueError, match="special code"):
        make_special(0x12)


def test_parse_command_decodes_like_the_firmware():
    command = parse_command(bytes.fromhex("7F FF 7F F0 00 00 07 FF"), AK80_9)
    assert command.position_rad == pytest.approx(32767 * 25 / 65535 - 12.5)
    assert command.velocity_rad_s == pytest.approx(-50 / 4095)
    assert command.kp_Nm_per_rad == 0.0
    assert command.kd_Nm_s_per_rad == 0.0
    assert command.torque_Nm == pytest.approx(-18 / 4095)  # zero quantizes one half-step down
    with pytest.raises(MalformedFrame, match="7 bytes"):
        parse_command(bytes(7), AK80_9)


# --- replies ------------------------------------------------------------------------------


def test_six_byte_bgkatz_reply():
    assert make_reply(1, 0.0, 0.0, 0.0, AK80_9) == bytes.fromhex("01 7F FF 7F F7 FF")
    # p 0xC000, v 0x400, τ 0xC00
    reply = parse_reply(bytes.fromhex("05 C0 00 40 0C 00"), AK80_9)
    assert reply.motor_id == 5
    assert reply.feedback.position_rad == pytest.approx(0xC000 * 25 / 65535 - 12.5)
    assert reply.feedback.velocity_rad_s == pytest.approx(0x400 * 100 / 4095 - 50)
    assert reply.feedback.torque_Nm == pytest.approx(0xC00 * 36 / 4095 - 18)
    assert reply.feedback.temperature_C is None
    assert (reply.feedback.fault, reply.feedback.fault_code) == ("", 0)


def test_eight_byte_cubemars_reply_carries_temperature_and_error():
    frame = make_reply(1, 0.0, 0.0, 0.0, AK80_9, temperature_C=40.2, fault_code=2)
    assert frame == bytes.fromhex("01 7F FF 7F F7 FF 28 02")
    feedback = parse_reply(frame, AK80_9).feedback
    assert feedback.temperature_C == 40.0
    assert feedback.fault_code == 2
    assert feedback.fault == CubeMarsFault.OVER_CURRENT.description == "over-current"
    cold = parse_reply(bytes.fromhex("01 7F FF 7F F7 FF EC 00"), AK80_9).feedback
    assert cold.temperature_C == -20.0
    assert (cold.fault, cold.fault_code) == ("", 0)
    unknown = parse_reply(bytes.fromhex("01 7F FF 7F F7 FF 28 63"), AK80_9).feedback
    assert unknown.fault == "unknown fault code 99"


@pytest.mark.parametrize("length", [0, 5, 7, 9])
def test_a_reply_of_another_length_is_malformed(length):
    with pytest.raises(MalformedFrame, match=f"{length} bytes"):
        parse_reply(bytes(length), AK80_9)


def test_ranges_are_validated():
    with pytest.raises(ValueError, match="torque_max_Nm"):
        MitRanges(12.5, 50.0, 0.0)
    with pytest.raises(ValueError, match="position_max_rad"):
        MitRanges(math.nan, 50.0, 18.0)


# --- properties ---------------------------------------------------------------------------

ranges_strategy = st.sampled_from(sorted(MIT_MOTOR_MODELS)).map(MIT_MOTOR_MODELS.__getitem__)
wide = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False, allow_infinity=False)
commands = st.builds(MotorCommand, wide, wide, wide, wide, wide)


@given(ranges_strategy, commands)
def test_round_trip_is_within_one_quantization_step_of_the_clamped_command(ranges, command):
    frame = make_command(command, ranges)
    decoded = parse_command(frame, ranges)
    clamped = clamp_command(command, ranges)
    step = steps(ranges)
    codes = unpack_command_codes(frame)
    moved = codes[0] == 0xFFFE and codes[1:4] == (0xFFF, 0xFFF, 0xFFF)  # special collision
    for name in FIELDS:
        error = getattr(clamped, name) - getattr(decoded, name)
        allowed = step[name] * (2 if name == "position_rad" and moved else 1)
        assert -1e-9 <= error <= allowed * (1 + 1e-9), name  # truncation: never above


@given(ranges_strategy, commands, st.sampled_from(FIELDS), wide)
def test_changing_one_field_changes_only_its_bits(ranges, command, field, value):
    values = {name: getattr(command, name) for name in FIELDS}
    a = make_command(MotorCommand(**values), ranges)
    b = make_command(MotorCommand(**{**values, field: value}), ranges)
    diff = int.from_bytes(a, "big") ^ int.from_bytes(b, "big")
    # A frame moved off a special code has its position one step lower (tested above).
    moved = any(frame[:7] == bytes.fromhex("FF FE FF FF FF FF FF") for frame in (a, b))
    ignore = MASKS["position_rad"] if moved else 0
    assert diff & ~(MASKS[field] | ignore) == 0


@given(
    ranges_strategy,
    st.integers(1, 255),
    wide,
    wide,
    wide,
    st.one_of(st.none(), st.floats(-20, 127)),
    st.integers(0, 7),
)
def test_reply_round_trip(ranges, motor_id, position, velocity, torque, temperature, fault):
    reply = parse_reply(
        make_reply(
            motor_id,
            position,
            velocity,
            torque,
            ranges,
            temperature_C=temperature,
            fault_code=fault,
        ),
        ranges,
    )
    step = steps(ranges)
    clamped = clamp_command(MotorCommand(position, velocity, 0.0, 0.0, torque), ranges)
    assert reply.motor_id == motor_id
    for name, got in (
        ("position_rad", reply.feedback.position_rad),
        ("velocity_rad_s", reply.feedback.velocity_rad_s),
        ("torque_Nm", reply.feedback.torque_Nm),
    ):
        assert -1e-9 <= getattr(clamped, name) - got <= step[name] * (1 + 1e-9)
    if temperature is None:
        assert reply.feedback.temperature_C is None
    else:
        assert reply.feedback.temperature_C == round(temperature)
        assert reply.feedback.fault_code == fault
