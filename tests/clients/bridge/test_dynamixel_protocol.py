"""Dynamixel Protocol 2.0: golden bytes from the e-Manual and from dynamixel-sdk, torque map.

Golden packets are the worked examples of the ROBOTIS e-Manual, Protocol 2.0
(https://emanual.robotis.com/docs/en/dxl/protocol2/, ``ROBOTIS-GIT/emanual``
``docs/en/dxl/protocol2.md``), for an XM430-W210 with ID 1 (and 2).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
import threading
import tty

import dynamixel_sdk as sdk
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import clients.bridge.protocols.dynamixel as dxl
from clients.bridge.protocols.dynamixel import (
    ALERT_BIT,
    DYNAMIXEL_MODELS,
    FEEDBACK_LENGTH_BYTES,
    CommandError,
    ControlTable,
    HardwareError,
    Instruction,
    Packet,
    PacketError,
    PacketReader,
    StatusError,
    crc16,
    current_from_torque,
    decode_feedback,
    describe_hardware_error,
    goal_current_from_torque,
    make_packet,
    make_ping,
    make_read,
    make_reboot,
    make_status,
    make_sync_read,
    make_sync_write,
    make_write,
    parse_packet,
    stuff,
    torque_from_current,
    unstuff,
    watchdog_register_from_timeout,
)


def h(text: str) -> bytes:
    return bytes.fromhex(text)


def test_all_names_exported():
    for name in dxl.__all__:
        assert hasattr(dxl, name), name


# ----------------------------------------------------------------- e-Manual golden bytes


def test_ping_golden():
    assert make_ping(1) == h("FF FF FD 00 01 03 00 01 19 4E")
    assert make_ping(dxl.BROADCAST_ID) == h("FF FF FD 00 FE 03 00 01 31 42")
    # Model number 1030 (0x0406), firmware 38 (0x26).
    assert make_status(1, 0, h("06 04 26")) == h("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D")
    assert make_status(2, 0, h("06 04 26")) == h("FF FF FD 00 02 07 00 55 00 06 04 26 6F 6D")
    reply = parse_packet(h("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D"))
    assert reply == Packet(1, Instruction.STATUS, h("06 04 26"), 0)
    assert int.from_bytes(reply.params[:2], "little") == 1030


def test_read_golden():
    # Present Position (132, 4 bytes) = 166.
    assert make_read(1, ControlTable.PRESENT_POSITION, 4) == h(
        "FF FF FD 00 01 07 00 02 84 00 04 00 1D 15"
    )
    reply = h("FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0")
    assert make_status(1, 0, (166).to_bytes(4, "little")) == reply
    packet = parse_packet(reply)
    assert packet.is_status and packet.error == 0
    assert int.from_bytes(packet.params, "little") == 166


def test_write_golden():
    # Goal Position (116, 4 bytes) = 512.
    assert make_write(1, ControlTable.GOAL_POSITION, (512).to_bytes(4, "little")) == h(
        "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89"
    )
    assert make_status(1) == h("FF FF FD 00 01 04 00 55 00 A1 0C")
    assert parse_packet(h("FF FF FD 00 01 04 00 55 00 A1 0C")) == Packet(1, 0x55, b"", 0)


def test_reboot_and_other_instructions_golden():
    assert make_reboot(1) == h("FF FF FD 00 01 03 00 08 2F 4E")
    assert make_packet(1, Instruction.ACTION) == h("FF FF FD 00 01 03 00 05 02 CE")
    assert make_packet(1, Instruction.FACTORY_RESET, h("01")) == h(
        "FF FF FD 00 01 04 00 06 01 A1 E6"
    )
    assert make_packet(1, Instruction.REG_WRITE, h("68 00 C8 00 00 00")) == h(
        "FF FF FD 00 01 09 00 04 68 00 C8 00 00 00 AE 8E"
    )
    assert make_packet(1, Instruction.CLEAR, h("01 44 58 4C 22")) == h(
        "FF FF FD 00 01 08 00 10 01 44 58 4C 22 B1 DC"
    )
    assert make_packet(
        dxl.BROADCAST_ID, Instruction.BULK_READ, h("01 90 00 02 00 02 92 00 01 00")
    ) == h("FF FF FD 00 FE 0D 00 92 01 90 00 02 00 02 92 00 01 00 1A 05")


def test_sync_read_golden():
    assert make_sync_read(ControlTable.PRESENT_POSITION, 4, [1, 2]) == h(
        "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA"
    )
    first = parse_packet(h("FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0"))
    second = parse_packet(h("FF FF FD 00 02 08 00 55 00 1F 08 00 00 BA BE"))
    assert int.from_bytes(first.params, "little") == 166
    assert int.from_bytes(second.params, "little") == 2079


def test_sync_write_golden():
    packet = make_sync_write(
        ControlTable.GOAL_POSITION,
        4,
        {1: (150).to_bytes(4, "little"), 2: (170).to_bytes(4, "little")},
    )
    assert packet == h("FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87")
    with pytest.raises(PacketError, match="sync write needs 4"):
        make_sync_write(ControlTable.GOAL_POSITION, 4, {1: b"\x00\x00"})


def test_bulk_read_status_golden():
    assert make_status(1, 0, h("77 00")) == h("FF FF FD 00 01 06 00 55 00 77 00 C3 69")
    assert make_status(2, 0, h("24")) == h("FF FF FD 00 02 05 00 55 00 24 8B A9")


# ----------------------------------------------------------------- CRC, stuffing, parsing


def test_crc16_is_crc16_buypass():
    # Catalogue check value of CRC-16/BUYPASS (poly 0x8005, init 0, no reflection).
    assert crc16(b"123456789") == 0xFEE8
    assert crc16(b"") == 0
    assert crc16(b"6789", crc16(b"12345")) == 0xFEE8


def test_stuffing():
    assert stuff(h("FF FF FD")) == h("FF FF FD FD")
    assert stuff(h("FF FF FD FD")) == h("FF FF FD FD FD")
    assert stuff(h("FF FF FF FD 00 FF FF FD")) == h("FF FF FF FD FD 00 FF FF FD FD")
    assert unstuff(h("FF FF FD FD FD")) == h("FF FF FD FD")
    with pytest.raises(PacketError, match="stuffing"):
        unstuff(h("FF FF FD 00"))


def test_stuffed_packet_length_and_crc():
    # Writing FF FF FD at Goal Position: LEN counts the stuffing byte, CRC covers it.
    packet = make_write(1, ControlTable.GOAL_POSITION, h("FF FF FD 00"))
    assert packet[5:7] == (10).to_bytes(2, "little")
    assert packet[7:15] == h("03 74 00 FF FF FD FD 00")
    assert crc16(packet[:-2]) == int.from_bytes(packet[-2:], "little")
    assert parse_packet(packet).params == h("74 00 FF FF FD 00")


def test_status_error_byte_and_alert_bit():
    packet = parse_packet(make_status(3, ALERT_BIT | StatusError.ACCESS))
    assert packet.alert
    assert packet.status_error is StatusError.ACCESS
    assert "EEPROM" in packet.status_error.description
    crc_error = parse_packet(make_status(3, StatusError.CRC))
    assert not crc_error.alert and crc_error.status_error is StatusError.CRC
    assert parse_packet(make_status(3, 0x7E)).status_error == 0x7E


def test_parse_rejects_bad_packets():
    good = make_read(1, 132, 4)
    with pytest.raises(PacketError) as crc:
        parse_packet(good[:-1] + bytes([good[-1] ^ 1]))
    assert crc.value.field == "crc" and crc.value.packet_id == 1
    with pytest.raises(PacketError) as header:
        parse_packet(b"\xff\xff\xfe\x00" + good[4:])
    assert header.value.field == "header"
    with pytest.raises(PacketError) as length:
        parse_packet(good[:-3])
    assert length.value.field == "length"
    with pytest.raises(PacketError):
        make_ping(253)  # 0xFD looks like the header: never an ID


def test_reader_splits_stream_skips_garbage_and_reports_crc():
    first, second = make_status(1, 0, h("A6 00")), make_status(2, ALERT_BIT, h("1F 08"))
    bad = bytearray(make_status(3, 0, h("00 00")))
    bad[-1] ^= 0xFF
    reader = PacketReader()
    stream = h("00 FF 13") + first + bytes(bad) + second
    results = []
    for i in range(0, len(stream), 5):
        results += reader.feed(stream[i : i + 5])
    assert results[0] == parse_packet(first)
    assert isinstance(results[1], PacketError) and results[1].field == "crc"
    assert results[1].packet_id == 3
    assert results[2] == parse_packet(second) and results[2].alert


@given(
    packet_id=st.integers(0, 0xFC) | st.just(0xFE),
    instruction=st.sampled_from(list(Instruction)),
    params=st.binary(max_size=64)
    | st.lists(st.sampled_from([b"\xff", b"\xfd", b"\x00"]), max_size=24).map(b"".join),
)
def test_make_parse_round_trip(packet_id, instruction, params):
    assume(instruction != Instruction.STATUS or params)  # a status needs its error byte
    raw = make_packet(packet_id, instruction, params)
    assert crc16(raw[:-2]) == int.from_bytes(raw[-2:], "little")
    packet = parse_packet(raw)
    assert packet.packet_id == packet_id and packet.instruction == instruction
    if instruction == Instruction.STATUS:
        assert (packet.error, packet.params) == (params[0], params[1:])
    elif instruction != Instruction.STATUS:
        assert packet.params == params


@given(st.lists(st.sampled_from([b"\xff", b"\xfd", b"\x00", b"\x55"]), max_size=40).map(b"".join))
def test_stuffing_round_trip_and_no_header_inside(body):
    stuffed = stuff(body)
    assert unstuff(stuffed) == body
    # After stuffing, every FF FF FD is followed by FD: no header can start inside.
    for i in range(len(stuffed) - 2):
        if stuffed[i : i + 3] == h("FF FF FD"):
            assert stuffed[i + 3 : i + 4] == h("FD")


@given(
    st.lists(st.tuples(st.integers(0, 0xFC), st.binary(max_size=20)), max_size=5),
    st.integers(1, 9),
)
def test_reader_round_trip_any_chunking(replies, chunk):
    stream = b"".join(make_status(i, 0, p) for i, p in replies)
    reader = PacketReader()
    out = []
    for k in range(0, len(stream), chunk):
        out += reader.feed(stream[k : k + chunk])
    assert [(p.packet_id, p.error, p.params) for p in out] == [(i, 0, p) for i, p in replies]
    assert len(out) == len(replies)


# ----------------------------------------------------------------- control table, units


def test_control_table_matches_emanual():
    # Address, size (XM430-W350 / XM540-W270 control tables, e-Manual).
    expected = {
        "OPERATING_MODE": (11, 1),
        "CURRENT_LIMIT": (38, 2),
        "TORQUE_ENABLE": (64, 1),
        "HARDWARE_ERROR_STATUS": (70, 1),
        "BUS_WATCHDOG": (98, 1),
        "GOAL_CURRENT": (102, 2),
        "PRESENT_CURRENT": (126, 2),
        "PRESENT_VELOCITY": (128, 4),
        "PRESENT_POSITION": (132, 4),
        "PRESENT_INPUT_VOLTAGE": (144, 2),
        "PRESENT_TEMPERATURE": (146, 1),
        "RETURN_DELAY_TIME": (9, 1),
    }
    for name, (address, size) in expected.items():
        register = ControlTable[name]
        assert (register, dxl.REGISTER_SIZE_BYTES[register]) == (address, size)
    # Every register ends before the next one starts.
    registers = sorted(ControlTable)
    for here, after in itertools.pairwise(registers):
        assert here + dxl.REGISTER_SIZE_BYTES[here] <= after, here.name
    assert FEEDBACK_LENGTH_BYTES == 21


def test_decode_feedback():
    data = bytearray(FEEDBACK_LENGTH_BYTES)
    data[0:2] = (-12).to_bytes(2, "little", signed=True)
    data[2:6] = (-100).to_bytes(4, "little", signed=True)
    data[6:10] = (5000).to_bytes(4, "little", signed=True)
    data[18:20] = (121).to_bytes(2, "little")
    data[20] = 41
    feedback = decode_feedback(bytes(data))
    assert (feedback.current_units, feedback.velocity_units, feedback.position_pulses) == (
        -12,
        -100,
        5000,
    )
    assert (feedback.input_voltage_units, feedback.temperature_C) == (121, 41)


def test_hardware_error_text():
    assert describe_hardware_error(0) == ""
    bits = HardwareError.OVERHEATING | HardwareError.OVERLOAD
    assert describe_hardware_error(bits) == "overheating error, overload error"
    assert "0x02" in describe_hardware_error(0x02)


def test_watchdog_register():
    assert watchdog_register_from_timeout(0.02) == 1
    assert watchdog_register_from_timeout(0.021) == 2
    assert watchdog_register_from_timeout(0.1) == 5
    assert watchdog_register_from_timeout(2.54) == 127
    for bad in (0.0, -1.0, math.nan, 3.0):
        with pytest.raises(CommandError):
            watchdog_register_from_timeout(bad)


# ----------------------------------------------------------------- torque map


@pytest.mark.parametrize("name", sorted(DYNAMIXEL_MODELS))
def test_torque_map_clamps_at_stall_and_current_limit(name):
    model = DYNAMIXEL_MODELS[name]
    stall_units = round(model.stall_current_A / model.current_unit_A)
    assert goal_current_from_torque(name, 0.0) == 0
    assert goal_current_from_torque(name, model.stall_torque_Nm) == stall_units
    assert goal_current_from_torque(name, 10 * model.stall_torque_Nm) == stall_units
    assert goal_current_from_torque(name, -1e9) == -stall_units
    assert stall_units <= model.current_limit_units
    assert torque_from_current(name, model.stall_current_A) == pytest.approx(model.stall_torque_Nm)
    lowered = dataclasses.replace(model, current_limit_units=100)
    assert goal_current_from_torque(lowered, model.stall_torque_Nm) == 100
    assert goal_current_from_torque(lowered, -model.stall_torque_Nm) == -100


def test_torque_map_datasheet_points():
    # XM430-W350 stall: 3.8 N·m at 2.1 A (11.1 V), 4.1 at 2.3 (12 V), 4.8 at 2.7 (14.8 V).
    for current_A, torque_Nm in ((2.1, 3.8), (2.3, 4.1), (2.7, 4.8)):
        assert torque_from_current("XM430-W350", current_A) == pytest.approx(torque_Nm)
        assert torque_from_current("XM430-W350", -current_A) == pytest.approx(-torque_Nm)
    assert goal_current_from_torque("XM430-W350", 4.1) == round(2.3 / 2.69e-3)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_torque_map_refuses_non_finite(bad):
    with pytest.raises(CommandError, match="not finite") as error:
        goal_current_from_torque("XM540-W270", bad)
    assert error.value.field == "torque_Nm"


def test_unknown_model():
    with pytest.raises(CommandError, match="XM430-W350"):
        goal_current_from_torque("MX-28", 1.0)


@given(st.sampled_from(sorted(DYNAMIXEL_MODELS)), st.floats(-20.0, 20.0))
def test_torque_map_round_trip_within_one_unit(name, torque_Nm):
    model = DYNAMIXEL_MODELS[name]
    units = goal_current_from_torque(name, torque_Nm)
    clamped = max(-model.stall_torque_Nm, min(model.stall_torque_Nm, torque_Nm))
    made = torque_from_current(name, units * model.current_unit_A)
    # Worst slope of the table times one unit bounds the rounding error.
    table = model.torque_table
    slope = max((t1 - t0) / (i1 - i0) for (i0, t0), (i1, t1) in itertools.pairwise(table))
    assert abs(made - clamped) <= slope * model.current_unit_A * 0.5 + 1e-9
    assert current_from_torque(name, torque_from_current(name, 1.0)) == pytest.approx(1.0)


# ----------------------------------------------------------------- dynamixel-sdk, both ways


class _Pty:
    """A pty whose slave the SDK opens; the test plays the servo on the master."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.port = sdk.PortHandler(os.ttyname(self.slave))
        assert self.port.openPort()
        self.packets = sdk.PacketHandler(2.0)

    def read_request(self) -> bytes:
        reader, data = PacketReader(), b""
        while True:
            chunk = os.read(self.master, 1024)
            data += chunk
            if reader.feed(chunk):
                return data

    def serve_once(self, reply: bytes) -> threading.Thread:
        """Answer the next request with ``reply``; the request is in ``self.request``."""

        def run() -> None:
            self.request = self.read_request()
            if reply:
                os.write(self.master, reply)

        thread = threading.Thread(target=run, daemon=True)
        thread.start()
        return thread

    def close(self) -> None:
        self.port.closePort()
        os.close(self.master)
        os.close(self.slave)


