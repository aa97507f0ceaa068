"""Which of a robot's joints are its knees, hips, ankles, arms and spine, from its model.

The walk bends the knees of its rest pose (de Lasa §6.1's walking height) and may relax the
arms (E_arms, §6.2); the twisting jump turns the spine in flight (§5). They find those
joints by name (``knee``, ``hip``, ``ankle``, ``shoulder``, ``elbow``) and the spine by the
tree's shape, so that the same parameters run on any biped.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

__all__ = ["ARM_WORDS", "arm_dofs", "knee_bend_direction", "spine_joints"]

ARM_WORDS = ("shoulder", "elbow")
"""Joint names with one of these words are an arm's."""


def knee_bend_direction(model: pin.Model) -> np.ndarray:
    """Per joint DoF: +1 on a knee's pitch (local y), −½ on a hip's or an ankle's, else 0."""
    direction = np.zeros(model.nv - 6)
    for joint_id in range(2, model.njoints):
        name, joint = model.names[joint_id], model.joints[joint_id]
        start = joint.idx_v - 6
        scale = 1.0 if "knee" in name else -0.5 if ("hip" in name or "ankle" in name) else 0.0
        kind = joint.shortname()
        if scale and kind == "JointModelSpherical":
            direction[start + 1] = scale
        elif scale and kind == "JointModelRY":
            direction[start] = scale
    return direction


def arm_dofs(model: pin.Model) -> np.ndarray:
    """Per joint DoF, whether it belongs to a shoulder or an elbow (E_arms of §6.2)."""
    arms = np.zeros(model.nv - 6, dtype=bool)
    for joint_id in range(2, model.njoints):
        joint = model.joints[joint_id]
        if any(word in model.names[joint_id] for word in ARM_WORDS):
            start = joint.idx_v - 6
            arms[start : start + joint.nv] = True
    return arms


def spine_joints(model: pin.Model) -> list[int]:
    """Wire indices (of their xyzw) of the spine: the ball joints, root excluded, that branch.

    A joint branches when two or more end joints (leaves) hang from it: on the thesis
    humanoid ``lower_back`` and ``upper_back`` (each carries the neck and both arms); a
    leg or an arm holds one end joint only.
    """
    parents = list(model.parents)
    leaves_below = [0] * model.njoints
    for leaf in set(range(1, model.njoints)) - set(parents):
        joint = leaf
        while joint > 0:  # Pinocchio numbers a parent before its children
            leaves_below[joint] += 1
            joint = parents[joint]
    return [
        model.joints[j].idx_q - 7
        for j in range(2, model.njoints)
        if model.joints[j].nq == 4 and model.joints[j].nv == 3 and leaves_below[j] >= 2
    ]
