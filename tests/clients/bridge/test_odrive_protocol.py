"""ODrive CANSimple frames, byte for byte (no I/O)."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from clients.bridge.protocols import odrive
from clients.bridge.protocols.odrive import (
    AxisError,
    AxisError05,
    AxisState,
    Command,
    ControlMode,
    Firmware,
    Heartbeat,
    InputMode,
    InvalidCommand,
    MalformedFrame,
    arbitration_id,
    describe_axis_error,
    make_clear_errors,
    make_encoder_estimates,
    make_estop,
    make_heartbeat,
    make_request,
    make_rx_sdo_read,
    make_rx_sdo_write,
    make_set_axis_state,
    make_set_controller_mode,
    make_set_input_torque,
    make_temperature,
    make_torques,
    parse_clear_errors,
    parse_encoder_estimates,
    parse_heartbeat,
    parse_rx_sdo,
    parse_set_axis_state,
    parse_set_controller_mode,
    parse_set_input_torque,
    parse_temperature,
    parse_torques,
    split_arbitration_id,
)

FLOAT32_MAX = 3.4028234663852886e38


def f32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


def test_public_names_exist():
    for name in odrive.__all__:
        assert hasattr(odrive, name), name


# ---------------------------------------------------------------- golden bytes


def test_command_ids_match_the_06_reference():
    assert Command.HEARTBEAT == 0x01
    assert Command.ESTOP == 0x02
    assert Command.GET_ERROR == 0x03
    assert Command.RX_SDO == 0x04
    assert Command.TX_SDO == 0x05
    assert Command.SET_AXIS_STATE == 0x07
    assert Command.GET_ENCODER_ESTIMATES == 0x09
    assert Command.SET_CONTROLLER_MODE == 0x0B
    assert Command.SET_INPUT_TORQUE == 0x0E
    assert Command.GET_IQ == 0x14
    assert Command.GET_TEMPERATURE == 0x15
    assert Command.CLEAR_ERRORS == 0x18
    assert Command.GET_TORQUES == 0x1C
    assert AxisState.IDLE == 1
    assert AxisState.CLOSED_LOOP_CONTROL == 8
    assert ControlMode.TORQUE_CONTROL == 1
    assert InputMode.PASSTHROUGH == 1
    assert AxisError.WATCHDOG_TIMER_EXPIRED == 0x0100_0000
    assert AxisError.ESTOP_REQUESTED == 0x0200_0000
    assert AxisError05.WATCHDOG_TIMER_EXPIRED == 0x800
    assert AxisError05.ESTOP_REQUESTED == 0x4000


def test_arbitration_id_packs_node_then_command():
    assert arbitration_id(0x01, 0x0C) == 0x2C  # the reference's example
    assert arbitration_id(3, Command.SET_INPUT_TORQUE) == 0x06E
    assert arbitration_id(0x3F, 0x1F) == 0x7FF
    assert split_arbitration_id(0x06E) == (3, 0x0E)
    with pytest.raises(InvalidCommand):
        arbitration_id(64, 0)
    with pytest.raises(InvalidCommand):
        arbitration_id(0, 32)


def test_set_input_torque_golden():
    frame = make_set_input_torque(3, 1.5)
    assert frame.arbitration_id == 0x06E
    assert not frame.is_extended_id and not frame.is_remote_frame
    assert bytes(frame.data) == bytes.fromhex("0000c03f")
    assert bytes(make_set_input_torque(0, -2.0).data) == bytes.fromhex("000000c0")


def test_set_input_torque_clamps_at_and_beyond_the_limit():
    def sent(torque: float) -> float:
        return parse_set_input_torque(make_set_input_torque(1, torque, torque_limit_Nm=2.0).data)

    assert sent(2.0) == 2.0
    assert sent(1.999) == f32(1.999)
    assert sent(2.5) == 2.0
    assert sent(-7.0) == -2.0
    assert sent(math.inf) == 2.0
    assert sent(-math.inf) == -2.0


def test_set_input_torque_refuses_nan_and_unclampable_values():
    with pytest.raises(InvalidCommand, match="NaN") as caught:
        make_set_input_torque(4, math.nan)
    assert caught.value.node_id == 4 and caught.value.field == "torque_Nm"
    with pytest.raises(InvalidCommand, match="NaN"):
        make_set_input_torque(4, math.nan, torque_limit_Nm=1.0)
    with pytest.raises(InvalidCommand, match="torque limit"):
        make_set_input_torque(4, math.inf)
    with pytest.raises(InvalidCommand, match="float32"):
        make_set_input_torque(4, 1e39)


def test_state_and_mode_frames_golden():
    frame = make_set_axis_state(1, AxisState.CLOSED_LOOP_CONTROL)
    assert frame.arbitration_id == 0x027
    assert bytes(frame.data) == bytes.fromhex("08000000")
    assert bytes(make_set_axis_state(1, AxisState.IDLE).data) == bytes.fromhex("01000000")
    frame = make_set_controller_mode(1, ControlMode.TORQUE_CONTROL, InputMode.PASSTHROUGH)
    assert frame.arbitration_id == 0x02B
    assert bytes(frame.data) == bytes.fromhex("0100000001000000")
    assert parse_set_axis_state(bytes.fromhex("08000000")) is AxisState.CLOSED_LOOP_CONTROL
    assert parse_set_controller_mode(bytes.fromhex("0100000001000000")) == (
        ControlMode.TORQUE_CONTROL,
        InputMode.PASSTHROUGH,
    )


def test_estop_and_clear_errors_golden():
    frame = make_estop(5)
    assert (frame.arbitration_id, bytes(frame.data)) == (0x0A2, b"")
    frame = make_clear_errors(2)
    assert (frame.arbitration_id, bytes(frame.data)) == (0x058, b"\x00")
    assert bytes(make_clear_errors(2, identify=True).data) == b"\x01"
    assert parse_clear_errors(b"") is False
    assert parse_clear_errors(b"\x01") is True


def test_requests_are_remote_frames():
    frame = make_request(1, Command.GET_ENCODER_ESTIMATES)
    assert frame.arbitration_id == 0x029
    assert frame.is_remote_frame and not frame.is_extended_id
    assert frame.dlc == 8 and bytes(frame.data) == b""
    assert make_request(2, Command.GET_TORQUES).arbitration_id == 0x05C
    assert make_request(2, Command.GET_TEMPERATURE).arbitration_id == 0x055
    assert make_request(2, Command.HEARTBEAT).arbitration_id == 0x041
    with pytest.raises(InvalidCommand):
        make_request(2, Command.SET_INPUT_TORQUE)


def test_heartbeat_06_layout():
    # The docs.rs odrive-can-protocol example frame: id 0x021, node 1.
    heartbeat = parse_heartbeat(bytes.fromhex("0100008008000100"))
    assert heartbeat == Heartbeat(
        axis_error=0x8000_0001, axis_state=8, procedure_result=0, trajectory_done=True
    )
    heartbeat = parse_heartbeat(bytes.fromhex("0000000101030000"))
    assert heartbeat.axis_error == AxisError.WATCHDOG_TIMER_EXPIRED
    assert heartbeat.axis_state == AxisState.IDLE
    assert heartbeat.procedure_result == 3
    frame = make_heartbeat(1, Heartbeat(axis_error=0x0200_0000, axis_state=1))
    assert frame.arbitration_id == 0x021
    assert bytes(frame.data) == bytes.fromhex("0000000201000000")


def test_heartbeat_05_layout():
    data = bytes.fromhex("0008000008010081")
    heartbeat = parse_heartbeat(data, firmware=Firmware.V0_5)
    assert heartbeat == Heartbeat(
        axis_error=AxisError05.WATCHDOG_TIMER_EXPIRED,
        axis_state=AxisState.CLOSED_LOOP_CONTROL,
        trajectory_done=True,
        motor_error_flag=True,
        encoder_error_flag=False,
        controller_error_flag=True,
    )
    assert bytes(make_heartbeat(0, heartbeat, firmware=Firmware.V0_5).data) == data
    # The same bytes read as 0.6: byte 5 is the procedure result, 6 the trajectory flag.
    as_06 = parse_heartbeat(data)
    assert (as_06.procedure_result, as_06.trajectory_done) == (1, False)


def test_feedback_frames_golden():
    frame = make_encoder_estimates(1, 0.5, -1.0)
    assert frame.arbitration_id == 0x029
    assert bytes(frame.data) == bytes.fromhex("0000003f000080bf")
    estimates = parse_encoder_estimates(bytes(frame.data))
    assert (estimates.position_turns, estimates.velocity_turns_s) == (0.5, -1.0)
    torques = parse_torques(bytes.fromhex("0000803f00000040"))
    assert (torques.target_Nm, torques.estimate_Nm) == (1.0, 2.0)
    assert make_torques(1, 1.0, 2.0).arbitration_id == 0x03C
    temperature = parse_temperature(bytes.fromhex("000020420000de42"))
    assert (temperature.fet_C, temperature.motor_C) == (40.0, 111.0)
    assert bytes(make_temperature(1, 40.0, 111.0).data) == bytes.fromhex("000020420000de42")


def test_rx_sdo_watchdog_writes_golden():
    frame = make_rx_sdo_write(0, 201, True, "bool")
    assert frame.arbitration_id == 0x004
    assert bytes(frame.data) == bytes.fromhex("01c9000001")
    frame = make_rx_sdo_write(2, 200, 0.05, "float")
    assert frame.arbitration_id == 0x044
    assert bytes(frame.data) == bytes.fromhex("01c80000cdcc4c3d")
    request = parse_rx_sdo(bytes(frame.data))
    assert (request.opcode, request.endpoint_id) == (1, 200)
    assert struct.unpack("<f", request.value)[0] == f32(0.05)
    assert bytes(make_rx_sdo_read(2, 0x1234).data) == bytes.fromhex("00341200")
    with pytest.raises(InvalidCommand):
        make_rx_sdo_write(0, 200, math.nan, "float")
    with pytest.raises(InvalidCommand):
        make_rx_sdo_write(0, 200, 1.0, "double")
    with pytest.raises(InvalidCommand):
        make_rx_sdo_write(0, 0x10000, 1, "uint32")
    with pytest.raises(InvalidCommand):
        make_rx_sdo_write(0, 200, 300, "uint8")


def test_short_or_bad_payloads_are_malformed():
    with pytest.raises(MalformedFrame):
        parse_set_input_torque(b"\x00\x00\x00")
    with pytest.raises(MalformedFrame):
        parse_encoder_estimates(bytes(7))
    with pytest.raises(MalformedFrame, match="NaN"):
        parse_encoder_estimates(struct.pack("<ff", math.nan, 0.0))
    with pytest.raises(MalformedFrame):
        parse_heartbeat(bytes(5))
    with pytest.raises(MalformedFrame):
        parse_set_axis_state(struct.pack("<I", 99))
    with pytest.raises(MalformedFrame):
        parse_set_controller_mode(struct.pack("<II", 9, 1))


def test_describe_axis_error_names_bits():
    assert describe_axis_error(0) == ""
    assert describe_axis_error(0x0100_0000) == "WATCHDOG_TIMER_EXPIRED"
    assert describe_axis_error(0x0300_0000) == "WATCHDOG_TIMER_EXPIRED|ESTOP_REQUESTED"
    assert describe_axis_error(0x800, Firmware.V0_5) == "WATCHDOG_TIMER_EXPIRED"
    assert describe_axis_error(0x800) == "DC_BUS_OVER_REGEN_CURRENT"
    assert describe_axis_error(0x8000_0000) == "0x80000000"


# ---------------------------------------------------------------- round trips

finite32 = st.floats(-FLOAT32_MAX, FLOAT32_MAX, allow_nan=False, allow_infinity=False, width=32)
nodes = st.integers(0, 0x3F)


@given(nodes, st.integers(0, 0x1F))
def test_arbitration_id_round_trip(node_id, command):
    identifier = arbitration_id(node_id, command)
    assert identifier < 0x800
    assert split_arbitration_id(identifier) == (node_id, command)


@given(nodes, finite32)
def test_torque_round_trip(node_id, torque):
    frame = make_set_input_torque(node_id, torque)
    assert split_arbitration_id(frame.arbitration_id) == (node_id, Command.SET_INPUT_TORQUE)
    assert parse_set_input_torque(frame.data) == torque


@given(st.floats(allow_nan=False), st.floats(1e-3, 1e3))
def test_clamped_torque_never_exceeds_the_limit(torque, limit):
    sent = parse_set_input_torque(make_set_input_torque(0, torque, torque_limit_Nm=limit).data)
    assert abs(sent) <= f32(limit)
    if abs(torque) <= limit:
        assert sent == f32(torque)


@given(finite32, finite32)
def test_encoder_estimates_round_trip(position, velocity):
    estimates = parse_encoder_estimates(make_encoder_estimates(7, position, velocity).data)
    assert (estimates.position_turns, estimates.velocity_turns_s) == (position, velocity)


@given(
    st.integers(0, 0xFFFF_FFFF),
    st.integers(0, 14),
    st.integers(0, 255),
    st.booleans(),
)
def test_heartbeat_06_round_trip(error, state, result, done):
    heartbeat = Heartbeat(error, state, procedure_result=result, trajectory_done=done)
    assert parse_heartbeat(make_heartbeat(9, heartbeat).data) == heartbeat


@given(st.integers(0, 0xFFFF_FFFF), st.integers(0, 14), st.booleans(), st.booleans(), st.booleans())
def test_heartbeat_05_round_trip(error, state, motor, encoder, controller):
    heartbeat = Heartbeat(
        error,
        state,
        trajectory_done=controller,
        motor_error_flag=motor,
        encoder_error_flag=encoder,
        controller_error_flag=not controller,
    )
    frame = make_heartbeat(9, heartbeat, firmware=Firmware.V0_5)
    assert parse_heartbeat(frame.data, firmware=Firmware.V0_5) == heartbeat


@given(nodes, st.integers(0, 0xFFFF), finite32)
def test_rx_sdo_float_round_trip(node_id, endpoint_id, value):
    request = parse_rx_sdo(make_rx_sdo_write(node_id, endpoint_id, value, "float").data)
    assert (request.opcode, request.endpoint_id) == (1, endpoint_id)
    assert struct.unpack("<f", request.value)[0] == value
