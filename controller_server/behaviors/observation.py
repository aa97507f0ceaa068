"""What a behaviour sees of one control tick."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Observation"]


@dataclass(frozen=True)
class Observation:
    """What a behaviour sees of one tick.

    Attributes:
        time_s: Client time (s).
        position_com_in_world: CM (m).
        velocity_com_in_world: CM velocity (m/s).
        touching: Per contact, its flag from the client.
        position_contact_frames_in_world: ``(contacts, 3)`` contact frame origins (m).
        orientation_contact_frames_in_world: ``(contacts, 3, 3)`` their rotations.
        joint_position: Joint positions, wire order (ball joints: xyzw).
        orientation_base_in_world_xyzw: Root orientation, scalar last.
        ground_height: Ground plane height (m).
    """

    time_s: float
    position_com_in_world: np.ndarray
    velocity_com_in_world: np.ndarray
    touching: tuple[bool, ...]
    position_contact_frames_in_world: np.ndarray
    orientation_contact_frames_in_world: np.ndarray
    joint_position: np.ndarray
    orientation_base_in_world_xyzw: np.ndarray
    ground_height: float
