"""States that give the base as an IMU reading (issue 17): estimated per session, typed errors.

Through the session table and the codec both ways, as a worker serves them (no sockets;
the simulated runs in ``tests/clients/test_imu_balance.py`` go through a real server).
"""

import msgpack
import numpy as np
import pinocchio as pin
import pytest

from clients.state import RobotState
from controller_server.session_table import SessionTable
from protocol import ErrorCode, decode, encode
from protocol.messages import Command, Error, Hello, ImuSample, Welcome

ALICE = b"alice"
GRAVITY_UP = np.array([0.0, 0.0, 9.80665])
"""An accelerometer at rest, level: the specific force is +g up."""


@pytest.fixture
def server():
    return SessionTable()


def ask(server, message):
    """Send through the codec both ways, as the socket loop does."""
    payload = message if isinstance(message, bytes) else encode(message)
    return decode(encode(server.handle(ALICE, payload)))


def hello(server, **fields) -> Welcome:
    reply = ask(server, Hello(seq=1, model="thesis_humanoid", **fields))
    assert isinstance(reply, Welcome), reply
    return reply


def standing(welcome: Welcome) -> RobotState:
    return RobotState.standing(welcome)


def imu_state(welcome, time_s, *, seq=2, gyro=(0.0, 0.0, 0.0), accel=GRAVITY_UP, flags=None):
    """The standing robot's joints and a still, level IMU (on the root body, unturned)."""
    sample = ImuSample(
        angular_velocity_imu_in_imu=np.array(gyro, dtype=float),
        linear_acceleration_imu_in_imu=np.array(accel, dtype=float),
    )
    flags = [True] * len(welcome.contacts) if flags is None else flags
    message = standing(welcome).to_imu_message(time_s, flags, sample)
    return message.model_copy(update={"seq": seq})


def payload(message, **changes):
    """The message's msgpack map with keys replaced (``None``: removed)."""
    values = msgpack.unpackb(encode(message))
    for key, value in changes.items():
        if value is None:
            values.pop(key, None)
        else:
            values[key] = value
    return msgpack.packb(values)


def assert_error(reply, code, field):
    assert isinstance(reply, Error), reply
    assert (reply.code, reply.field) == (code, field), reply
    assert reply.detail
    return reply.detail


def test_a_still_robot_is_estimated_where_it_stands_and_commanded_as_with_the_truth(server):
    """The estimate of a robot standing still is its true pose; the torques match the truth's."""
    welcome = hello(server)
    for tick in range(50):
        command = ask(server, imu_state(welcome, tick * 1e-3, seq=tick + 2))
        assert isinstance(command, Command), command
    estimate = command.diagnostics.base_estimate
    np.testing.assert_allclose(
        estimate.position_base_in_world, welcome.standing_position_base_in_world, atol=1e-3
    )
    np.testing.assert_allclose(
        np.abs(estimate.orientation_base_in_world_xyzw), [0, 0, 0, 1], atol=1e-6
    )
    np.testing.assert_allclose(estimate.linear_velocity_base_in_world, 0.0, atol=1e-3)
    assert estimate.covariance.shape == (225,)
    covariance = estimate.covariance.reshape(15, 15)
    np.testing.assert_allclose(covariance, covariance.T, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(covariance) > -1e-12)
    assert sorted(estimate.stance_contacts) == sorted(c.name for c in welcome.contacts)
    # The same tick with the true base (fresh session: the same controller history).
    truth = SessionTable()
    assert isinstance(truth.handle(ALICE, encode(Hello(seq=1, model="thesis_humanoid"))), Welcome)
    for tick in range(50):
        message = standing(welcome).to_message(tick * 1e-3, [True, True])
        reference = decode(encode(truth.handle(ALICE, encode(message))))
    assert reference.diagnostics.base_estimate is None
    scale = np.abs(reference.joint_torque).max()
    np.testing.assert_allclose(command.joint_torque, reference.joint_torque, atol=1e-3 * scale)


def test_neither_or_both_base_forms_are_refused_naming_the_fields(server):
    welcome = hello(server)
    with_imu = imu_state(welcome, 0.0)
    full = standing(welcome).to_message(0.0, [True, True])
    detail = assert_error(
        ask(
            server,
            payload(
                full,
                position_base_in_world=None,
                orientation_base_in_world_xyzw=None,
                linear_velocity_base_in_world=None,
                angular_velocity_base_in_base=None,
            ),
        ),
        ErrorCode.INVALID_FIELD,
        "position_base_in_world",
    )
    assert "`imu`" in detail
    detail = assert_error(
        ask(server, payload(full, angular_velocity_base_in_base=None)),
        ErrorCode.INVALID_FIELD,
        "angular_velocity_base_in_base",
    )
    assert "lacks angular_velocity_base_in_base" in detail
    both = payload(
        with_imu, position_base_in_world=np.asarray(full.position_base_in_world).tobytes()
    )
    detail = assert_error(ask(server, both), ErrorCode.INVALID_FIELD, "position_base_in_world")
    assert "both `imu` and position_base_in_world" in detail
    assert isinstance(ask(server, with_imu), Command)  # the session goes on


