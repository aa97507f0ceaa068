"""What a format's reader makes of a robot, for ``describe`` to finish.

A :class:`Body` (frame, parent, collision points), a :class:`FoundContact` (a frame and its
sole's corners), and the :class:`Draft` each reader returns, with the URDF collision meshes
it could not read (:class:`UnreadableMesh`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

__all__ = [
    "Body",
    "Draft",
    "FoundContact",
    "UnreadableMesh",
]


@dataclass(frozen=True)
class FoundContact:
    """A support: a frame of the model and the corners of its sole in that frame (m).

    Attributes:
        name: Contact name on the wire, e.g. ``left_foot``.
        frame: The frame the points are in (a body's or a site's).
        points_in_frame: ``(k, 3)`` sole corners in the frame (m).
        friction_coefficient: Coulomb μ.
        reason: Why this contact, for a person (``poise inspect``).
    """

    name: str
    frame: str
    points_in_frame: np.ndarray
    friction_coefficient: float = 0.8
    reason: str = ""


@dataclass(frozen=True)
class Body:
    """A rigid body of the robot: its Pinocchio frame, parent body and collision points.

    Attributes:
        name: Body (MJCF) or link (URDF) name; its Pinocchio frame's name.
        parent: Index of the parent body in :attr:`RobotDescription.bodies` (−1: the root).
        frame_id: Pinocchio frame of the body.
        collision_points: ``(k, 3)`` points of its collision geometry in the
            body frame (m): box and mesh vertices, cylinder rims, ellipsoid
            extremes along their axes, and the centres of spheres and of
            capsules' end spheres.
        collision_radii: ``(k,)`` radius around each point (m): a sphere's or
            capsule's radius, 0 for a vertex. The lowest point of a round
            shape is its centre less its radius along the world's z.
    """

    name: str
    parent: int
    frame_id: int
    collision_points: np.ndarray
    collision_radii: np.ndarray

    @classmethod
    def with_shapes(cls, name: str, parent: int, frame_id: int, shapes: list[np.ndarray]) -> Body:
        """A body whose collision geometry is ``(k, 4)`` blocks of points and radii."""
        stacked = np.vstack(shapes) if shapes else np.zeros((0, 4))
        return cls(name, parent, frame_id, stacked[:, :3], stacked[:, 3])


@dataclass
class Draft:
    """What a format's reader gives :func:`describe` to finish."""

    model: pin.Model
    bodies: list[Body]
    torque_limit: np.ndarray
    actuator_kind: dict[str, str]
    ball_swing_limit: dict[str, float]
    configuration: np.ndarray
    keyframes: dict[str, np.ndarray]
    sole_sites: list[FoundContact]
    warnings: list[str]
    unreadable_meshes: list[UnreadableMesh] = field(default_factory=list)
    disabled_collision_pairs: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class UnreadableMesh:
    """A URDF collision mesh left out: its link, ``filename`` as written, and why."""

    link: str
    filename: str
    reason: str
