"""The compiled estimator against its specification, the Python ``ImuBaseEstimator``.

Per built-in model, 1,200 seeded IMU ticks in sequence (the filter state evolves): the
synthetic base motion and BMI088-class IMU of ``test_base_estimator`` (its helpers) on an
upside-down, offset IMU mount, the joints swaying about standing so that the feet's corners
on the ground change, feet lifted and set down, a gap that restarts the filter, and bad
inputs between good ones, at the start too (NaN, infinite and misshapen readings and
joints, time not advancing, a wrong flag count, no foot on the ground). Both kernels must
raise the same error (type, field, words; the numbers in it within the tolerance) on the
same ticks, and otherwise agree, estimate and filter state (pose, velocity, biases,
covariance, stance points, time, corners in use), within 1e-8 of each field's scale. Then
the hand-over between kernels in one estimator, and the session following its
controller's ``kernel``, threads, and a missing core.
"""

from __future__ import annotations

import dataclasses
import re
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pinocchio as pin
import pytest

from controller_server.compiled import CompiledCoreUnavailable
from controller_server.errors import EstimatorInputError
from controller_server.estimation import EstimatorNoise, ImuBaseEstimator, compiled_estimator
from controller_server.models import BUILTIN_MODELS, RobotModel, load_robot_model
from controller_server.session import Session
from protocol.messages import Hello, ImuSample, State
from tests.controller_server.test_base_estimator import MOUNT, NoisyImu, base_motion

MODEL_NAMES = tuple(BUILTIN_MODELS)
TICKS = 1200
RATE_HZ = 1000.0
TOLERANCE = 1e-8
HELLO_MOUNT = {
    "imu_position_in_frame": tuple(MOUNT.position_imu_in_base),
    "imu_orientation_in_frame_xyzw": tuple(pin.Quaternion(MOUNT.rotation_imu_to_base).coeffs()),
}
"""``test_base_estimator``'s IMU mount (upside down, turned, off the base origin) in ``hello``."""

BAD_INPUTS = {
    150: ("imu", "angular_velocity_imu_in_imu", np.array([np.nan, 0.0, 0.0])),
    350: ("imu", "linear_acceleration_imu_in_imu", np.array([0.0, np.inf, 9.8])),
    450: ("time", None, None),  # the previous tick's time again
    650: ("joint", None, np.nan),  # a leg joint: that foot's point is NaN
    760: ("flags", None, None),  # one flag too few
    801: ("imu", "angular_velocity_imu_in_imu", np.array([0.0, np.nan, 0.0])),  # at the start
    802: ("no stance", None, None),  # the start needs a foot on the ground
    905: ("joint", None, np.inf),
    1000: ("imu", "angular_velocity_imu_in_imu", np.zeros(2)),  # misshapen
}
"""Tick → what is wrong with it (each tick after it is good again)."""
GAP_TICK = 800
"""This tick comes 80 ms after the previous one: the filter restarts at the next."""


def flags_at(tick: int) -> list[bool]:
    """Both feet, the left lifted over 200–299, the right over 500–599, both over 700–709."""
    left = not (200 <= tick < 300 or 700 <= tick < 710)
    right = not (500 <= tick < 600 or 700 <= tick < 710)
    return [left, right]


