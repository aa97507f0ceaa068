"""Conversions between wire conventions and Pinocchio's, at the session edge.

Wire (docs/architecture.md): base pose in world, quaternions scalar-last,
``linear_velocity_base_in_world``, ``angular_velocity_base_in_base``.
Pinocchio's free flyer: ``q = [p, quat_xyzw, q_joints]`` and
``v = [v_base_in_base, ω_base_in_base, v_joints]``. Accelerations go back as
the classical acceleration of the base origin in world axes and the angular
acceleration in base axes: ``a_world = R (v̇_local + ω × v_local)``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin

from controller_server.controllers import ControlInput, ControlOutput
from controller_server.estimation import BaseEstimate
from controller_server.math.spatial import cross
from controller_server.models import RobotModel
from protocol.errors import ErrorCode, ProtocolError
from protocol.fastpath import construct
from protocol.messages import (
    BASE_POSE_FIELDS,
    BaseEstimateDiagnostics,
    Command,
    Diagnostics,
    PrioritizedDiagnostics,
    PriorityLevelReport,
    State,
    WeightedDiagnostics,
)

__all__ = [
    "BaseFields",
    "EstimateBase",
    "base_estimate_diagnostics",
    "check_base_form",
    "command_from_output",
    "control_input_from_state",
]

EstimateBase = Callable[[State], BaseEstimate]
"""The session's estimate of the base from a state's ``imu`` block (its joints checked)."""

QUATERNION_NORM_TOLERANCE = 0.1
"""A wire quaternion's norm must lie within 1 ± this; the server normalises it.

Rounding and float32 sensors are off by 1e-7; a quaternion 10 % off unit
length is a client bug (it once turned into a rotation with determinant 1.5e5),
refused with the field named rather than silently rescaled.
"""


def _check_length(field: str, array: np.ndarray, expected: int, seq: int) -> None:
    if array.size != expected:
        raise ProtocolError(
            ErrorCode.BAD_SHAPE,
            field,
            f"expected {expected} values for this robot, got {array.size}",
            seq,
        )


def _check_quaternion(field: str, quaternion: np.ndarray, seq: int) -> None:
    norm = float(np.linalg.norm(quaternion))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise ProtocolError(
            ErrorCode.INVALID_FIELD,
            field,
            f"quaternion has norm {norm:.3g}; send a unit quaternion xyzw "
            f"(within {QUATERNION_NORM_TOLERANCE:g}, the server normalises)",
            seq,
        )


BaseFields = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""Position, orientation (xyzw), linear velocity (world) and angular velocity (base)."""


def check_base_form(state: State) -> BaseFields | None:
    """The state gives the base one way: all of :data:`BASE_POSE_FIELDS`, or ``imu``.

    Returns:
        The four base fields, or ``None`` for a state that gives ``imu``.

    Raises:
        ProtocolError: ``INVALID_FIELD`` naming the fields: both forms, or neither
            (some base fields and no ``imu`` counts as neither, naming the missing ones).
    """
    fields = [getattr(state, name) for name in BASE_POSE_FIELDS]
    given = [
        name for name, field in zip(BASE_POSE_FIELDS, fields, strict=True) if field is not None
    ]
    if state.imu is not None:
        if given:
            raise ProtocolError(
                ErrorCode.INVALID_FIELD,
                given[0],
                f"the state carries both `imu` and {', '.join(given)}: give the base either "
                "as the four base fields or as `imu`, not both",
                state.seq,
            )
        return None
    missing = [name for name in BASE_POSE_FIELDS if name not in given]
    if missing:
        raise ProtocolError(
            ErrorCode.INVALID_FIELD,
            missing[0],
            f"the state lacks {', '.join(missing)}: give the base either as "
            f"{', '.join(BASE_POSE_FIELDS)} or as `imu` (an IMU reading, estimated by the server)",
            state.seq,
        )
    position, orientation, linear_velocity, angular_velocity = fields
    return position, orientation, linear_velocity, angular_velocity


