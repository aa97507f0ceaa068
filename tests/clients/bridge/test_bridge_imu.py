"""The bridge with ``base_state = "imu"``: the server estimates the base from an IMU.

Hardware in the loop as in ``test_bridge_hil.py``: the revolute_humanoid on
emulated MIT-mode actuators, simulated by the reference simulator, with a
simulated BMI088 (noise, biases, an AHRS orientation output) on its pelvis
instead of the simulator's ground truth. The server's estimate
(``diagnostics.base_estimate``) is graded against that ground truth, which
the bridge never sends. A program's own ``ImuSource`` (``source =
"external"``) drives the same loop.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import clients.bridge.app as bridge_app
from clients.bridge.app import BridgeSession, open_bridge
from clients.bridge.base_state import ImuBaseReading, SupportFlags
from clients.bridge.config import (
    BridgeConfig,
    BridgeConfigError,
    imu_mount_on_root_body,
    load_bridge_config,
)
from clients.bridge.emulation import emulated_imu_spec
from clients.bridge.joint_map import JointMap
from clients.bridge.loop import Bridge
from clients.physics.imu import SimulatedImu
from clients.physics.status import standing_state
from clients.state import RobotState
from protocol.messages import Command, ImuSample, State
from tests.clients.bridge.test_bridge_config import welcome as one_revolute_joint_per_name

EXAMPLE = Path(__file__).parents[3] / "examples" / "bridge" / "revolute_humanoid_imu.toml"
DIAGNOSTICS_PERIOD_TICKS = 10
"""The tests ask for the estimate every 10 ticks (the bridge: every 100)."""


def with_imu(config: BridgeConfig, **imu: object) -> BridgeConfig:
    """``config`` with ``[imu]`` keys replaced."""
    return config.model_copy(update={"imu": config.imu_settings.model_copy(update=imu)})


def tilt_deg(estimated_xyzw: np.ndarray, true_xyzw: np.ndarray) -> float:
    """Angle between the estimated and the true base up axes (°); yaw does not count."""
    up_estimated = pin.Quaternion(np.asarray(estimated_xyzw)).toRotationMatrix()[2]
    up_true = pin.Quaternion(np.asarray(true_xyzw)).toRotationMatrix()[2]
    return float(np.degrees(np.arccos(np.clip(up_estimated @ up_true, -1.0, 1.0))))


def rotation_error_deg(estimated_xyzw: np.ndarray, true_xyzw: np.ndarray) -> float:
    """The whole rotation between the estimated and the true base orientation (°)."""
    estimated = pin.Quaternion(np.asarray(estimated_xyzw)).toRotationMatrix()
    true = pin.Quaternion(np.asarray(true_xyzw)).toRotationMatrix()
    return float(np.degrees(np.linalg.norm(pin.log3(estimated.T @ true))))


@dataclass
class Conversation:
    """What the bridge sent the server, and each estimate beside the simulator's truth.

    Wraps the session's client: the plant advances only while the loop waits
    for its next tick, so when a command arrives the simulated robot is still
    where the state it answers was measured.
    """

    session: BridgeSession
    states: list[State] = field(default_factory=list)
    commands: list[Command] = field(default_factory=list)
    estimates: list[tuple[float, object, RobotState]] = field(default_factory=list)

    def __post_init__(self) -> None:
        client = self.session.bridge.client
        send, receive = client.send_state, client.receive_command
        plant = self.session.emulation.plant

        def send_state(state: State) -> None:
            self.states.append(state)
            send(state)

        def receive_command() -> Command:
            command = receive()
            self.commands.append(command)
            diagnostics = command.diagnostics
            if diagnostics is not None and diagnostics.base_estimate is not None:
                self.estimates.append(
                    (plant.time_s, diagnostics.base_estimate, plant.backend.state())
                )
            return command

        client.send_state, client.receive_command = send_state, receive_command  # type: ignore[method-assign]

    def errors(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Tilt (°), height (m) and velocity (m/s) errors of every estimate."""
        tilt, height, velocity = [], [], []
        for _, estimate, truth in self.estimates:
            estimated, true = (
                estimate.orientation_base_in_world_xyzw,
                truth.orientation_base_in_world_xyzw,
            )
            tilt.append(tilt_deg(estimated, true))
            height.append(estimate.position_base_in_world[2] - truth.position_base_in_world[2])
            velocity.append(
                np.linalg.norm(
                    estimate.linear_velocity_base_in_world - truth.linear_velocity_base_in_world
                )
            )
        return np.array(tilt), np.array(height), np.array(velocity)


