"""``poise bridge --emulate``: every bus of a map served by emulated actuators on a simulated robot.

Each CAN bus becomes a python-can ``virtual`` channel with the map's
actuators emulated on it (:class:`~clients.bridge.emulators.motor.CanDeviceHost`),
each Dynamixel bus a pseudo-terminal with emulated servos; every emulated
motor drives its joint of the simulated robot (:class:`~clients.bridge.plant.Plant`).
The bridge opens the buses with :attr:`Emulation.bus_overrides` and is
paced by the plant, so the run is reproducible whatever the machine's load.
With ``base_state = "imu"`` (``source = "emulated"``) a simulated IMU sits
where ``[imu]`` mounts it, fed after every physics step.
"""

from __future__ import annotations

import itertools
import os
import time
from contextlib import ExitStack
from typing import Any

import can
import pinocchio as pin

from clients.bridge.buses import motor_peak_torque_Nm
from clients.bridge.config import BridgeConfig, imu_mount_on_root_body
from clients.bridge.emulators.damiao import EmulatedDamiao
from clients.bridge.emulators.dynamixel import DynamixelEmulator
from clients.bridge.emulators.mit import EmulatedMitActuator
from clients.bridge.emulators.motor import CanDevice, CanDeviceHost, EmulatedMotor
from clients.bridge.emulators.odrive import EmulatedODrive
from clients.bridge.joint_map import JointMap
from clients.bridge.plant import Plant, PlantPacer, RealTimePacer
from clients.bridge.protocols.damiao import DAMIAO_MOTOR_MODELS
from clients.bridge.protocols.mit import MIT_MOTOR_MODELS
from clients.physics.backend import physics_backend
from clients.physics.imu import ImuSpec, SimulatedImu
from clients.physics.status import standing_state
from protocol.messages import Welcome

__all__ = ["Emulation", "emulated_imu_spec"]

_CHANNELS = itertools.count()

CAN_REPLY_DELAY_S = 150e-6
"""How long an emulated CAN actuator takes to answer on the wall clock.

Real ones answer 100–300 µs after a command (the firmware's CAN interrupt,
then one 8-byte frame, about 130 µs at 1 Mbit/s); in simulated time the
robot's clock stands still meanwhile, so no delay is added there.
"""

SIMULATED_REPLY_TIMEOUT_S = 0.1
"""Reply timeout of every bus when the simulated robot paces the loop.

The emulators answer from threads of this process, so a reply can wait for
the interpreter; in simulated time that costs the robot nothing, and the
map's timeouts (a few ms, for hardware) would count such replies as missed.
On a busy machine (load 6 on 2 cores) a thread waited over 20 ms five ticks
in a row; the map's largest allowed timeout, 0.1 s, only costs a silent
actuator's fault-injection test its wall time.
"""

WALL_CLOCK_REPLY_TIMEOUT_S = 0.005
"""Reply timeout of every bus on the wall clock, at least.

The buses exchange at once, one thread each, and here the devices answer
from threads of the same process, so they compete for the interpreter as
real actuators never do; a map's 2 ms for 6 actuators is then too short.
"""

ODRIVE_PEAK_TORQUE_NM = 60.0
"""Torque an emulated ODrive's motor makes at most when the map gives no joint limit."""