@pytest.mark.parametrize(
    ("fields", "words"),
    [
        ({"imu_frame": "pelvsi"}, ["no frame 'pelvsi'", "did you mean 'pelvis'?"]),
        ({"imu_frame": "left_foot"}, ["moves relative to the root body", "mount the IMU"]),
    ],
)
def test_an_imu_frame_unknown_or_off_the_root_body_is_refused_at_hello(server, fields, words):
    reply = ask(server, Hello(seq=3, model="thesis_humanoid", **fields))
    detail = assert_error(reply, ErrorCode.INVALID_FIELD, "imu_frame")
    for word in words:
        assert word in detail
    hello(server, imu_frame="pelvis", imu_position_in_frame=(0.0, 0.0, 0.1))  # then it works


def test_a_bad_imu_mount_in_hello_is_invalid():
    with pytest.raises(ValueError, match="unit quaternion"):
        Hello(model="thesis_humanoid", imu_orientation_in_frame_xyzw=(0.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="within 10 m"):
        Hello(model="thesis_humanoid", imu_position_in_frame=(0.0, 0.0, 11.0))


def test_nan_readings_time_and_stance_errors_are_typed_and_the_session_continues(server):
    welcome = hello(server)
    state = imu_state(welcome, 0.0)
    nan = np.array([0.0, np.nan, 0.0]).tobytes()
    inf = np.array([0.0, 0.0, np.inf]).tobytes()
    imu = msgpack.unpackb(encode(state))["imu"]
    for key, raw, code in (
        ("angular_velocity_imu_in_imu", nan, ErrorCode.NON_FINITE),
        ("linear_acceleration_imu_in_imu", inf, ErrorCode.NON_FINITE),
        (
            "linear_acceleration_imu_in_imu",
            np.array([0, 0, 2e4]).tobytes(),
            ErrorCode.INVALID_FIELD,
        ),
        ("orientation_imu_in_world_xyzw", np.zeros(4).tobytes(), ErrorCode.INVALID_FIELD),
    ):
        reply = ask(server, payload(state, imu={**imu, key: raw}))
        assert_error(reply, code, f"imu.{key}")
    # No stance foot at the start: nothing to place the base on.
    assert_error(
        ask(server, imu_state(welcome, 0.0, flags=[False, False])),
        ErrorCode.INVALID_FIELD,
        "contact_flags",
    )
    assert isinstance(ask(server, state), Command)
    # Time must advance between IMU states.
    assert_error(ask(server, imu_state(welcome, 0.0)), ErrorCode.INVALID_FIELD, "time_s")
    assert isinstance(ask(server, imu_state(welcome, 0.001)), Command)
    # A gap cannot be integrated: an error, and the estimator starts afresh at the next state.
    detail = assert_error(ask(server, imu_state(welcome, 0.5)), ErrorCode.INVALID_FIELD, "time_s")
    assert "restarts" in detail
    command = ask(server, imu_state(welcome, 0.501))
    assert isinstance(command, Command)
    assert command.diagnostics.base_estimate.position_base_in_world[2] == pytest.approx(
        welcome.standing_position_base_in_world[2], abs=1e-3
    )
    # A state with the base given directly is still served, and carries no estimate.
    full = ask(server, standing(welcome).to_message(0.6, [True, True]))
    assert isinstance(full, Command) and full.diagnostics.base_estimate is None


def test_the_imu_orientation_starts_the_filter_and_a_turned_offset_mount_is_undone(server):
    """An IMU 10 cm up, turned 90° about z; its AHRS says 3° of roll: so does the estimate."""
    turn = pin.Quaternion(np.array([0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)]))  # IMU in pelvis
    welcome = hello(
        server,
        imu_frame="pelvis",
        imu_position_in_frame=(0.0, 0.0, 0.1),
        imu_orientation_in_frame_xyzw=tuple(turn.coeffs()),
    )
    roll = pin.exp3(np.array([np.radians(3.0), 0.0, 0.0]))  # R_WB the AHRS reports
    rotation_imu = roll @ turn.toRotationMatrix()  # R_WI = R_WB R_BI
    message = imu_state(welcome, 0.0).model_copy(
        update={
            "imu": ImuSample(
                angular_velocity_imu_in_imu=np.zeros(3),
                linear_acceleration_imu_in_imu=rotation_imu.T @ GRAVITY_UP,
                orientation_imu_in_world_xyzw=pin.Quaternion(rotation_imu).coeffs(),
            )
        }
    )
    command = ask(server, message)
    assert isinstance(command, Command), command
    estimate = command.diagnostics.base_estimate
    rotation = pin.Quaternion(estimate.orientation_base_in_world_xyzw).toRotationMatrix()
    np.testing.assert_allclose(rotation, roll, atol=1e-9)