@pytest.fixture
def estimates_often(monkeypatch):
    monkeypatch.setattr(bridge_app, "DIAGNOSTICS_PERIOD_TICKS", DIAGNOSTICS_PERIOD_TICKS)


@pytest.mark.slow
@pytest.mark.e2e
def test_the_revolute_humanoid_stands_and_takes_a_push_on_the_servers_imu_estimate(
    server, estimates_often
):
    config = load_bridge_config(EXAMPLE)
    push = config.emulation.pushes[0]
    assert push.body == "torso" and push.force_in_world_N == (100.0, 0.0, 0.0)
    assert push.start_s == 4.0 and push.duration_s == 0.1
    with open_bridge(config, server.endpoint, emulate=True) as session:
        conversation = Conversation(session)
        report = session.bridge.run(5.0)
    plant = session.emulation.plant
    assert plant.fall_reason == "", plant.fall_reason
    assert plant.time_s == pytest.approx(5.0, abs=0.01)
    assert report.stopped == "duration" and report.latches == []
    # Every tick got a command, or a late reply (a busy machine) was counted.
    assert report.commands + report.server_timeouts == report.timing.ticks + 1 == 2501
    assert report.server_timeouts <= 0.05 * report.timing.ticks and report.invalid_commands == 0
    # Every state carried the IMU and no base, at times that strictly increase.
    assert all(s.imu is not None and s.position_base_in_world is None for s in conversation.states)
    times = np.array([state.time_s for state in conversation.states])
    assert np.all(np.diff(times) > 0)
    np.testing.assert_allclose(np.diff(times), 1.0 / config.bridge.rate_hz, rtol=1e-9)
    # The server's estimate against the truth the bridge never sent.
    assert len(conversation.estimates) == 2501 // DIAGNOSTICS_PERIOD_TICKS + 1
    tilt, height, velocity = conversation.errors()
    after_push = np.array([time_s >= push.start_s for time_s, _, _ in conversation.estimates])
    print(
        f"estimate - truth over {len(tilt)} estimates in 5 s: tilt max {tilt.max():.3f}° "
        f"(after the push {tilt[after_push].max():.3f}°), height max "
        f"{1e3 * np.abs(height).max():.2f} mm, velocity max {velocity.max():.4f} m/s"
    )
    assert tilt.max() < 1.0
    assert np.abs(height).max() < 0.01
    assert velocity.max() < 0.05


@pytest.mark.e2e
def test_an_imu_mounted_turned_gives_the_same_estimate(server, estimates_often):
    config = load_bridge_config(EXAMPLE)
    config = with_imu(config, orientation_in_frame_xyzw=(0.0, 0.0, 0.5**0.5, 0.5**0.5))
    with open_bridge(config, server.endpoint, emulate=True) as session:
        conversation = Conversation(session)
        session.bridge.run(0.05)
    assert conversation.estimates
    for _, estimate, truth in conversation.estimates:
        error = rotation_error_deg(
            estimate.orientation_base_in_world_xyzw, truth.orientation_base_in_world_xyzw
        )
        assert error < 2.0  # the AHRS's tilt error (0.5° RMS) and its yaw, at rest


class ProgramsImu:
    """What a program driving a real robot writes (``source = "external"``).

    Here its "driver" is a simulated IMU on the emulated robot and its "force
    sensors" the simulator's support flags; the bridge knows neither.
    """

    def __init__(self) -> None:
        self.imu: SimulatedImu | None = None
        self.support: SupportFlags | None = None
        self.reads = 0

    def read(self) -> ImuBaseReading:
        assert self.imu is not None and self.support is not None
        reading = self.imu.reading()
        assert reading is not None
        self.reads += 1
        sample = ImuSample(
            angular_velocity_imu_in_imu=reading.angular_velocity_imu_in_imu.tolist(),
            linear_acceleration_imu_in_imu=reading.linear_acceleration_imu_in_imu.tolist(),
        )  # no orientation output: the server levels on the accelerometer
        return ImuBaseReading(sample, self.support.read())


