"""Joint layout helpers for clients: wire-order slices and the neutral pose.

Clients learn the robot from ``welcome``; these helpers turn its joint list
into index ranges of ``joint_position`` / ``joint_velocity`` without any
rigid-body library.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from protocol.messages import JointInfo

__all__ = ["JointIndices", "joint_slices", "neutral_joint_position"]


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


@dataclass(frozen=True)
class JointIndices:
    """Where each kind of joint sits in ``joint_position`` and ``joint_velocity``.

    Attributes:
        ball_position: ``(b, 4)`` quaternion (xyzw) entries of each ball joint.
        ball_velocity: ``(b, 3)`` angular-rate entries of each ball joint.
        scalar_position: Entries of the 1-DoF joints in ``joint_position``.
        scalar_velocity: Their entries in ``joint_velocity`` (same order).
    """

    ball_position: np.ndarray
    ball_velocity: np.ndarray
    scalar_position: np.ndarray
    scalar_velocity: np.ndarray

    @classmethod
    def of(cls, joints: Sequence[JointInfo]) -> JointIndices:
        """The indices of ``welcome.joints``."""
        slices = joint_slices(joints)
        ball = [slices[j.name] for j in joints if j.kind == "ball"]
        scalar = [slices[j.name] for j in joints if j.kind != "ball"]
        return cls(
            np.array([np.arange(q.start, q.stop) for q, _ in ball], dtype=int).reshape(-1, 4),
            np.array([np.arange(v.start, v.stop) for _, v in ball], dtype=int).reshape(-1, 3),
            np.array([q.start for q, _ in scalar], dtype=int),
            np.array([v.start for _, v in scalar], dtype=int),
        )
