"""The hardware bridge's own cost per tick, against the raw transport, in one run.

For each CAN protocol, ``--actuators`` emulated actuators on one python-can
``virtual`` channel, served by a thread of this process as hardware would be
served by the bus:

- **bus**: one :meth:`ActuatorBus.exchange` (pack every command, send, gather
  and parse every reply, with the protocol's checks);
- **raw**: the same number of 8-byte frames sent and echoed back unchanged by
  a device that does no decoding: python-can and the thread hop alone.

For Dynamixel, the bus's exchange (a sync write and a sync read through
``dynamixel-sdk`` on a pseudo-terminal, Return Delay 0) against a raw write of
the same sync-write packet and read of the same reply bytes from an echoing pty.

The emulators run in this process, so "bus" also pays for what a device's
firmware would do (decode, answer); "raw" pays for neither. Chunks alternate,
so both see the same machine load. Prints the median and
p99 per tick and the ratio bus / raw.

Usage: python bench/bridge.py [--actuators 6] [--count 2000] [--chunks 5]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
import itertools
import os
import threading
import time
import tty
from collections.abc import Callable
from contextlib import ExitStack

import can
import numpy as np

from clients.bridge.actuator import MotorCommand
from clients.bridge.emulators.damiao import EmulatedDamiao
from clients.bridge.emulators.dynamixel import DynamixelEmulator
from clients.bridge.emulators.mit import EmulatedMitActuator
from clients.bridge.emulators.motor import CanDevice, CanDeviceHost, EmulatedMotor
from clients.bridge.emulators.odrive import EmulatedODrive
from clients.bridge.protocols.can_io import DamiaoBus, MitBus
from clients.bridge.protocols.damiao import DAMIAO_MOTOR_MODELS, DamiaoMotor
from clients.bridge.protocols.dynamixel import make_sync_write
from clients.bridge.protocols.dynamixel_bus import DynamixelBus
from clients.bridge.protocols.mit import MIT_MOTOR_MODELS
from clients.bridge.protocols.odrive_bus import ODriveBus

_channels = itertools.count()


class Echo(CanDevice):
    """Answers every frame with itself: the transport and nothing else."""

    def on_frame(self, message: can.Message) -> list[can.Message]:
        return [message]


def measure(
    calls: dict[str, Callable[[], object]], count: int, chunks: int
) -> dict[str, np.ndarray]:
    """Seconds per call of each callable, measured in alternating chunks."""
    times: dict[str, list[float]] = {name: [] for name in calls}
    for _ in range(chunks):
        for name, call in calls.items():
            for _ in range(count // chunks):
                start = time.perf_counter()
                call()
                times[name].append(time.perf_counter() - start)
    return {name: np.array(values) for name, values in times.items()}


def can_rig(stack: ExitStack, protocol: str, n: int):
    channel = f"bench-{os.getpid()}-{next(_channels)}"
    ids = list(range(1, n + 1))
    motors = {i: EmulatedMotor(torque_limit_Nm=10.0) for i in ids}
    if protocol == "mit":
        ranges = MIT_MOTOR_MODELS["AK80-9"]
        devices = [EmulatedMitActuator(i, motors[i], ranges, reply_length=8) for i in ids]
    elif protocol == "damiao":
        ranges = DAMIAO_MOTOR_MODELS["DM-J4310"]
        devices = [EmulatedDamiao(i, motors[i], ranges, master_id=0x10 + i) for i in ids]
    else:
        devices = [EmulatedODrive(i, motors[i]) for i in ids]
    host = can.Bus(interface="virtual", channel=channel)
    stack.callback(host.shutdown)
    stack.enter_context(CanDeviceHost(host, devices))
    driver = can.Bus(interface="virtual", channel=channel)
    if protocol == "mit":
        bus = MitBus(driver, dict.fromkeys(ids, ranges), reply_timeout_s=0.05)
    elif protocol == "damiao":
        bus = DamiaoBus(
            driver, {i: DamiaoMotor(ranges, 0x10 + i) for i in ids}, reply_timeout_s=0.05
        )
    else:
        bus = ODriveBus(driver, ids, reply_timeout_s=0.05, temperature_period=0)
    stack.callback(bus.close)
    bus.exchange(dict.fromkeys(ids, MotorCommand()))
    bus.enable()
    commands = dict.fromkeys(ids, MotorCommand(torque_Nm=0.5))
    # ODrive asks for two replies per node (encoder estimates and torques).
    frames_each_way = n * (3 if protocol == "odrive" else 1)
    return (lambda: bus.exchange(commands)), raw_can(stack, frames_each_way)


def raw_can(stack: ExitStack, frames: int) -> Callable[[], None]:
    channel = f"bench-raw-{os.getpid()}-{next(_channels)}"
    host = can.Bus(interface="virtual", channel=channel)
    stack.callback(host.shutdown)
    stack.enter_context(CanDeviceHost(host, [Echo()]))
    driver = can.Bus(interface="virtual", channel=channel)
    stack.callback(driver.shutdown)
    message = can.Message(arbitration_id=1, data=bytes(8), is_extended_id=False)

    def round_trip() -> None:
        for _ in range(frames):
            driver.send(message)
        for _ in range(frames):
            driver.recv(0.05)

    return round_trip


def dynamixel_rig(stack: ExitStack, n: int):
    servos = dict.fromkeys(range(1, n + 1), "XM430-W350")
    emulator = stack.enter_context(DynamixelEmulator(servos, return_delay_s=0.0))
    bus = DynamixelBus(emulator.port, servos, reply_timeout_s=0.05)
    stack.callback(bus.close)
    bus.exchange(dict.fromkeys(servos, MotorCommand()))
    bus.enable()
    commands = dict.fromkeys(servos, MotorCommand(torque_Nm=0.5))
    # Raw: the sync write's bytes out, the sync read's reply bytes (n status packets
    # of 21 bytes of data: 11 + 1 + 21 + 2 each) back, through an echoing pty.
    request = make_sync_write(102, 2, {i: bytes(2) for i in servos})
    reply_size = n * (11 + 21)
    master, slave = os.openpty()
    stack.callback(os.close, master)
    stack.callback(os.close, slave)
    tty.setraw(slave)  # no line discipline: bytes through as they are, no echo
    stop = threading.Event()

    def echo() -> None:
        while not stop.is_set():
            received = 0
            while received < len(request):  # one whole request, then one reply
                try:
                    received += len(os.read(master, len(request) - received))
                except OSError:  # the pty closed: the benchmark is over
                    return
            os.write(master, bytes(reply_size))

    thread = threading.Thread(target=echo, daemon=True)
    thread.start()
    stack.callback(stop.set)

    def raw() -> None:
        os.write(slave, request)
        got = 0
        while got < reply_size:
            got += len(os.read(slave, reply_size - got))

    return (lambda: bus.exchange(commands)), raw


def report(name: str, times: dict[str, np.ndarray]) -> None:
    bus, raw = times["bus"], times["raw"]
    print(
        f"{name:<22} bus p50 {1e3 * np.median(bus):6.3f} ms p99 {1e3 * np.percentile(bus, 99):6.3f}"
        f" | raw p50 {1e3 * np.median(raw):6.3f} ms | ratio {np.median(bus) / np.median(raw):.2f}x"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--actuators", type=int, default=6, help="per bus (default: 6)")
    parser.add_argument("--count", type=int, default=2000, help="exchanges (default: 2000)")
    parser.add_argument("--chunks", type=int, default=5, help="alternations (default: 5)")
    args = parser.parse_args()
    n = args.actuators
    print(f"per exchange with {n} actuators on one bus; raw = the same traffic, no protocol")
    for protocol in ("mit", "damiao", "odrive"):
        with ExitStack() as stack:
            exchange, raw = can_rig(stack, protocol, n)
            report(protocol, measure({"bus": exchange, "raw": raw}, args.count, args.chunks))
    with ExitStack() as stack:
        exchange, raw = dynamixel_rig(stack, n)
        report("dynamixel (pty)", measure({"bus": exchange, "raw": raw}, args.count, args.chunks))


if __name__ == "__main__":
    main()
