"""One conformance suite over every actuator protocol: the same checks on each bus.

Each bus talks to its own emulator (MIT, Damiao and ODrive on a python-can
``virtual`` channel, Dynamixel on a pseudo-terminal) with two actuators, ids
1 and 2, and the emulated motors' physics tells what reached them.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass

import can
import pytest

from clients.bridge.actuator import ZERO_COMMAND, ActuatorBus, MotorCommand
from clients.bridge.emulators.damiao import EmulatedDamiao
from clients.bridge.emulators.dynamixel import DynamixelEmulator
from clients.bridge.emulators.mit import EmulatedMitActuator
from clients.bridge.emulators.motor import CanDeviceHost, EmulatedMotor
from clients.bridge.emulators.odrive import EmulatedODrive
from clients.bridge.protocols.can_io import DamiaoBus, MitBus
from clients.bridge.protocols.damiao import DAMIAO_MOTOR_MODELS, DamiaoMotor
from clients.bridge.protocols.dynamixel import DYNAMIXEL_MODELS
from clients.bridge.protocols.dynamixel_bus import DynamixelBus
from clients.bridge.protocols.mit import MIT_MOTOR_MODELS
from clients.bridge.protocols.odrive_bus import ODriveBus
from protocol.errors import PoiseError

PROTOCOLS = ["mit", "damiao", "odrive", "dynamixel"]
IDS = (1, 2)
REPLY_TIMEOUT_S = 0.05  # generous for a busy machine; an exchange ends when all have answered
_channels = itertools.count()


@dataclass
class Rig:
    bus: ActuatorBus
    motors: dict[int, EmulatedMotor]
    torque_step_Nm: float
    """What the protocol can tell apart in torque (its quantum, or the current unit's)."""
    position_step_rad: float
    damps: bool
    """Whether its safe state is a damper (MIT, Damiao) rather than no torque."""


@contextmanager
def rig(protocol: str) -> Iterator[Rig]:
    with ExitStack() as stack:
        if protocol == "dynamixel":
            model = DYNAMIXEL_MODELS["XM430-W350"]
            motors = {i: EmulatedMotor(torque_limit_Nm=model.stall_torque_Nm) for i in IDS}
            emulator = stack.enter_context(
                DynamixelEmulator(dict.fromkeys(IDS, model.name), motors)
            )
            bus = DynamixelBus(
                emulator.port, dict.fromkeys(IDS, model.name), reply_timeout_s=REPLY_TIMEOUT_S
            )
            stack.callback(bus.close)
            # One current unit in torque, on the steepest segment of the torque map.
            slope = max(
                (t1 - t0) / (i1 - i0)
                for (i0, t0), (i1, t1) in itertools.pairwise(model.torque_table)
            )
            yield Rig(bus, motors, slope * model.current_unit_A, 2 * math.pi / 4096, False)
            return
        channel = f"conformance-{next(_channels)}-{time.monotonic_ns()}"
        host_bus = can.Bus(interface="virtual", channel=channel)
        stack.callback(host_bus.shutdown)
        if protocol == "odrive":
            motors = {i: EmulatedMotor(torque_limit_Nm=5.0) for i in IDS}
            devices = [EmulatedODrive(i, motors[i]) for i in IDS]
        else:
            catalogue = MIT_MOTOR_MODELS if protocol == "mit" else DAMIAO_MOTOR_MODELS
            ranges = catalogue["AK80-9" if protocol == "mit" else "DM-J4310"]
            motors = {i: EmulatedMotor(torque_limit_Nm=ranges.torque_max_Nm) for i in IDS}
            devices = [
                EmulatedMitActuator(i, motors[i], ranges, reply_length=8)
                if protocol == "mit"
                else EmulatedDamiao(i, motors[i], ranges, master_id=0x10 + i)
                for i in IDS
            ]
        stack.enter_context(CanDeviceHost(host_bus, devices))
        driver = can.Bus(interface="virtual", channel=channel)
        if protocol == "odrive":
            bus = ODriveBus(driver, IDS, reply_timeout_s=REPLY_TIMEOUT_S)
            step_Nm, position_step = 1e-5, 1e-6
        elif protocol == "mit":
            bus = MitBus(driver, dict.fromkeys(IDS, ranges), reply_timeout_s=REPLY_TIMEOUT_S)
        else:
            motors_on_bus = {i: DamiaoMotor(ranges, 0x10 + i) for i in IDS}
            bus = DamiaoBus(driver, motors_on_bus, reply_timeout_s=REPLY_TIMEOUT_S)
        if protocol != "odrive":
            step_Nm = 2 * ranges.torque_max_Nm / 4095
            position_step = 2 * ranges.position_max_rad / 65535
        stack.callback(bus.close)
        yield Rig(bus, motors, step_Nm, position_step, protocol != "odrive")


def send(bus: ActuatorBus, command: MotorCommand) -> dict:
    return bus.exchange(dict.fromkeys(IDS, command))


def enabled(r: Rig) -> None:
    send(r.bus, ZERO_COMMAND)
    r.bus.enable()
    send(r.bus, ZERO_COMMAND)


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_a_zero_command_reads_positions_and_applies_nothing(protocol):
    with rig(protocol) as r:
        r.motors[1].sense(0.5, 0.0)
        r.motors[2].sense(-1.25, 0.0)
        feedback = send(r.bus, ZERO_COMMAND)
        assert feedback[1].position_rad == pytest.approx(0.5, abs=2 * r.position_step_rad)
        assert feedback[2].position_rad == pytest.approx(-1.25, abs=2 * r.position_step_rad)
        send(r.bus, MotorCommand(torque_Nm=1.0))  # not enabled yet
        assert r.motors[1].torque_Nm() == 0.0


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_an_enabled_actuator_makes_the_commanded_torque_and_reports_it(protocol):
    with rig(protocol) as r:
        enabled(r)
        feedback = send(r.bus, MotorCommand(torque_Nm=1.5))
        for i in IDS:
            assert r.motors[i].torque_Nm() == pytest.approx(1.5, abs=r.torque_step_Nm), i
        feedback = send(r.bus, MotorCommand(torque_Nm=1.5))
        assert feedback[1].torque_Nm == pytest.approx(1.5, abs=2 * r.torque_step_Nm)


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_a_torque_beyond_the_motor_is_clamped_and_a_nan_never_sent(protocol):
    with rig(protocol) as r:
        enabled(r)
        send(r.bus, MotorCommand(torque_Nm=1e6))
        limit = r.motors[1].torque_limit_Nm
        assert 0.0 < r.motors[1].torque_Nm() <= limit + r.torque_step_Nm
        before = len(r.motors[1].received)
        with pytest.raises(PoiseError) as error:
            send(r.bus, MotorCommand(torque_Nm=math.nan))
        assert isinstance(error.value, ValueError)
        time.sleep(0.02)
        assert len(r.motors[1].received) == before


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_the_safe_state_damps_or_lets_go(protocol):
    with rig(protocol) as r:
        enabled(r)
        send(r.bus, MotorCommand(torque_Nm=1.0))
        r.motors[1].sense(0.0, 2.0)  # moving at 2 rad/s
        r.bus.hold_safe(dict.fromkeys(IDS, 0.5))
        expected = -0.5 * 2.0 if r.damps else 0.0
        # MIT's zero velocity and torque codes decode a hair below zero.
        assert r.motors[1].torque_Nm() == pytest.approx(expected, abs=2 * r.torque_step_Nm + 0.01)


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_a_silent_actuator_is_none_and_the_other_still_answers(protocol):
    with rig(protocol) as r:
        enabled(r)
        r.motors[2].silent = True
        feedback = send(r.bus, MotorCommand(torque_Nm=0.5))
        assert feedback[2] is None and feedback[1] is not None


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_disable_stops_every_actuator(protocol):
    with rig(protocol) as r:
        enabled(r)
        send(r.bus, MotorCommand(torque_Nm=1.0))
        r.bus.disable()
        time.sleep(0.01)
        assert all(motor.torque_Nm() == 0.0 for motor in r.motors.values())