class CountingSensor:
    """Counts the plant's resets and physics steps."""

    def __init__(self) -> None:
        self.resets = 0
        self.updates = 0
        self.times: list[float] = []

    def reset(self, state: RobotState, time_s: float) -> None:
        self.resets += 1
        self.times = [time_s]

    def update(self, state: RobotState, time_s: float) -> None:
        self.updates += 1
        self.times.append(time_s)


@pytest.mark.e2e
def test_a_programs_own_imu_source_drives_the_bridge(server, estimates_often):
    emulated = load_bridge_config(EXAMPLE)
    config = with_imu(emulated, source="external")
    source = ProgramsImu()
    with open_bridge(config, server.endpoint, emulate=True, imu_source=source) as session:
        assert session.emulation is not None and session.emulation.imu is None  # not emulated
        plant = session.emulation.plant
        source.imu = SimulatedImu(emulated_imu_spec(emulated), config.bridge.model)
        plant.add_sensor(source.imu)
        source.support = SupportFlags(plant, config.bridge.support_force_threshold_N)
        counter = CountingSensor()
        plant.add_sensor(counter)
        conversation = Conversation(session)
        report = session.bridge.run(1.0)
        steps_per_tick = round(config.emulation.physics_rate_hz / config.bridge.rate_hz)
        assert counter.resets == 1 and counter.updates == 500 * steps_per_tick
        assert np.all(np.diff(counter.times) > 0)  # after every physics step, in order
        assert source.imu.reading().time_s == pytest.approx(plant.time_s)
        plant.reset(standing_state(session.bridge.client.welcome, {}))  # the sensors start over
        assert counter.resets == 2 and counter.times == [0.0]
        assert source.imu.reading().time_s == 0.0
    assert plant.fall_reason == "" and report.latches == []
    assert report.commands + report.server_timeouts == 501 and report.invalid_commands == 0
    assert source.reads == 501
    assert all(state.imu.orientation_imu_in_world_xyzw is None for state in conversation.states)
    tilt, height, _ = conversation.errors()
    print(
        f"levelled on the accelerometer, 1 s: tilt max {tilt.max():.3f}°, "
        f"height max {1e3 * np.abs(height).max():.2f} mm"
    )
    assert tilt.max() < 2.0  # the BMI088's zero-g offset (up to 1.1° of tilt) is not observable
    assert np.abs(height).max() < 0.01


class StallingImu(ProgramsImu):
    """A driver that stops updating after ``live_reads`` reads: the same sample from then on."""

    def __init__(self, live_reads: int) -> None:
        super().__init__()
        self.live_reads = live_reads
        self.frozen: ImuBaseReading | None = None

    def read(self) -> ImuBaseReading:
        if self.frozen is not None:
            return self.frozen
        reading = super().read()
        if self.reads == self.live_reads:
            self.frozen = reading
        return reading


@pytest.mark.e2e
def test_a_stalled_imu_latches_the_safe_state(server):
    """The same sample past ``[imu] max_sample_age_s`` latches, as a silent actuator would."""
    emulated = load_bridge_config(EXAMPLE)
    config = with_imu(emulated, source="external", max_sample_age_s=0.02)
    source = StallingImu(live_reads=100)
    with open_bridge(config, server.endpoint, emulate=True, imu_source=source) as session:
        plant = session.emulation.plant
        source.imu = SimulatedImu(emulated_imu_spec(emulated), config.bridge.model)
        plant.add_sensor(source.imu)
        source.support = SupportFlags(plant, config.bridge.support_force_threshold_N)
        report = session.bridge.run(0.5)
    assert len(report.latches) == 1 and "same sample" in report.latches[0], report.latches
    assert "max_sample_age_s" in report.latches[0]
    # 500 Hz: sample 100 is the last fresh one; the 12th tick after it is 22 ms old.
    assert report.commands + report.server_timeouts == 100 + 10


