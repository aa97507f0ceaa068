"""The robot of a track posed in MuJoCo: what the video and the live view draw.

The MuJoCo model is the simulator's own (:class:`~clients.physics.mujoco_backend.MujocoBackend`:
the same file, floor and joint order), so a run of either backend, or a
recorded log, is drawn by setting each state (wire conventions; the
quaternion reordered to MuJoCo's ``w x y z`` by the backend) and running
MuJoCo's forward kinematics. Nothing is integrated.
"""

from __future__ import annotations

import mujoco
import numpy as np

from clients.physics.mujoco_backend import MujocoBackend
from clients.state import RobotState
from clients.track import Track

__all__ = ["RobotScene"]


class RobotScene:
    """``scene.pose(state)``, then read :attr:`model` and :attr:`data` (world frame, m).

    Args:
        track: The run whose robot this is (model, keyframe, joint and contact order).

    Raises:
        UnsupportedModel: MuJoCo cannot load the track's model.
    """

    def __init__(self, track: Track):
        self._backend = MujocoBackend(
            track.model,
            joint_names=[joint.name for joint in track.welcome.joints],
            contacts=list(track.welcome.contacts),
            keyframe=track.keyframe,
        )

    @property
    def model(self) -> mujoco.MjModel:
        """The MuJoCo model (robot and floor)."""
        return self._backend.model

    @property
    def data(self) -> mujoco.MjData:
        """The MuJoCo data of the last :meth:`pose`."""
        return self._backend.data

    def pose(self, state: RobotState) -> None:
        """Put the robot in ``state`` (forward kinematics only)."""
        self._backend.reset(state)

    def point_in_world(self, body: str, point_in_body_m: tuple[float, float, float]) -> np.ndarray:
        """Where a point fixed in ``body`` (its frame, m) is in the world now (m).

        Raises:
            KeyError: The model has no such body (the message lists them).
        """
        return self._backend.body_point_in_world(body, point_in_body_m)

    def body_names(self) -> list[str]:
        """Names of the model's bodies, the world first (``""`` for unnamed ones)."""
        return [self.model.body(index).name for index in range(self.model.nbody)]
