"""A run's track: what every client fills tick by tick for its pictures (clients/track.py)."""

import logging
import time

import numpy as np
import pytest

from clients.state import RobotState
from clients.track import Track
from protocol.messages import BaseEstimateDiagnostics, Command, ImuSample, State, Welcome
from tests.protocol.samples import sample_messages

SAMPLES = {type(message): message for message in sample_messages()}
WELCOME: Welcome = SAMPLES[Welcome]
DIAGNOSED: Command = SAMPLES[Command]
PLAIN = DIAGNOSED.model_copy(update={"diagnostics": None})
BASE_STATE: State = SAMPLES[State]


def empty_track(**options) -> Track:
    return Track("run", "tracking", "test", "thesis_humanoid", None, WELCOME, **options)


def imu_state(time_s: float) -> State:
    return BASE_STATE.model_copy(
        update={
            "time_s": time_s,
            "position_base_in_world": None,
            "orientation_base_in_world_xyzw": None,
            "linear_velocity_base_in_world": None,
            "angular_velocity_base_in_base": None,
            "imu": ImuSample(
                angular_velocity_imu_in_imu=[0.0, 0.0, 0.0],
                linear_acceleration_imu_in_imu=[0.0, 0.0, 9.81],
            ),
        }
    )


def with_estimate(height_m: float) -> Command:
    estimate = BaseEstimateDiagnostics(
        position_base_in_world=[0.1, 0.0, height_m],
        orientation_base_in_world_xyzw=[0.0, 0.0, 0.0, 1.0],
        linear_velocity_base_in_world=[0.0, 0.0, 0.0],
        angular_velocity_base_in_base=[0.0, 0.0, 0.0],
        gyro_bias_in_imu=[0.0, 0.0, 0.0],
        accel_bias_in_imu=[0.0, 0.0, 0.0],
        covariance=np.zeros(15),
        stance_contacts=["left_foot"],
    )
    diagnostics = DIAGNOSED.diagnostics.model_copy(update={"base_estimate": estimate})
    return DIAGNOSED.model_copy(update={"diagnostics": diagnostics})


def test_exchanges_are_timed_from_the_first_state_and_keep_the_sent_base():
    track = empty_track()
    for time_s in (10.0, 10.5, 11.25):
        state = BASE_STATE.model_copy(update={"time_s": time_s})
        assert track.add_exchange(state, PLAIN)
    assert track.time_s == [0.0, 0.5, 1.25]
    np.testing.assert_array_equal(track.states[2].position_base_in_world, [0.0, 0.0, 1.0])
    assert track.tick_at(0.7) == 1 and track.tick_at(-1.0) == 0 and track.tick_at(5.0) == 2


def test_an_imu_state_is_drawn_with_the_servers_base_estimate_held_between_diagnostics():
    track = empty_track()
    assert not track.add_exchange(imu_state(0.0), PLAIN)  # no estimate yet: nothing to draw
    assert track.add_exchange(imu_state(0.1), with_estimate(0.9))
    assert track.add_exchange(imu_state(0.2), PLAIN)  # held from the last diagnostics
    assert track.add_exchange(imu_state(0.3), with_estimate(0.8))
    heights = [state.position_base_in_world[2] for state in track.states]
    assert heights == [0.9, 0.9, 0.8]
    assert track.time_s == pytest.approx([0.1, 0.2, 0.3])


def test_a_track_without_end_keeps_its_last_seconds_only():
    track = empty_track(keep_s=1.0)
    state = RobotState.standing(WELCOME)
    for tick in range(10_000):  # 10 s at 1 kHz
        assert track.add(tick / 1000, state, PLAIN)
    assert len(track.time_s) == len(track.states) == len(track.commands)
    assert track.time_s[-1] == 9.999
    assert track.time_s[-1] - track.time_s[0] >= 1.0  # the last keep_s seconds at least …
    assert len(track.time_s) <= 2001  # … and never more than twice that


def test_a_view_process_that_stops_never_stops_the_loop(caplog):
    from clients.visual.live_process import LiveViewProcess

    view = LiveViewProcess(port=0)
    try:
        assert view.url.startswith("http://127.0.0.1:")
        view._process.kill()
        view._process.wait(timeout=30)
        track = empty_track(keep_s=1.0)
        state = RobotState.standing(WELCOME)
        deadline = time.monotonic() + 30
        with caplog.at_level(logging.WARNING, logger="poise.view"):
            tick = 0
            while "the live view stopped" not in caplog.text:
                assert time.monotonic() < deadline, "the sending thread never noticed"
                track.add(tick / 100, state, DIAGNOSED)
                view.observe(track)  # never raises, never waits
                tick += 1
                time.sleep(0.01)
        assert "the run goes on without it" in caplog.text
    finally:
        view.close()
