"""Dynamixel Protocol 2.0 for the X series: packets, control table and torque map.

Pure encode/decode functions, byte for byte as the ROBOTIS e-Manual specifies
them (https://emanual.robotis.com/docs/en/dxl/protocol2/, source
``ROBOTIS-GIT/emanual`` ``docs/en/dxl/protocol2.md``, and the X-series model
pages under ``docs/en/dxl/x/``). This module is their one import: it
re-exports the names of three modules, each imported only by those after it:

* ``dynamixel_packets``: the packet framing (header, byte stuffing, CRC-16,
  instruction and status packets, sync read and write, the stream reader)
  and the errors;
* ``dynamixel_registers``: the X-series control table (addresses, sizes,
  units), register values as bytes, the feedback read, the Bus Watchdog;
* ``dynamixel_models``: the servo catalogue :data:`DYNAMIXEL_MODELS` and the
  torque ↔ current map per model.

The I/O part, :class:`~clients.bridge.protocols.dynamixel_bus.DynamixelBus`,
is in ``dynamixel_bus.py``.

dynamixel-sdk 4.1.0 caveats found while testing against it: its Python
``txPacket`` discards ``addStuffing``'s result, so a packet that needs stuffing
goes out unstuffed (the bus never sends an ``FF FF FD`` run: Goal Current
sync writes put an ID ≤ 0xFC after every two data bytes); its GroupSyncRead
stops at the first missing status packet and its ``readRx`` discards other
IDs' packets while waiting, so the bus collects the sync-read replies itself.
"""

from clients.bridge.protocols.dynamixel_models import (
    DYNAMIXEL_MODELS,
    DynamixelModel,
    current_from_torque,
    get_model,
    goal_current_from_torque,
    torque_from_current,
)
from clients.bridge.protocols.dynamixel_packets import (
    ALERT_BIT,
    BROADCAST_ID,
    HEADER,
    MAX_ID,
    CommandError,
    DynamixelError,
    Instruction,
    Packet,
    PacketError,
    PacketReader,
    StatusError,
    crc16,
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
    unstuff,
)
from clients.bridge.protocols.dynamixel_registers import (
    BUS_WATCHDOG_UNIT_S,
    CURRENT_UNIT_A,
    EEPROM_END,
    FEEDBACK_LENGTH_BYTES,
    FEEDBACK_START,
    POSITION_UNIT_RAD,
    REGISTER_SIZE_BYTES,
    RETURN_DELAY_UNIT_S,
    SIGNED_REGISTERS,
    VELOCITY_UNIT_RAD_S,
    ControlTable,
    Feedback,
    HardwareError,
    OperatingMode,
    decode_feedback,
    describe_hardware_error,
    pack_register,
    unpack_register,
    watchdog_register_from_timeout,
)

__all__ = [
    "ALERT_BIT",
    "BROADCAST_ID",
    "BUS_WATCHDOG_UNIT_S",
    "CURRENT_UNIT_A",
    "DYNAMIXEL_MODELS",
    "EEPROM_END",
    "FEEDBACK_LENGTH_BYTES",
    "FEEDBACK_START",
    "HEADER",
    "MAX_ID",
    "POSITION_UNIT_RAD",
    "REGISTER_SIZE_BYTES",
    "RETURN_DELAY_UNIT_S",
    "SIGNED_REGISTERS",
    "VELOCITY_UNIT_RAD_S",
    "CommandError",
    "ControlTable",
    "DynamixelError",
    "DynamixelModel",
    "Feedback",
    "HardwareError",
    "Instruction",
    "OperatingMode",
    "Packet",
    "PacketError",
    "PacketReader",
    "StatusError",
    "crc16",
    "current_from_torque",
    "decode_feedback",
    "describe_hardware_error",
    "get_model",
    "goal_current_from_torque",
    "make_packet",
    "make_ping",
    "make_read",
    "make_reboot",
    "make_status",
    "make_sync_read",
    "make_sync_write",
    "make_write",
    "pack_register",
    "parse_packet",
    "stuff",
    "torque_from_current",
    "unpack_register",
    "unstuff",
    "watchdog_register_from_timeout",
]
