"""Random robot states near standing, for fuzzing, tests and benchmarks."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from clients.layout import joint_slices, neutral_joint_position
from protocol.messages import State, Welcome

__all__ = ["random_state"]


def random_state(
    welcome: Welcome,
    rng: np.random.Generator,
    spread: float = 0.1,
    wrenches: bool = False,
) -> State:
    """A state near standing: random pose, velocities, tilt and contact flags.

    Args:
        welcome: The session's handshake reply (joints, contacts, standing height).
        rng: Random generator (seed it for reproducible runs).
        spread: Scale of the joint angles (rad); velocities are 3× that (rad/s).
        wrenches: Also send random measured contact wrenches.
    """
    joints = list(welcome.joints)
    position = neutral_joint_position(joints)
    for joint, (q_slice, _) in zip(joints, joint_slices(joints).values(), strict=True):
        if joint.kind == "ball":
            position[q_slice] = Rotation.from_rotvec(rng.normal(0, spread, 3)).as_quat()
        else:
            lower = joint.position_lower[0] if joint.position_lower else -np.inf
            upper = joint.position_upper[0] if joint.position_upper else np.inf
            position[q_slice] = np.clip(rng.normal(0, spread), lower, upper)
    nv = sum(j.nv for j in joints)
    flags = [bool(f) for f in rng.random(len(welcome.contacts)) < 0.8]
    return State(
        time_s=float(rng.random()),
        joint_position=position,
        joint_velocity=rng.normal(0, 3 * spread, nv),
        position_base_in_world=np.array(welcome.standing_position_base_in_world)
        + rng.normal(0, 0.01, 3),
        orientation_base_in_world_xyzw=Rotation.from_rotvec(rng.normal(0, spread / 2, 3)).as_quat(),
        linear_velocity_base_in_world=rng.normal(0, spread, 3),
        angular_velocity_base_in_base=rng.normal(0, spread, 3),
        contact_flags=flags,
        contact_wrench_in_world=(
            np.concatenate(
                [
                    [*rng.normal(0, 20, 2), rng.uniform(0, 400), *rng.normal(0, 5, 3)]
                    for _ in welcome.contacts
                ]
            )
            if wrenches
            else None
        ),
    )
