"""Motion clips checked against analytic trajectories (Macchietto 2008, eq. 5.3).

Clips are sampled at 200 Hz from closed-form motions: a revolute knee
``q = 0.5 + 0.3 sin(πt)``, a ball joint rotating about a fixed axis by
``θ = 0.3 sin(ωt)``, and a ball joint composed of two rotations whose body
angular velocity turns in the joint frame. Velocities must match the analytic
derivatives to 1e-3 and accelerations to 1e-2 of their peak magnitude (the
accelerations only away from the one-sided ends, whose error is O(h)).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller_server.errors import InvalidParams
from controller_server.features import motion_clip
from controller_server.features.clip_library import CLIP_KEYFRAMES, build_clip, keyframe_clip
from controller_server.features.motion_clip import (
    CLIPS_DIR,
    ClipSample,
    MotionClip,
    load_motion_clip,
    make_sway_clip,
)
from controller_server.models import RobotModel, load_robot_model

RATE_HZ = 200.0
DURATION_S = 2.0
VELOCITY_TOLERANCE = 1e-3  # relative to the peak analytic velocity
ACCELERATION_TOLERANCE = 1e-2  # relative to the peak analytic acceleration
END_MARGIN_S = 0.05  # accelerations are checked this far from either end
OMEGA = 2.0 * math.pi * 0.5
AXIS = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
# Off-frame sample times (not multiples of 1/200 s), ends included.
SAMPLE_TIMES = np.concatenate([[0.0], np.linspace(0.0013, DURATION_S - 0.0017, 157), [DURATION_S]])


@pytest.fixture(scope="module")
def revolute() -> RobotModel:
    return load_robot_model("revolute_humanoid")


@pytest.fixture(scope="module")
def thesis() -> RobotModel:
    return load_robot_model("thesis_humanoid")


def q_start(robot: RobotModel, joint_name: str) -> int:
    """Index of the joint's first entry in the wire ``joint_position``."""
    return robot.model.idx_qs[robot.model.getJointId(joint_name)] - 7


def v_index(robot: RobotModel, joint_name: str) -> int:
    """Index of the joint's first DoF in the full tangent vector."""
    return robot.model.idx_vs[robot.model.getJointId(joint_name)]


def quaternion_xyzw(rotation: np.ndarray) -> np.ndarray:
    return pin.Quaternion(rotation).coeffs().copy()


# --- analytic trajectories: (q_joint(t), v_joint(t), a_joint(t)) --------------------------


