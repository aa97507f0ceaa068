"""What a client reads off a robot's state: its standing state, whether it fell, its supports.

Shared by the simulator's runner and the bridge's emulated plant.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from clients.layout import joint_slices
from clients.physics.errors import ScenarioError
from clients.state import RobotState
from protocol.errors import did_you_mean
from protocol.messages import Welcome

__all__ = ["FALL_TILT_RAD", "fall_reason", "standing_state", "support_flags"]

FALL_TILT_RAD = np.radians(60.0)
"""Base tilt from upright beyond which the robot has fallen."""
FALL_HEIGHT_FRACTION = 0.5
"""Base height below this fraction of the standing height means fallen."""


def standing_state(
    welcome: Welcome,
    joint_overrides: dict[str, list[float]],
    model: pin.Model | None = None,
    model_label: str | None = None,
) -> RobotState:
    """The server's standing pose (with joint overrides), at rest.

    With overrides and the robot's ``model`` (wire joint order), the base is
    raised or lowered so the lowest contact point of ``welcome.contacts``
    touches z = 0 again, as in the standing pose. ``model_label`` names the
    robot in errors (the user's file; default: the server's name for it).

    Raises:
        ScenarioError: An override names a joint the robot lacks (the message
            suggests the closest and lists them all) or has the wrong length.
    """
    joints = list(welcome.joints)
    position = RobotState.standing(welcome).joint_position.copy()
    slices = joint_slices(joints)
    for name, value in joint_overrides.items():
        if name not in slices:
            hint = did_you_mean(name, slices)
            raise ScenarioError(
                f"initial_joint_position: {model_label or welcome.model_name} has no joint "
                f"{name!r}; {hint}joints: {', '.join(slices)}"
            )
        joint = next(j for j in joints if j.name == name)
        if len(value) != joint.nq:
            example = "[x, y, z, w] (a quaternion)" if joint.kind == "ball" else "[0.3]"
            raise ScenarioError(
                f"initial_joint_position.{name} = {value}: a {joint.kind} joint takes "
                f"{joint.nq} number(s), e.g. {example}"
            )
        position[slices[name][0]] = value
    state = RobotState.standing(welcome, position)
    if joint_overrides and model is not None:
        q = np.concatenate(
            [state.position_base_in_world, state.orientation_base_in_world_xyzw, position]
        )
        data = model.createData()
        pin.framesForwardKinematics(model, data, pin.normalize(model, q))
        state.position_base_in_world[2] -= min(
            float(data.oMf[model.getFrameId(contact.frame)].act(np.array(point))[2])
            for contact in welcome.contacts
            for point in contact.points_in_frame or ()
        )
    return state


def fall_reason(state: RobotState, standing_height_m: float, non_foot_contact: bool) -> str:
    """Why the robot in ``state`` has fallen, or ``""`` if it has not."""
    if non_foot_contact:
        return "non-foot contact with the ground"
    if state.position_base_in_world[2] < FALL_HEIGHT_FRACTION * standing_height_m:
        return "base below half its standing height"
    # z of the base's up axis in world, from the unit quaternion [x, y, z, w].
    x, y = state.orientation_base_in_world_xyzw[:2]
    norm_squared = float(
        np.dot(state.orientation_base_in_world_xyzw, state.orientation_base_in_world_xyzw)
    )
    up_z = 1.0 - 2.0 * (x * x + y * y) / norm_squared
    if np.arccos(np.clip(up_z, -1.0, 1.0)) > FALL_TILT_RAD:
        return "base tilted past 60°"
    return ""


def support_flags(
    supporting: list[bool], touching: list[bool], normal_force_N: np.ndarray, threshold_N: float
) -> list[bool]:
    """Which feet the client reports as supports (``contact_flags``).

    A foot that merely touches is not yet a support: a foot set down lightly
    carries no load, and a controller that plans its share of the weight on
    it (and holds it still, eq. 5.1) lets the body drop onto it. So a touching
    foot becomes a support once its normal force exceeds ``threshold_N``, and
    stays one until it lifts off (hysteresis, like a force-sensor threshold on
    hardware).
    """
    return [
        bool(touch and (support or force > threshold_N))
        for support, touch, force in zip(supporting, touching, normal_force_N, strict=True)
    ]
