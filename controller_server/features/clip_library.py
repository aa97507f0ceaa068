"""Keyframed motion clips for the thesis' tracking tests (Macchietto 2008, ch. 7.2–7.3).

The thesis tracked motion capture and keyframed motion: double-support
squats and toe-touches, single-support leg swings and kicks, and a
single-support leg circle on ice (thesis: a front kick and a side kick; here
one ``kicks`` clip plays both). These clips are keyframed for
``thesis_humanoid``, whose joint frames are aligned with the world in the
neutral pose (x forward, y left, z up), so a rotation vector ``(x, y, z)``
per ball joint reads directly: ``−y`` at a hip swings the thigh forward,
``+y`` at a knee bends it, ``+x`` at the left hip lifts the leg sideways.

Between keyframes every joint's rotation vector is eased with
``s = (1 − cos πu) / 2``, so velocities are zero at each keyframe and the
clips start and end at rest in the neutral pose. One-leg clips first lean
both legs so the CM is over the right foot, move the left leg, and lean
back; a scenario takes the left foot out of the supports (``support_mask``)
while it is up.

``python -m controller_server.features.clip_library`` writes every clip to
``controller_server/clips/``; a test checks the committed files match.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin

from controller_server.features.motion_clip import CLIPS_DIR, MotionClip, make_sway_clip
from controller_server.models import RobotModel, load_robot_model

__all__ = ["CLIP_KEYFRAMES", "Keyframe", "build_clip", "keyframe_clip", "write_clips"]

Keyframe = tuple[float, Mapping[str, tuple[float, float, float]]]
"""``(time_s, {joint: rotation vector (rad) in the parent frame})``; absent joints neutral."""

RATE_HZ = 50.0
"""Frame rate of the written clips."""


def _legs(hip: float, knee: float, ankle: float) -> dict[str, tuple[float, float, float]]:
    """Both legs flexed in the sagittal plane (pitch about y)."""
    return {
        f"{side}_{joint}": (0.0, angle, 0.0)
        for side in ("left", "right")
        for joint, angle in (("hip", hip), ("knee", knee), ("ankle", ankle))
    }


def _arms(shoulder: float, elbow: float = 0.0) -> dict[str, tuple[float, float, float]]:
    """Both arms raised forward (``shoulder < 0``) and the elbows bent."""
    return {
        f"{side}_{joint}": (0.0, angle, 0.0)
        for side in ("left", "right")
        for joint, angle in (("shoulder", shoulder), ("elbow", elbow))
    }


WEIGHT_SHIFT_ROLL_RAD = 0.12
"""Both legs rolled so the pelvis (and the CM) moves 8.75 cm right, over the right foot."""


def _on_right_foot(
    motion: list[Keyframe], shift_s: float = 1.2, hold_s: float = 0.6
) -> list[Keyframe]:
    """Shift the weight onto the right foot, play ``motion`` (left leg), hold, shift back.

    The hold after the motion gives the left foot time to land before a
    scenario makes it a support again and the weight moves back.

    The roll ``r`` turns both hips by ``+r`` and both ankles by ``−r`` about x:
    the legs lean right (their tops move −y), the feet stay flat, the pelvis
    stays upright. ``motion``'s
    rotations are added to that stance; its first and last keyframes (neutral)
    become the shifted stance.
    """
    roll = WEIGHT_SHIFT_ROLL_RAD
    shifted = {
        "left_ankle": (-roll, 0.0, 0.0),
        "right_ankle": (-roll, 0.0, 0.0),
        "left_hip": (roll, 0.0, 0.0),
        "right_hip": (roll, 0.0, 0.0),
    }

    def on_stance(pose: Mapping[str, tuple[float, float, float]]) -> dict[str, tuple[float, ...]]:
        joints = set(shifted) | set(pose)
        zero = (0.0, 0.0, 0.0)
        return {
            j: tuple(a + b for a, b in zip(shifted.get(j, zero), pose.get(j, zero), strict=True))
            for j in joints
        }

    end_s = motion[-1][0]
    return [
        (0.0, {}),
        *((shift_s + time_s, on_stance(pose)) for time_s, pose in motion),
        (shift_s + end_s + hold_s, on_stance({})),
        (shift_s + end_s + hold_s + shift_s, {}),
    ]


def _leg_circle() -> list[Keyframe]:
    """The left foot lifts, draws a loop forward, out and back (3.6 s), knee soft; 4.8 s."""
    frames: list[Keyframe] = [(0.0, {}), (0.6, {"left_hip": (0.0, -0.1, 0.0)})]
    for k in range(1, 9):
        phase = 2.0 * math.pi * k / 8
        hip = (0.25 * (1.0 - math.cos(phase)), -0.1 - 0.3 * math.sin(phase), 0.0)
        frames.append((0.6 + 0.45 * k, {"left_hip": hip, "left_knee": (0.0, 0.15, 0.0)}))
    frames.append((4.8, {}))
    return frames


CLIP_KEYFRAMES: dict[str, list[Keyframe]] = {
    # Double support.
    "squat": [
        (0.0, {}),
        (1.5, {**_legs(-0.6, 1.2, -0.6), **_arms(-0.8)}),
        (2.0, {**_legs(-0.6, 1.2, -0.6), **_arms(-0.8)}),
        (3.5, {}),
    ],
    "toe_touch": [
        (0.0, {}),
        (
            1.5,
            {
                "lower_back": (0.0, 0.55, 0.0),
                "upper_back": (0.0, 0.5, 0.0),
                "neck": (0.0, 0.3, 0.0),
                **_arms(-0.9, 0.1),
            },
        ),
        (
            2.3,
            {
                "lower_back": (0.0, 0.55, 0.0),
                "upper_back": (0.0, 0.5, 0.0),
                "neck": (0.0, 0.3, 0.0),
                **_arms(-0.9, 0.1),
            },
        ),
        (4.0, {}),
    ],
    # Single support on the right foot: weight shift, the left leg moves, weight back.
    "leg_swing": _on_right_foot(
        [
            (0.0, {}),
            (0.8, {"left_hip": (0.0, -0.2, 0.0), "left_knee": (0.0, 0.4, 0.0)}),
            (1.6, {"left_hip": (0.0, -0.7, 0.0), "left_knee": (0.0, 0.1, 0.0)}),
            (2.5, {"left_hip": (0.0, 0.35, 0.0), "left_knee": (0.0, 0.2, 0.0)}),
            (3.4, {"left_hip": (0.0, -0.7, 0.0), "left_knee": (0.0, 0.1, 0.0)}),
            (4.2, {"left_hip": (0.0, -0.2, 0.0), "left_knee": (0.0, 0.4, 0.0)}),
            (5.0, {}),
        ]
    ),
    "kicks": _on_right_foot(
        [
            (0.0, {}),
            (0.8, {"left_hip": (0.0, -0.9, 0.0), "left_knee": (0.0, 1.3, 0.0)}),
            (1.2, {"left_hip": (0.0, -1.0, 0.0), "left_knee": (0.0, 0.1, 0.0)}),
            (1.7, {"left_hip": (0.0, -0.9, 0.0), "left_knee": (0.0, 1.3, 0.0)}),
            (2.5, {"left_hip": (0.0, -0.2, 0.0), "left_knee": (0.0, 0.4, 0.0)}),
            (3.3, {"left_hip": (0.3, -0.5, 0.0), "left_knee": (0.0, 1.2, 0.0)}),
            (3.8, {"left_hip": (0.75, 0.0, 0.0), "left_knee": (0.0, 0.1, 0.0)}),
            (4.3, {"left_hip": (0.3, -0.5, 0.0), "left_knee": (0.0, 1.2, 0.0)}),
            (5.1, {}),
        ]
    ),
    "leg_circle": _on_right_foot(_leg_circle(), shift_s=2.0),
}
"""Keyframes of every built-in clip (thesis_humanoid)."""


def _quaternion_xyzw(rotation_vector: Sequence[float]) -> np.ndarray:
    return pin.Quaternion(pin.exp3(np.asarray(rotation_vector, dtype=float))).coeffs()


def keyframe_clip(robot: RobotModel, keyframes: Sequence[Keyframe], name: str) -> MotionClip:
    """A clip through ``keyframes`` (ball joints only), eased between them, at 50 Hz.

    Raises:
        ValueError: Keyframe times not increasing from 0, or a joint that is not
            a ball joint of the robot.
    """
    times = [time_s for time_s, _ in keyframes]
    if times[0] != 0.0 or any(b <= a for a, b in itertools.pairwise(times)):
        raise ValueError(f"keyframe times must increase from 0: {times}")
    ball = {j.name for j in robot.joints if j.kind == "ball"}
    unknown = {joint for _, pose in keyframes for joint in pose} - ball
    if unknown:
        raise ValueError(f"not ball joints of {robot.name!r}: {sorted(unknown)}")
    starts = {
        joint: robot.model.idx_qs[robot.model.getJointId(joint)] - 7 for joint in sorted(ball)
    }
    neutral = pin.neutral(robot.model)[7:]
    poses = [
        {joint: np.asarray(pose.get(joint, (0.0, 0.0, 0.0)), dtype=float) for joint in starts}
        for _, pose in keyframes
    ]

    def joint_position(t: float) -> np.ndarray:
        segment = min(int(np.searchsorted(times, t, side="right")) - 1, len(times) - 2)
        u = (t - times[segment]) / (times[segment + 1] - times[segment])
        s = 0.5 - 0.5 * math.cos(math.pi * min(max(u, 0.0), 1.0))
        row = neutral.copy()
        for joint, start in starts.items():
            rotation = (1.0 - s) * poses[segment][joint] + s * poses[segment + 1][joint]
            row[start : start + 4] = _quaternion_xyzw(rotation)
        return row

    return MotionClip.from_function(robot, joint_position, times[-1], RATE_HZ, name=name)


def build_clip(name: str, robot: RobotModel | None = None) -> MotionClip:
    """The built-in clip ``name`` (``stand_sway`` or a key of :data:`CLIP_KEYFRAMES`)."""
    robot = robot or load_robot_model("thesis_humanoid")
    if name == "stand_sway":
        return make_sway_clip(robot)
    return keyframe_clip(robot, CLIP_KEYFRAMES[name], name)


def write_clips() -> list[str]:
    """Write every built-in clip to ``CLIPS_DIR``; return the file names."""
    robot = load_robot_model("thesis_humanoid")
    names = ["stand_sway", *CLIP_KEYFRAMES]
    for name in names:
        build_clip(name, robot).to_json(CLIPS_DIR / f"{name}.json")
    return [f"{name}.json" for name in names]


if __name__ == "__main__":
    print("\n".join(write_clips()))