class Emulation:
    """The emulated actuators and the simulated robot of one bridge run.

    A context manager: entering starts the emulators' threads, leaving stops
    them and closes their channels and pseudo-terminals. The emulated motors
    keep time by the simulated robot's clock, or with ``wall_clock`` by
    ``time.monotonic``, like the loop's pacer (:meth:`pacer`).

    Attributes:
        plant: The simulated robot.
        imu: Its IMU (``base_state = "imu"``, ``source = "emulated"``), else None.
        motors: Each joint's emulated motor, by joint name.
        devices: Each joint's protocol emulator, by joint name (fault
            injection in tests: ``motor.silent``, ``motor.fault_code``, …).
        bus_overrides: What :func:`~clients.bridge.buses.open_buses` needs to
            reach the emulators instead of the map's interfaces.
    """

    def __init__(
        self,
        config: BridgeConfig,
        welcome: Welcome,
        joint_map: JointMap,
        wall_clock: bool = False,
    ):
        imu_spec = None  # first: a mistake in [imu] leaves nothing open
        if config.bridge.base_state == "imu" and config.imu_settings.source == "emulated":
            imu_spec = emulated_imu_spec(config)
        self._stack = ExitStack()
        self.wall_clock = wall_clock
        self.plant: Plant
        # The motors' own clock (their watchdogs, the times they log) is the loop's.
        clock = time.monotonic if wall_clock else (lambda: self.plant.time_s)
        self.motors: dict[str, EmulatedMotor] = {}
        self.devices: dict[str, Any] = {}
        self.bus_overrides: dict[str, dict[str, Any]] = {}
        for name in joint_map.names:
            actuator = config.joints[name]
            protocol = config.buses[actuator.bus].protocol
            peak = motor_peak_torque_Nm(protocol, actuator)
            if peak == float("inf"):
                limit = joint_map.torque_limit_Nm[joint_map.names.index(name)]
                peak = min(ODRIVE_PEAK_TORQUE_NM, limit / actuator.gear_ratio)
            self.motors[name] = EmulatedMotor(torque_limit_Nm=peak, clock=clock)
        self._servers: list[Any] = []
        for bus_name, spec in config.buses.items():
            joints = config.joints_on(bus_name)
            if spec.protocol == "dynamixel":
                emulator = DynamixelEmulator(
                    {a.id: a.motor for a in joints.values()},
                    {a.id: self.motors[joint] for joint, a in joints.items()},
                )
                for joint, a in joints.items():
                    self.devices[joint] = emulator.servos[a.id]
                self._servers.append(emulator)
                self.bus_overrides[bus_name] = {"port": emulator.port}
                continue
            channel = f"poise-emulated-{os.getpid()}-{next(_CHANNELS)}-{bus_name}"
            devices: list[CanDevice] = []
            for joint, a in joints.items():
                device = self._can_device(spec.protocol, a.id, a.motor, a.master_id, joint)
                self.devices[joint] = device
                devices.append(device)
            host_bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
            reply_delay_s = CAN_REPLY_DELAY_S if wall_clock else 0.0
            self._servers.append(CanDeviceHost(host_bus, devices, reply_delay_s))
            self._stack.callback(host_bus.shutdown)
            self.bus_overrides[bus_name] = {"interface": "virtual", "channel": channel}
        least_s = WALL_CLOCK_REPLY_TIMEOUT_S if wall_clock else SIMULATED_REPLY_TIMEOUT_S
        for bus_name, spec in config.buses.items():
            timeout_s = max(spec.reply_timeout_s, least_s)
            self.bus_overrides[bus_name]["reply_timeout_s"] = timeout_s
        emulation = config.emulation
        backend = physics_backend(
            emulation.backend,
            config.bridge.model,
            emulation.physics_rate_hz,
            emulation.friction_coefficient,
        )
        backend.reset(standing_state(welcome, {}))
        self.plant = Plant(
            backend,
            joint_map,
            [self.motors[name] for name in joint_map.names],
            [push.to_push() for push in config.emulation.pushes],
            welcome.standing_position_base_in_world[2],
        )
        self.imu: SimulatedImu | None = None
        if imu_spec is not None:
            self.imu = SimulatedImu(imu_spec, config.bridge.model)
            self.plant.add_sensor(self.imu)

    def _can_device(
        self, protocol: str, actuator_id: int, motor: str, master_id: int | None, joint: str
    ) -> CanDevice:
        if protocol == "mit":
            # CubeMars AK firmware answers with 8 bytes (temperature, error code).
            return EmulatedMitActuator(
                actuator_id, self.motors[joint], MIT_MOTOR_MODELS[motor], reply_length=8
            )
        if protocol == "damiao":
            return EmulatedDamiao(
                actuator_id,
                self.motors[joint],
                DAMIAO_MOTOR_MODELS[motor],
                master_id=master_id or 0,
            )
        return EmulatedODrive(actuator_id, self.motors[joint])

    def pacer(self, period_s: float) -> PlantPacer | RealTimePacer:
        """Paces the bridge by the plant; with ``wall_clock``, by the wall clock.

        On the wall clock the plant does not move (the robot hangs still):
        for measuring the loop's real-time behaviour, e.g. its watchdog.
        """
        return RealTimePacer(period_s) if self.wall_clock else PlantPacer(self.plant, period_s)

    def __enter__(self) -> Emulation:
        # Servers stop before their channels close (the stack unwinds in reverse).
        for server in self._servers:
            self._stack.enter_context(server)
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._stack.close()


def emulated_imu_spec(config: BridgeConfig) -> ImuSpec:
    """The simulated IMU where ``[imu]`` mounts it, with the errors of ``[emulation] imu``.

    Raises:
        BridgeConfigError: See :func:`~clients.bridge.config.imu_mount_on_root_body`.
    """
    body, mount = imu_mount_on_root_body(config)
    return config.emulation.imu.model_copy(
        update={
            "body": body,
            "position_in_body_m": tuple(float(x) for x in mount.translation),
            "orientation_in_body_xyzw": tuple(
                float(x) for x in pin.Quaternion(mount.rotation).coeffs()
            ),
        }
    )