def knee(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return (
        np.array([0.5 + 0.3 * math.sin(OMEGA * t)]),
        np.array([0.3 * OMEGA * math.cos(OMEGA * t)]),
        np.array([-0.3 * OMEGA**2 * math.sin(OMEGA * t)]),
    )


def fixed_axis(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotation by θ = 0.3 sin(ωt) about a fixed axis: ω_body = θ̇ u, ω̇_body = θ̈ u."""
    theta = 0.3 * math.sin(OMEGA * t)
    return (
        quaternion_xyzw(pin.exp3(theta * AXIS)),
        0.3 * OMEGA * math.cos(OMEGA * t) * AXIS,
        -0.3 * OMEGA**2 * math.sin(OMEGA * t) * AXIS,
    )


def two_axes(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """R = Rz(α) Rx(β): ω_body = α̇ c + β̇ eₓ with c = Rx(β)ᵀ e_z, ċ = −β̇ eₓ × c."""
    alpha, alpha_dot, alpha_ddot = (
        0.4 * math.sin(OMEGA * t),
        0.4 * OMEGA * math.cos(OMEGA * t),
        -0.4 * OMEGA**2 * math.sin(OMEGA * t),
    )
    beta, beta_dot, beta_ddot = (
        0.3 * math.cos(2 * OMEGA * t),
        -0.6 * OMEGA * math.sin(2 * OMEGA * t),
        -1.2 * OMEGA**2 * math.cos(2 * OMEGA * t),
    )
    e_x, e_z = np.eye(3)[0], np.eye(3)[2]
    rotation = pin.exp3(alpha * e_z) @ pin.exp3(beta * e_x)
    c = pin.exp3(beta * e_x).T @ e_z
    c_dot = -beta_dot * np.cross(e_x, c)
    return (
        quaternion_xyzw(rotation),
        alpha_dot * c + beta_dot * e_x,
        alpha_ddot * c + alpha_dot * c_dot + beta_ddot * e_x,
    )


CASES = {
    "revolute_knee": ("revolute_humanoid", "left_knee", knee),
    "ball_fixed_axis": ("thesis_humanoid", "left_hip", fixed_axis),
    "ball_two_axes": ("thesis_humanoid", "lower_back", two_axes),
}


def clip_of(robot: RobotModel, joint_name: str, trajectory, time_s=None) -> MotionClip:
    """A clip moving one joint along ``trajectory``, the others neutral."""
    start = q_start(robot, joint_name)
    neutral = pin.neutral(robot.model)[7:]

    def joint_position(t: float) -> np.ndarray:
        row = neutral.copy()
        q = trajectory(t)[0]
        row[start : start + len(q)] = q
        return row

    if time_s is None:
        return MotionClip.from_function(robot, joint_position, DURATION_S, RATE_HZ)
    return MotionClip.from_frames(robot, time_s, [joint_position(t) for t in time_s])


def check_against_analytic(robot: RobotModel, joint_name: str, trajectory, clip: MotionClip):
    index = v_index(robot, joint_name)
    nv = len(trajectory(0.0)[1])
    peak_v = max(np.abs(trajectory(t)[1]).max() for t in SAMPLE_TIMES)
    peak_a = max(np.abs(trajectory(t)[2]).max() for t in SAMPLE_TIMES)
    for t in SAMPLE_TIMES:
        sample = clip.sample(t)
        _, v_expected, a_expected = trajectory(t)
        np.testing.assert_allclose(
            sample.v[index : index + nv], v_expected, rtol=0, atol=VELOCITY_TOLERANCE * peak_v
        )
        if END_MARGIN_S <= t <= DURATION_S - END_MARGIN_S:
            np.testing.assert_allclose(
                sample.a[index : index + nv],
                a_expected,
                rtol=0,
                atol=ACCELERATION_TOLERANCE * peak_a,
            )
        others = np.ones(robot.model.nv, dtype=bool)
        others[index : index + nv] = False
        assert not sample.v[others].any() and not sample.a[others].any()


@pytest.mark.parametrize("case", CASES)
def test_derivatives_match_analytic(case):
    model_name, joint_name, trajectory = CASES[case]
    robot = load_robot_model(model_name)
    check_against_analytic(robot, joint_name, trajectory, clip_of(robot, joint_name, trajectory))


@pytest.mark.parametrize("case", ["revolute_knee", "ball_two_axes"])
def test_non_uniform_time_steps(case):
    model_name, joint_name, trajectory = CASES[case]
    robot = load_robot_model(model_name)
    rng = np.random.default_rng(0)
    # Steps between 2.5 and 7.5 ms; the end pinned to the duration.
    steps = rng.uniform(0.5, 1.5, size=400) / RATE_HZ
    time_s = np.concatenate([[0.0], np.cumsum(steps)])
    time_s = time_s[time_s < DURATION_S - 1e-3]
    time_s = np.append(time_s, DURATION_S)
    clip = clip_of(robot, joint_name, trajectory, time_s)
    check_against_analytic(robot, joint_name, trajectory, clip)


@pytest.mark.parametrize("case", CASES)
def test_frame_times_return_frames_exactly(case):
    model_name, joint_name, trajectory = CASES[case]
    robot = load_robot_model(model_name)
    clip = clip_of(robot, joint_name, trajectory)
    for i, t in enumerate(clip.time_s):
        sample = clip.sample(t)
        assert np.array_equal(sample.q, clip.configurations[i])
        assert np.array_equal(sample.v, clip.velocities[i])
        assert np.array_equal(sample.a, clip.accelerations[i])


@pytest.mark.parametrize("case", CASES)
def test_configurations_track_and_stay_normalised(case):
    model_name, joint_name, trajectory = CASES[case]
    robot = load_robot_model(model_name)
    clip = clip_of(robot, joint_name, trajectory)
    model = robot.model
    start = q_start(robot, joint_name) + 7
    ball_starts = [model.idx_qs[model.getJointId(j.name)] for j in robot.joints if j.kind == "ball"]
    for t in SAMPLE_TIMES:
        q = clip.sample(t).q
        assert q.shape == (model.nq,)
        assert np.array_equal(q[:7], [0, 0, 0, 0, 0, 0, 1])
        for s in [3, *ball_starts]:
            assert abs(np.linalg.norm(q[s : s + 4]) - 1.0) < 1e-12
        # Interpolated on the manifold: within h²/8 of the true path.
        expected = q.copy()
        q_joint = trajectory(t)[0]
        expected[start : start + len(q_joint)] = q_joint
        assert np.linalg.norm(pin.difference(model, q, expected)) < 1e-4


def test_interpolation_is_on_the_manifold(thesis):
    """Halfway between two frames 0.4 rad apart about z: exactly 0.2 rad, unit quaternion."""
    start = q_start(thesis, "neck")
    neutral = pin.neutral(thesis.model)[7:]
    rows = [neutral.copy(), neutral.copy()]
    rows[1][start : start + 4] = quaternion_xyzw(pin.exp3(np.array([0.0, 0.0, 0.4])))
    clip = MotionClip.from_frames(thesis, [0.0, 1.0], rows)
    q = clip.sample(0.5).q
    np.testing.assert_allclose(q[7 + start : 11 + start], [0, 0, math.sin(0.1), math.cos(0.1)])
    index = v_index(thesis, "neck")
    np.testing.assert_allclose(clip.velocities[:, index : index + 3], [[0, 0, 0.4]] * 2)
    assert not clip.accelerations.any()


def test_quaternion_sign_flips_do_not_matter(thesis):
    """q and −q are one rotation: flipping every other frame changes no derivative."""
    clip = clip_of(thesis, "left_hip", fixed_axis)
    rows = np.array(clip.configurations[:, 7:])
    start = q_start(thesis, "left_hip")
    rows[::2, start : start + 4] *= -1.0
    flipped = MotionClip.from_frames(thesis, clip.time_s, rows)
    np.testing.assert_allclose(flipped.velocities, clip.velocities, atol=1e-9)
    np.testing.assert_allclose(flipped.accelerations, clip.accelerations, atol=1e-6)


# --- playback ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def knee_clip(revolute) -> MotionClip:
    return clip_of(revolute, "left_knee", knee)


def assert_sample_close(actual: ClipSample, expected: ClipSample, atol: float = 1e-12):
    for a, e in zip(actual, expected, strict=True):
        np.testing.assert_allclose(a, e, rtol=0, atol=atol)


def test_start_offsets_playback(knee_clip):
    for tau in (0.0, 0.3131, 1.0, 1.77):
        assert_sample_close(knee_clip.sample(5.0 + tau, start_s=5.0), knee_clip.sample(tau))


@pytest.mark.parametrize("speed", [0.5, 2.0, 3.0])
def test_speed_scales_velocity_and_acceleration(knee_clip, speed):
    for t in (0.1, 0.2345, 0.6):
        sample, reference = knee_clip.sample(t, speed=speed), knee_clip.sample(t * speed)
        np.testing.assert_allclose(sample.q, reference.q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(sample.v, speed * reference.v, rtol=0, atol=1e-12)
        np.testing.assert_allclose(sample.a, speed**2 * reference.a, rtol=0, atol=1e-12)


def test_speed_matches_analytic_time_scaling(revolute, knee_clip):
    """Played at speed 2 the knee follows q(2t): v = 2 q̇(2t), a = 4 q̈(2t)."""
    index = v_index(revolute, "left_knee")
    for t in (0.2, 0.4, 0.7):
        sample = knee_clip.sample(t, speed=2.0)
        _, v, a = knee(2.0 * t)
        assert abs(sample.v[index] - 2.0 * v[0]) < 2.0 * VELOCITY_TOLERANCE * 0.3 * OMEGA
        assert abs(sample.a[index] - 4.0 * a[0]) < 4.0 * ACCELERATION_TOLERANCE * 0.3 * OMEGA**2


def test_loop_wraps_modulo_duration(knee_clip):
    for tau in (0.0, 0.25, 1.3):
        for laps in (1, 3):
            assert_sample_close(
                knee_clip.sample(laps * DURATION_S + tau, loop=True),
                knee_clip.sample(tau),
                atol=1e-9,
            )
    # With start and speed together: clip time (t − start)·speed, wrapped.
    assert_sample_close(
        knee_clip.sample(1.0 + 2.6 / 2.0, start_s=1.0, speed=2.0, loop=True),
        knee_clip.sample(0.6 / 2.0, speed=2.0),
        atol=1e-9,
    )


def test_hold_before_start_and_after_end(knee_clip):
    zeros = np.zeros(knee_clip.model.nv)
    for t, frame in ((-1.0, 0), (0.99, 0), (DURATION_S + 1e-6, -1), (100.0, -1)):
        sample = knee_clip.sample(t, start_s=1.0 if t == 0.99 else 0.0)
        assert np.array_equal(sample.q, knee_clip.configurations[frame])
        assert np.array_equal(sample.v, zeros) and np.array_equal(sample.a, zeros)
    # Looping does not play before the start.
    assert np.array_equal(knee_clip.sample(-0.5, loop=True).v, zeros)


@settings(max_examples=60, deadline=None)
@given(
    time_s=st.floats(-5.0, 20.0),
    start_s=st.floats(-2.0, 2.0),
    speed=st.floats(0.0, 4.0),
    loop=st.booleans(),
)
def test_samples_are_valid_references(knee_clip, time_s, start_s, speed, loop):
    q, v, a = knee_clip.sample(time_s, start_s=start_s, speed=speed, loop=loop)
    assert q.shape == (knee_clip.model.nq,) and v.shape == a.shape == (knee_clip.model.nv,)
    assert np.all(np.isfinite(q)) and np.all(np.isfinite(v)) and np.all(np.isfinite(a))
    assert not v[:6].any() and not a[:6].any()
    knee_q = q[7 + q_start_of_knee(knee_clip)]
    assert 0.2 - 1e-9 <= knee_q <= 0.8 + 1e-9


def q_start_of_knee(clip: MotionClip) -> int:
    return clip.model.idx_qs[clip.model.getJointId("left_knee")] - 7


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"speed": -1.0}, "params.speed"),
        ({"speed": math.nan}, "params.speed"),
        ({"start_s": math.inf}, "params.start_s"),
    ],
)
def test_bad_playback_arguments(knee_clip, kwargs, field):
    with pytest.raises(InvalidParams) as info:
        knee_clip.sample(0.5, **kwargs)
    assert info.value.field == field


# --- files ---------------------------------------------------------------------------------


def test_builtin_clip_loads_by_name(thesis):
    clip = load_motion_clip("stand_sway", thesis)
    assert clip.name == "stand_sway" and clip.num_frames == 101 and clip.duration_s == 2.0
    # It is what make_sway_clip writes: ±0.1 rad about x at the lower back, the rest neutral.
    regenerated = make_sway_clip(thesis)
    np.testing.assert_array_equal(clip.configurations, regenerated.configurations)
    index = v_index(thesis, "lower_back")
    angles = [pin.log3(pin.Quaternion(q[7:11]).toRotationMatrix()) for q in clip.configurations]
    assert max(abs(angle[0]) for angle in angles) == pytest.approx(0.1)
    assert not np.any(np.delete(np.array(angles), 0, axis=1))
    moving = np.zeros(thesis.model.nv, dtype=bool)
    moving[index] = True
    assert not clip.velocities[:, ~moving].any()
    # One full period: looping is seamless.
    assert_sample_close(clip.sample(0.0), clip.sample(2.0, loop=True))
    assert (CLIPS_DIR / "stand_sway.json").is_file()


def test_clip_loads_by_path_and_round_trips(tmp_path, allow_model_dir, revolute, knee_clip):
    allow_model_dir(tmp_path)
    orientation = np.tile(quaternion_xyzw(pin.exp3(np.array([0.0, 0.1, 0.0]))), (3, 1))
    rows = knee_clip.configurations[:3, 7:]
    clip = MotionClip.from_frames(revolute, [0.0, 0.1, 0.25], rows, orientation, name="tilted")
    path = tmp_path / "tilted.json"
    clip.to_json(path)
    loaded = load_motion_clip(str(path), revolute)
    assert loaded.name == "tilted" and loaded.model_name == "revolute_humanoid"
    np.testing.assert_array_equal(loaded.time_s, clip.time_s)
    np.testing.assert_array_equal(loaded.configurations, clip.configurations)
    np.testing.assert_allclose(loaded.configurations[:, 3:7], orientation)
    assert not loaded.velocities[:, :6].any()
    # Path objects work too, and the orientation is omitted when upright.
    knee_clip.to_json(tmp_path / "knee.json")
    assert "orientation" not in (tmp_path / "knee.json").read_text()
    assert load_motion_clip(tmp_path / "knee.json", revolute).num_frames == knee_clip.num_frames


def valid_document(robot: RobotModel) -> dict:
    neutral = pin.neutral(robot.model)[7:].tolist()
    return {
        "name": "test",
        "model": robot.name,
        "joint_names": [joint.name for joint in robot.joints],
        "time_s": [0.0, 0.1, 0.2],
        "joint_position": [neutral, neutral, neutral],
    }


def _drop_last_joint_name(d):
    d["joint_names"] = d["joint_names"][:-1]


def _swap_joint_names(d):
    d["joint_names"][0], d["joint_names"][1] = d["joint_names"][1], d["joint_names"][0]


def _short_row(d):
    d["joint_position"][1] = d["joint_position"][1][:-1]


def _missing_row(d):
    d["joint_position"] = d["joint_position"][:2]


def _nan(d):
    d["joint_position"][2][0] = math.nan


def _inf_time(d):
    d["time_s"][2] = math.inf


def _repeated_time(d):
    d["time_s"] = [0.0, 0.1, 0.1]


def _decreasing_time(d):
    d["time_s"] = [0.0, 0.2, 0.1]


def _one_frame(d):
    d["time_s"], d["joint_position"] = [0.0], d["joint_position"][:1]


def _string_value(d):
    d["joint_position"][0][0] = "zero"


def _short_orientation(d):
    d["orientation_base_in_world_xyzw"] = [[0, 0, 0, 1], [0, 0, 1], [0, 0, 0, 1]]


def _zero_orientation(d):
    d["orientation_base_in_world_xyzw"] = [[0, 0, 0, 1], [0, 0, 0, 0], [0, 0, 0, 1]]


def _zero_ball_quaternion(d):
    d["joint_position"][0][:4] = [0, 0, 0, 0]


def _no_times(d):
    del d["time_s"]


MUTATIONS = {
    "joint_names_missing_one": _drop_last_joint_name,
    "joint_names_out_of_order": _swap_joint_names,
    "row_too_short": _short_row,
    "row_missing": _missing_row,
    "nan_position": _nan,
    "infinite_time": _inf_time,
    "repeated_time": _repeated_time,
    "decreasing_time": _decreasing_time,
    "one_frame": _one_frame,
    "string_value": _string_value,
    "orientation_row_too_short": _short_orientation,
    "zero_orientation": _zero_orientation,
    "zero_ball_quaternion": _zero_ball_quaternion,
    "no_time_s": _no_times,
}


@pytest.mark.parametrize("mutation", MUTATIONS)
def test_invalid_clip_raises_invalid_params(tmp_path, allow_model_dir, thesis, mutation):
    allow_model_dir(tmp_path)
    document = valid_document(thesis)
    MUTATIONS[mutation](document)
    path = tmp_path / "clip.json"
    path.write_text(json.dumps(document))  # NaN / Infinity as Python's json writes them
    with pytest.raises(InvalidParams) as info:
        load_motion_clip(str(path), thesis)
    assert info.value.field == "params.clip"


def test_valid_document_loads(tmp_path, allow_model_dir, thesis):
    allow_model_dir(tmp_path)
    path = tmp_path / "clip.json"
    path.write_text(json.dumps(valid_document(thesis)))
    assert load_motion_clip(path, thesis).num_frames == 3


@pytest.mark.parametrize(
    "text", ["", "{not json", "[1, 2, 3]", "\xff\xfe"], ids=["empty", "broken", "list", "bytes"]
)
def test_bad_json_raises_invalid_params(tmp_path, allow_model_dir, thesis, text):
    allow_model_dir(tmp_path)
    path = tmp_path / "clip.json"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(InvalidParams) as info:
        load_motion_clip(path, thesis)
    assert info.value.field == "params.clip"


@pytest.mark.parametrize("name", ["no_such_clip", "/nonexistent/clip.json", "missing.json"])
def test_unknown_clip_raises_invalid_params(thesis, name):
    with pytest.raises(InvalidParams) as info:
        load_motion_clip(name, thesis)
    assert info.value.field == "params.clip"
    assert "stand_sway" in info.value.detail


def test_clip_for_another_robot_is_refused(revolute):
    with pytest.raises(InvalidParams) as info:
        load_motion_clip("stand_sway", revolute)
    assert info.value.field == "params.clip" and "joint_names" in info.value.detail


def test_from_function_validates(revolute):
    neutral = pin.neutral(revolute.model)[7:]
    for duration_s, rate_hz in ((0.0, 100.0), (1.0, math.nan), (-1.0, 10.0)):
        with pytest.raises(InvalidParams):
            MotionClip.from_function(revolute, lambda t: neutral, duration_s, rate_hz)
    with pytest.raises(InvalidParams):
        MotionClip.from_function(revolute, lambda t: neutral[:-1], 1.0, 10.0)
    with pytest.raises(InvalidParams):
        make_sway_clip(revolute)


def test_arrays_are_read_only(knee_clip):
    with pytest.raises(ValueError):
        knee_clip.configurations[0, 0] = 1.0


def test_module_exports():
    for name in motion_clip.__all__:
        assert hasattr(motion_clip, name)
    assert isinstance(CLIPS_DIR, Path)


def test_clip_time_counts_from_the_first_frame(revolute, knee_clip):
    """A clip whose frames start at 10 s plays from its first frame at ``start_s``."""
    shifted = MotionClip.from_frames(
        revolute, knee_clip.time_s + 10.0, knee_clip.configurations[:, 7:]
    )
    assert shifted.duration_s == pytest.approx(DURATION_S)
    assert np.array_equal(shifted.sample(0.0).q, knee_clip.configurations[0])
    assert_sample_close(shifted.sample(0.7321), knee_clip.sample(0.7321), atol=1e-9)


def test_builtin_clips_are_what_the_clip_library_writes(thesis):
    """The committed JSON files are the generator's output (`python -m ...clip_library`)."""
    for name in ("stand_sway", *CLIP_KEYFRAMES):
        committed = (CLIPS_DIR / f"{name}.json").read_text()
        assert committed == build_clip(name, thesis).to_json(), name


def test_single_support_clips_lean_over_the_right_foot_then_come_back(thesis):
    """Once leaned, the CM is over the right foot; the clips start and end neutral, at rest."""
    model, data = thesis.model, thesis.model.createData()
    for name, leaned_s in (("leg_swing", 1.2), ("kicks", 1.2), ("leg_circle", 2.0)):
        clip = load_motion_clip(name, thesis)
        q = clip.sample(leaned_s).q.copy()
        pin.framesForwardKinematics(model, data, q)
        right_foot_y = data.oMf[model.getFrameId("right_foot")].translation[1]
        com_y = pin.centerOfMass(model, data, q)[1]
        assert abs(com_y - right_foot_y) < 0.02, (name, com_y, right_foot_y)
        for t in (0.0, clip.duration_s):
            sample = clip.sample(t)
            np.testing.assert_allclose(sample.q[7:], pin.neutral(model)[7:], atol=1e-12)
            # Eased keyframes start and end at rest; finite differences at 50 Hz leave O(h).
            np.testing.assert_allclose(sample.v, 0.0, atol=0.05)


def test_keyframes_must_name_ball_joints_in_increasing_time(thesis):
    with pytest.raises(ValueError, match="increase"):
        keyframe_clip(thesis, [(0.0, {}), (1.0, {}), (1.0, {})], "x")
    with pytest.raises(ValueError, match="not ball joints"):
        keyframe_clip(thesis, [(0.0, {}), (1.0, {"left_toe": (0.0, 0.1, 0.0)})], "x")