def test_the_emulated_imu_sits_where_the_map_mounts_it():
    config = load_bridge_config(EXAMPLE)
    spec = emulated_imu_spec(config)
    assert spec.body == "pelvis"  # the root body, whose frame "pelvis" is
    assert spec.position_in_body_m == pytest.approx(config.imu_settings.position_in_frame)
    assert spec.orientation_in_body_xyzw == pytest.approx((0.0, 0.0, 0.0, 1.0))
    assert spec.rate_hz == config.emulation.imu.rate_hz and spec.orientation_output
    on_root = emulated_imu_spec(with_imu(config, frame="", position_in_frame=(0.1, 0.0, 0.0)))
    assert on_root.body == "pelvis" and on_root.position_in_body_m == pytest.approx((0.1, 0, 0))


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        ("pelvsi", r"no such frame; did you mean 'pelvis'\? frames on the root body: .*pelvis"),
        ("torso", r"'torso' moves relative to the root body \(joint '\w+' between them\)"),
    ],
)
def test_an_imu_frame_off_the_root_body_is_refused_before_connecting(frame, message):
    config = with_imu(load_bridge_config(EXAMPLE), frame=frame)
    with pytest.raises(BridgeConfigError, match=message):
        imu_mount_on_root_body(config)
    with pytest.raises(BridgeConfigError, match=message):
        with open_bridge(config, "tcp://127.0.0.1:1", emulate=True):  # nothing listens there
            pass


@pytest.mark.e2e
@pytest.mark.parametrize(
    ("edit", "emulate", "message"),
    [
        (None, False, '[imu] source = "emulated" is the emulated robot\'s IMU: run with --emulate'),
        (
            ('frame = "pelvis"', 'frame = "pelvsi"'),
            True,
            "[imu] frame = 'pelvsi': revolute_humanoid.xml has no such frame; did you mean",
        ),
    ],
    ids=["emulated_imu_on_hardware", "frame_typo"],
)
def test_poise_bridge_says_a_mistake_about_the_imu_in_one_line(tmp_path, edit, emulate, message):
    path = EXAMPLE
    if edit is not None:
        text = EXAMPLE.read_text()
        assert edit[0] in text
        path = tmp_path / "map.toml"
        path.write_text(text.replace(edit[0], edit[1]))
    run = subprocess.run(
        [sys.executable, "-m", "controller_server.cli", "bridge", str(path),
         *(["--emulate"] if emulate else []), "--connect", "tcp://127.0.0.1:1"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert run.returncode == 2, run.stderr
    assert message in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1, run.stderr


class StillClock:
    """A loop clock that does not advance (a coarse clock read twice within one tick)."""

    period_s = 0.002

    def now_s(self) -> float:
        return 7.0

    def wait(self) -> bool:
        return False


class RecordingClient:
    """Takes each state and answers with no command (as a timeout would)."""

    def __init__(self) -> None:
        self.states: list[State] = []
        self.timeout_s = 1.0

    def send_state(self, state: State) -> None:
        self.states.append(state)

    def receive_command(self) -> None:
        return None


def test_imu_states_go_at_strictly_increasing_times_and_without_a_base():
    """On a clock that does not advance between two ticks, the time still does."""
    config = BridgeConfig.model_validate(
        {
            "bridge": {"base_state": "imu"},
            "buses": {"a": {"protocol": "mit"}},
            "joints": {"knee": {"bus": "a", "id": 1}},
        }
    )
    welcome = one_revolute_joint_per_name("knee")
    sample = ImuSample(
        angular_velocity_imu_in_imu=[0.0, 0.0, 0.1], linear_acceleration_imu_in_imu=[0, 0, 9.8]
    )

    class Still:
        def read(self) -> ImuBaseReading:
            return ImuBaseReading(sample, [])

    client = RecordingClient()
    joint_map = JointMap(config, welcome)
    bridge = Bridge(config.bridge, joint_map, {}, client, Still(), StillClock(), model=None)
    bridge.watchdog.feed()
    for _ in range(3):
        assert bridge._step_server() is None
    times = [state.time_s for state in client.states]
    assert times[0] == 0.0 and times[0] < times[1] < times[2]
    for state in client.states:
        assert state.imu is sample and state.contact_flags == []
        assert state.position_base_in_world is None and state.orientation_base_in_world_xyzw is None
        assert state.joint_position.tolist() == [0.0]