def control_input_from_state(
    robot: RobotModel,
    state: State,
    want_diagnostics: bool = True,
    estimate_base: EstimateBase | None = None,
) -> tuple[ControlInput, BaseEstimate | None]:
    """Validate a state's sizes against the robot and convert it.

    Args:
        robot: The session's robot.
        state: The decoded state.
        want_diagnostics: Whether the controller should compute diagnostics this tick.
        estimate_base: For a state with ``imu``: the session's estimator, called once the
            joints and contacts are checked.

    Returns:
        The controller's input, and the base estimate when the state carried ``imu``.

    Raises:
        ProtocolError: ``BAD_SHAPE`` (wrong lengths) or ``INVALID_FIELD``
            (a quaternion not of unit length within
            :data:`QUATERNION_NORM_TOLERANCE`, the base given both ways or neither,
            ``imu`` without an estimator), naming the field.
        EstimatorInputError: From ``estimate_base``.
    """
    seq = state.seq
    base = check_base_form(state)
    _check_length("joint_position", state.joint_position, robot.nq_joints, seq)
    _check_length("joint_velocity", state.joint_velocity, robot.nv_joints, seq)
    if len(state.contact_flags) != len(robot.contacts):
        raise ProtocolError(
            ErrorCode.BAD_SHAPE,
            "contact_flags",
            f"expected {len(robot.contacts)} flags ({', '.join(c.name for c in robot.contacts)}), "
            f"got {len(state.contact_flags)}",
            seq,
        )
    wrenches = state.contact_wrench_in_world
    if wrenches is not None:
        _check_length("contact_wrench_in_world", wrenches, 6 * len(robot.contacts), seq)
        wrenches = wrenches.reshape(-1, 6)
    starts = robot.ball_quaternion_starts
    if starts.size:
        quaternions = state.joint_position[robot.ball_quaternion_index].reshape(-1, 4)
        squared_norms = np.einsum("ij,ij->i", quaternions, quaternions)
        worst = int(np.argmax(np.abs(squared_norms - 1.0)))
        _check_quaternion("joint_position", quaternions[worst], seq)
    estimate = None
    if base is None:
        assert state.imu is not None  # check_base_form: the other form
        if state.imu.orientation_imu_in_world_xyzw is not None:
            _check_quaternion(
                "imu.orientation_imu_in_world_xyzw", state.imu.orientation_imu_in_world_xyzw, seq
            )
        if estimate_base is None:
            raise ProtocolError(
                ErrorCode.INVALID_FIELD, "imu", "no base estimator here: send the base pose", seq
            )
        estimate = estimate_base(state)
        position, orientation = (
            estimate.position_base_in_world,
            estimate.orientation_base_in_world_xyzw,
        )
        linear_velocity = estimate.linear_velocity_base_in_world
        angular_velocity = estimate.angular_velocity_base_in_base
    else:
        position, orientation, linear_velocity, angular_velocity = base
        _check_quaternion("orientation_base_in_world_xyzw", orientation, seq)

    q = np.concatenate([position, orientation, state.joint_position])
    q = pin.normalize(robot.model, q)  # returns the normalised copy
    rotation_base_to_world = pin.Quaternion(q[3:7]).toRotationMatrix()
    v = np.concatenate(
        [rotation_base_to_world.T @ linear_velocity, angular_velocity, state.joint_velocity]
    )
    control_input = ControlInput(
        state.time_s, q, v, tuple(state.contact_flags), wrenches, want_diagnostics
    )
    return control_input, estimate


def base_estimate_diagnostics(estimate: BaseEstimate) -> BaseEstimateDiagnostics:
    """The ``base_estimate`` section of the diagnostics."""
    return construct(
        BaseEstimateDiagnostics,
        position_base_in_world=estimate.position_base_in_world,
        orientation_base_in_world_xyzw=estimate.orientation_base_in_world_xyzw,
        linear_velocity_base_in_world=estimate.linear_velocity_base_in_world,
        angular_velocity_base_in_base=estimate.angular_velocity_base_in_base,
        gyro_bias_in_imu=estimate.gyro_bias_in_imu,
        accel_bias_in_imu=estimate.accel_bias_in_imu,
        covariance=estimate.covariance.reshape(-1),
        stance_contacts=list(estimate.position_contacts_in_world),
    )


def command_from_output(
    control_input: ControlInput,
    output: ControlOutput,
    seq: int,
    compute_time_s: float,
    estimate: BaseEstimate | None = None,
) -> Command:
    """Build the ``command`` reply for one tick.

    The server's own arrays are not re-validated field by field (pydantic
    costs about 0.1 ms per tick here; the client validates what it decodes),
    but every array an actuator could act on is checked for NaN/inf first;
    the messages are built as ``model_construct`` builds them
    (:func:`protocol.fastpath.construct`).

    Raises:
        ProtocolError: ``INTERNAL``, naming the field, if the controller
            produced a non-finite value; nothing is sent to the client.
    """
    q, v, a = control_input.q, control_input.v, output.acceleration
    rotation_base_to_world = pin.Quaternion(q[3:7]).toRotationMatrix()
    linear_acceleration_in_world = rotation_base_to_world @ (a[:3] + cross(v[3:6], v[:3]))
    arrays = {
        "joint_acceleration": a[6:],
        "base_linear_acceleration_in_world": linear_acceleration_in_world,
        "base_angular_acceleration_in_base": a[3:6],
        "joint_torque": output.joint_torque,
        "contact_force_in_world": output.contact_force_in_world.reshape(-1),
        "contact_wrench_in_world": output.contact_wrench_in_world.reshape(-1),
    }
    if not np.isfinite(np.concatenate(list(arrays.values()))).all():
        field = next(key for key, array in arrays.items() if not np.isfinite(array).all())
        raise ProtocolError(
            ErrorCode.INTERNAL, field, "the controller produced NaN/inf; not sent", seq
        )
    # Fresh arrays of this tick (views of the controller's output), encoded at once.
    values = output.diagnostics
    if values is None:
        return construct(Command, seq=seq, diagnostics=None, **arrays)
    values = dict(values)
    if values.get("weighted") is not None:
        values["weighted"] = construct(WeightedDiagnostics, **values["weighted"])
    if values.get("prioritized") is not None:
        section = values["prioritized"]
        levels = [construct(PriorityLevelReport, **level) for level in section["priority_levels"]]
        values["prioritized"] = construct(
            PrioritizedDiagnostics, **{**section, "priority_levels": levels}
        )
    if estimate is not None:
        values["base_estimate"] = base_estimate_diagnostics(estimate)
    diagnostics = construct(Diagnostics, compute_time_s=compute_time_s, **values)
    return construct(Command, seq=seq, diagnostics=diagnostics, **arrays)