def imu_sequence(robot: RobotModel, seed: int, *, ahrs: bool = False) -> list[State]:
    """``TICKS`` states: the synthetic IMU, swaying joints, the flags, a gap and bad inputs."""
    rng = np.random.default_rng(seed)
    imu = NoisyImu(
        rng, EstimatorNoise(), gyro_bias=rng.normal(0, 0.01, 3), accel_bias=rng.normal(0, 0.05, 3)
    )
    model = robot.model
    amplitude = rng.uniform(0.0, 0.08, model.nv)
    amplitude[:6] = 0.0
    frequency_hz, phase = rng.uniform(0.3, 2.0, model.nv), rng.uniform(0, 2 * np.pi, model.nv)
    dt = 1.0 / RATE_HZ
    states, time_s = [], 0.0
    for tick in range(TICKS):
        time_s += 0.08 if tick == GAP_TICK else dt
        truth = base_motion(time_s)
        gyro, accel = imu.read(time_s, dt, truth)
        q = pin.integrate(
            model,
            robot.standing_configuration,
            amplitude * np.sin(2 * np.pi * frequency_hz * time_s + phase),
        )
        orientation = None
        if ahrs:
            rotation_imu = truth[0] @ MOUNT.rotation_imu_to_base
            orientation = pin.Quaternion(rotation_imu).coeffs().copy()
        sample = ImuSample.model_construct(
            angular_velocity_imu_in_imu=gyro,
            linear_acceleration_imu_in_imu=accel,
            orientation_imu_in_world_xyzw=orientation,
        )
        states.append(
            State.model_construct(
                seq=tick,
                time_s=time_s,
                joint_position=q[7:].copy(),
                joint_velocity=np.zeros(model.nv - 6),
                contact_flags=flags_at(tick),
                imu=sample,
            )
        )
    for tick, (kind, field, value) in BAD_INPUTS.items():
        states[tick] = broken(robot, states[tick], states[tick - 1], kind, field, value)
    return states


def broken(robot, state: State, previous: State, kind: str, field, value) -> State:
    """``state`` with one bad input (built without validation, as a client's bug would be)."""
    if kind == "imu":
        imu = state.imu.model_copy(update={field: value})
        return state.model_copy(update={"imu": imu})
    if kind == "time":
        return state.model_copy(update={"time_s": previous.time_s})
    if kind == "flags":
        return state.model_copy(update={"contact_flags": state.contact_flags[:-1]})
    if kind == "no stance":
        return state.model_copy(update={"contact_flags": [False] * len(state.contact_flags)})
    joint_position = state.joint_position.copy()
    # The first joint in the left foot's chain (below the free flyer).
    model = robot.model
    joint = model.frames[robot.contacts[0].frame_id].parentJoint
    while model.parents[joint] > 1:
        joint = model.parents[joint]
    joint_position[model.joints[joint].idx_q - 7] = value
    return state.model_copy(update={"joint_position": joint_position})


NUMBER = re.compile(r"-?(?:\d+\.\d*(?:e[-+]\d+)?|\d+e[-+]\d+|\d+|nan|inf)")


def same_error(python: EstimatorInputError, compiled: EstimatorInputError) -> float:
    """Assert the same type, field and words; return the largest relative gap of its numbers."""
    assert type(compiled) is type(python)
    assert compiled.field == python.field
    assert NUMBER.sub("#", compiled.detail) == NUMBER.sub("#", python.detail), (
        python.detail,
        compiled.detail,
    )
    expected, actual = (np.array(NUMBER.findall(e.detail), dtype=float) for e in (python, compiled))
    finite = np.isfinite(expected)
    np.testing.assert_array_equal(np.isfinite(actual), finite)
    np.testing.assert_array_equal(actual[~finite], expected[~finite])  # the same NaNs, ±inf
    return relative_gap(expected[finite], actual[finite])


def relative_gap(expected, actual) -> float:
    """``max |a − e| / max |e|`` (0 for empty or all-zero fields that agree)."""
    expected, actual = np.asarray(expected, dtype=float), np.asarray(actual, dtype=float)
    assert expected.shape == actual.shape
    if expected.size == 0:
        return 0.0
    scale = np.abs(expected).max()
    gap = np.abs(actual - expected).max()
    return float(gap / scale) if scale > 0 else float(gap)


def estimate_gaps(python, compiled) -> dict[str, float]:
    """Per field of the two ``BaseEstimate``s, the relative gap (the contacts' names equal)."""
    assert list(compiled.position_contacts_in_world) == list(python.position_contacts_in_world)
    gaps = {}
    for field in dataclasses.fields(python):
        expected, actual = getattr(python, field.name), getattr(compiled, field.name)
        if isinstance(expected, dict):
            expected, actual = list(expected.values()), list(actual.values())
        gaps[f"estimate.{field.name}"] = relative_gap(expected, actual)
    return gaps