@pytest.fixture
def pty_sdk():
    wire = _Pty()
    yield wire
    wire.close()


def test_sdk_ping_read_write_reboot_match_ours(pty_sdk):
    wire, port, ph = pty_sdk, pty_sdk.port, pty_sdk.packets
    thread = wire.serve_once(make_status(1, 0, h("FC 03 2E")))
    model_number, result, error = ph.ping(port, 1)
    thread.join()
    assert wire.request == make_ping(1)
    assert (model_number, result, error) == (1020, sdk.COMM_SUCCESS, 0)

    thread = wire.serve_once(make_status(1, 0, (-2).to_bytes(4, "little", signed=True)))
    value, result, _ = ph.read4ByteTxRx(port, 1, ControlTable.PRESENT_POSITION)
    thread.join()
    assert wire.request == make_read(1, ControlTable.PRESENT_POSITION, 4)
    assert result == sdk.COMM_SUCCESS and value == 2**32 - 2

    # A status with the alert bit comes through the SDK as the error byte.
    thread = wire.serve_once(make_status(1, ALERT_BIT))
    result, error = ph.write2ByteTxRx(port, 1, ControlTable.GOAL_CURRENT, 2**16 - 300)
    thread.join()
    assert wire.request == make_write(
        1, ControlTable.GOAL_CURRENT, (-300).to_bytes(2, "little", signed=True)
    )
    assert result == sdk.COMM_SUCCESS and error == ALERT_BIT

    thread = wire.serve_once(make_status(1))
    assert ph.reboot(port, 1) == (sdk.COMM_SUCCESS, 0)
    thread.join()
    assert wire.request == make_reboot(1)


