"""Joint layout helpers for clients: wire-order slices and the neutral pose.

Clients learn the robot from ``welcome``; these helpers turn its joint list
into index ranges of ``joint_position`` / ``joint_velocity`` without any
rigid-body library.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from protocol.messages import JointInfo

__all__ = ["joint_slices", "neutral_joint_position"]


def joint_slices(joints: Sequence[JointInfo]) -> dict[str, tuple[slice, slice]]:
    """``name → (slice in joint_position, slice in joint_velocity)``."""
    slices, iq, iv = {}, 0, 0
    for joint in joints:
        slices[joint.name] = (slice(iq, iq + joint.nq), slice(iv, iv + joint.nv))
        iq += joint.nq
        iv += joint.nv
    return slices


def neutral_joint_position(joints: Sequence[JointInfo]) -> np.ndarray:
    """Zero angles, identity quaternions ``[0, 0, 0, 1]`` for ball joints."""
    parts = [np.array([0.0, 0.0, 0.0, 1.0]) if j.kind == "ball" else np.zeros(j.nq) for j in joints]
    return np.concatenate(parts) if parts else np.zeros(0)