def state_gaps(python: ImuBaseEstimator, compiled: ImuBaseEstimator) -> dict[str, float]:
    """The filter's state and the session's, Python fields against the compiled core's."""
    values = compiled._compiled.state()
    estimator = python.estimator
    assert values["initialized"] == estimator.initialized
    assert values["stance"] == estimator._stance
    assert [tuple(c) for c in values["corners"]] == list(python._corners)
    assert values["time_s"] == python._time_s
    if not estimator.initialized:
        return {}
    return {
        "state.rotation": relative_gap(estimator._rotation, values["rotation"]),
        "state.columns": relative_gap(estimator._columns, values["columns"]),
        "state.bias": relative_gap(estimator._bias, values["bias"]),
        "state.covariance": relative_gap(estimator._covariance, values["covariance"]),
        "state.gyro_reading": relative_gap(estimator._gyro_reading, values["gyro_reading"]),
    }


def outcome(estimator: ImuBaseEstimator, state: State, kernel: str):
    """The estimate, or the error raised."""
    try:
        return estimator(state, kernel=kernel)
    except EstimatorInputError as error:
        return error


def gaps_between(expected, actual, tick: int) -> dict[str, float]:
    """Both estimates' gaps, or both errors' (the same error), by name."""
    if isinstance(expected, Exception) or isinstance(actual, Exception):
        assert isinstance(expected, Exception) and isinstance(actual, Exception), (
            tick,
            expected,
            actual,
        )
        return {"error numbers": same_error(expected, actual)}
    return estimate_gaps(expected, actual)


def run_both(robot: RobotModel, hello: Hello, states: list[State]):
    """Each state through both kernels; the largest gaps, the error ticks, stance changes."""
    python = ImuBaseEstimator(robot, hello)
    compiled = ImuBaseEstimator(robot, hello)
    worst: dict[str, float] = {}
    errors, stance_counts = [], set()
    for tick, state in enumerate(states):
        expected = outcome(python, state, "python")
        actual = outcome(compiled, state, "compiled")
        gaps = gaps_between(expected, actual, tick) | state_gaps(python, compiled)
        if isinstance(expected, Exception):
            errors.append((tick, expected.field))
        else:
            stance_counts.add(len(expected.position_contacts_in_world))
        for name, gap in gaps.items():
            worst[name] = max(worst.get(name, 0.0), gap)
    return worst, errors, stance_counts


@pytest.fixture(scope="module", params=MODEL_NAMES)
def robot(request) -> RobotModel:
    return load_robot_model(request.param)


# The Python's own warnings on a NaN joint (the mean of no corner on the ground).
pytestmark = [
    pytest.mark.filterwarnings("ignore:Mean of empty slice:RuntimeWarning"),
    pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning"),
]


@pytest.mark.parametrize("ahrs", [False, True], ids=["levelled", "ahrs"])
def test_1200_imu_ticks_agree_with_the_python_filter(robot, ahrs):
    hello = Hello(model=robot.name, **HELLO_MOUNT)
    states = imu_sequence(robot, seed=len(robot.name) + ahrs, ahrs=ahrs)
    worst, errors, stance_counts = run_both(robot, hello, states)
    print(f"\n{robot.name} ({'ahrs' if ahrs else 'levelled'}): largest relative gaps")
    for name, gap in sorted(worst.items()):
        print(f"  {name:<40}{gap:.1e}")
    assert max(worst.values()) <= TOLERANCE, worst
    # Every bad input and the gap were refused, by both, naming the state's fields.
    assert [tick for tick, _ in errors] == sorted([*BAD_INPUTS, GAP_TICK])
    fields = dict(errors)
    assert fields[150] == fields[801] == fields[1000] == "imu.angular_velocity_imu_in_imu"
    assert fields[350] == "imu.linear_acceleration_imu_in_imu"
    assert fields[450] == fields[GAP_TICK] == "time_s"
    assert fields[650] == fields[905] == "joint_position"
    assert fields[760] == fields[802] == "contact_flags"
    assert stance_counts == {0, 1, 2}  # contact switches: both feet, one, none