def test_sdk_sync_write_and_sync_read_match_ours(pty_sdk):
    wire, port, ph = pty_sdk, pty_sdk.port, pty_sdk.packets
    group_write = sdk.GroupSyncWrite(port, ph, ControlTable.GOAL_CURRENT, 2)
    goals = {1: -300, 2: 855, 7: 0}
    for servo_id, units in goals.items():
        group_write.addParam(servo_id, list(units.to_bytes(2, "little", signed=True)))
    thread = wire.serve_once(b"")
    assert group_write.txPacket() == sdk.COMM_SUCCESS
    thread.join()
    assert wire.request == make_sync_write(
        ControlTable.GOAL_CURRENT,
        2,
        {i: u.to_bytes(2, "little", signed=True) for i, u in goals.items()},
    )

    group_read = sdk.GroupSyncRead(port, ph, ControlTable.PRESENT_POSITION, 4)
    for servo_id in (1, 2):
        group_read.addParam(servo_id)
    replies = make_status(1, 0, (166).to_bytes(4, "little")) + make_status(
        2, 0, (2079).to_bytes(4, "little")
    )
    thread = wire.serve_once(replies)
    assert group_read.txRxPacket() == sdk.COMM_SUCCESS
    thread.join()
    assert wire.request == make_sync_read(ControlTable.PRESENT_POSITION, 4, [1, 2])
    assert group_read.getData(1, ControlTable.PRESENT_POSITION, 4) == 166
    assert group_read.getData(2, ControlTable.PRESENT_POSITION, 4) == 2079