def test_the_kernel_can_change_between_ticks_without_restarting_the_filter(robot):
    """One estimator alternating kernels every 37 ticks follows the Python-only one."""
    hello = Hello(model=robot.name, **HELLO_MOUNT)
    states = imu_sequence(robot, seed=11)[:400]
    reference = ImuBaseEstimator(robot, hello)
    switching = ImuBaseEstimator(robot, hello)
    worst = 0.0
    for tick, state in enumerate(states):
        kernel = ("python", "compiled")[tick // 37 % 2]
        expected = outcome(reference, state, "python")
        actual = outcome(switching, state, kernel)
        worst = max(worst, *gaps_between(expected, actual, tick).values())
    assert worst <= TOLERANCE


def test_the_session_estimates_with_its_controllers_kernel():
    """A session whose controller runs ``kernel = "compiled"`` estimates by the core too."""
    hello = Hello(model="thesis_humanoid", **HELLO_MOUNT)
    robot = load_robot_model("thesis_humanoid")
    states = [s for s in imu_sequence(robot, seed=3)[:120] if np.all(np.isfinite(s.joint_position))]
    compiled = Session(hello.model_copy(update={"params": {"kernel": "compiled"}}))
    python = Session(hello.model_copy(update={"params": {"kernel": "python"}}))
    for state in states:
        expected = python.step(state).diagnostics
        actual = compiled.step(state).diagnostics
        if expected is not None:
            assert (
                relative_gap(expected.base_estimate.covariance, actual.base_estimate.covariance)
                <= TOLERANCE
            )
            assert (
                relative_gap(
                    expected.base_estimate.position_base_in_world,
                    actual.base_estimate.position_base_in_world,
                )
                <= TOLERANCE
            )
    assert compiled.base_estimator._kernel == "compiled"
    assert python.base_estimator._kernel == "python"
    assert python.base_estimator._compiled is None


def test_an_unknown_kernel_is_a_value_error():
    robot = load_robot_model("thesis_humanoid")
    estimator = ImuBaseEstimator(robot, Hello(model=robot.name))
    with pytest.raises(ValueError, match="kernel='fast'"):
        estimator(imu_sequence(robot, seed=0)[0], kernel="fast")


def test_without_the_core_the_compiled_kernel_says_why_and_the_python_one_goes_on(monkeypatch):
    def missing():
        raise CompiledCoreUnavailable("the compiled core cannot be imported (as if not built)")

    monkeypatch.setattr(compiled_estimator, "load_core", missing)
    robot = load_robot_model("thesis_humanoid")
    estimator = ImuBaseEstimator(robot, Hello(model=robot.name))
    states = imu_sequence(robot, seed=0)[:3]
    estimator(states[0])
    with pytest.raises(CompiledCoreUnavailable, match="cannot be imported"):
        estimator(states[1], kernel="compiled")
    assert estimator(states[1]).covariance.shape == (15, 15)  # never a silent fall back


def test_sessions_estimate_in_parallel_threads_as_alone():
    """The core releases the GIL: two sessions' estimators on two threads, as run alone."""
    robot = load_robot_model("revolute_humanoid")
    hello = Hello(model=robot.name, **HELLO_MOUNT)
    sequences = [imu_sequence(robot, seed=seed)[:300] for seed in (5, 6)]

    def run(states):
        estimator = ImuBaseEstimator(robot, hello)
        return [outcome(estimator, state, "compiled") for state in states]

    alone = [run(states) for states in sequences]
    with ThreadPoolExecutor(max_workers=2) as pool:
        together = list(pool.map(run, sequences))
    for expected_run, actual_run in zip(alone, together, strict=True):
        for tick, (expected, actual) in enumerate(zip(expected_run, actual_run, strict=True)):
            assert max(gaps_between(expected, actual, tick).values()) == 0.0