def test_sdk_stuffing_agrees_but_its_tx_path_drops_it(pty_sdk):
    """SDK 4.1.0: addStuffing stuffs like we do, but txPacket ignores its result.

    ``Protocol2PacketHandler.txPacket`` calls ``self.addStuffing(txpacket)`` and
    discards the returned list, which is a new list whenever stuffing made the
    packet longer; so the SDK sends ``FF FF FD`` unstuffed. The bus never
    sends such a run (Goal Current sync writes put an ID ≤ 0xFC after every
    two data bytes), but values written through the SDK must avoid it.
    """
    wire, port, ph = pty_sdk, pty_sdk.port, pty_sdk.packets
    ours = make_write(1, ControlTable.GOAL_POSITION, h("FF FF FD 00"))
    unstuffed = bytearray(h("FF FF FD 00 01 09 00 03 74 00 FF FF FD 00 00 00"))
    assert bytes(ph.addStuffing(list(unstuffed)))[:-2] == ours[:-2]
    thread = wire.serve_once(b"")
    ph.writeTxOnly(port, 1, ControlTable.GOAL_POSITION, 4, [0xFF, 0xFF, 0xFD, 0x00])
    thread.join()
    assert wire.request[5:7] == (9).to_bytes(2, "little")  # not stuffed: LEN 9, not 10
    assert wire.request != ours
