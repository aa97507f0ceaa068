"""Collision geometry as points and radii: MuJoCo's primitives and meshes, placed in frames.

Both readers use it: the MJCF's geoms and a URDF's ``<collision>`` shapes become the
``(k, 4)`` points and radii of a :class:`~controller_server.models.description.bodies.Body`.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin

__all__ = [
    "GEOM",
    "mesh_vertices",
    "placed",
    "se3",
    "shape_points",
    "to_world",
]

GEOM = mujoco.mjtGeom


def se3(position: np.ndarray, quaternion_wxyz: np.ndarray) -> pin.SE3:
    """A placement from a position and a MuJoCo quaternion (w, x, y, z)."""
    w, x, y, z = quaternion_wxyz
    return pin.SE3(pin.Quaternion(w, x, y, z).normalized().matrix(), np.array(position, float))


def placed(shape: np.ndarray, placement: pin.SE3) -> np.ndarray:
    """``(k, 4)`` points and radii in a shape's frame → in the frame it is placed in."""
    return np.column_stack([to_world(placement, shape[:, :3]), shape[:, 3]])


def mesh_vertices(mj: mujoco.MjModel, geom: int) -> np.ndarray | None:
    """A mesh geom's vertices in the geom's frame (``None``: not a mesh geom)."""
    mesh = int(mj.geom_dataid[geom])
    if mj.geom_type[geom] != GEOM.mjGEOM_MESH or mesh < 0:
        return None
    start, count = int(mj.mesh_vertadr[mesh]), int(mj.mesh_vertnum[mesh])
    return np.array(mj.mesh_vert[start : start + count], float)


def shape_points(kind: int, size: np.ndarray, vertices: np.ndarray | None) -> np.ndarray | None:
    """A primitive as ``(k, 4)`` points and radii in its frame (``None``: a plane, a height field).

    Boxes and meshes: their vertices; cylinders: 16 points on each rim;
    ellipsoids: their extremes along their axes; spheres: the centre with the
    radius; capsules: both end spheres.
    """
    rim = np.array(
        [(np.cos(a), np.sin(a), 0.0) for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)]
    )
    if kind == GEOM.mjGEOM_BOX:
        signs = np.array([(sx, sy, sz) for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)])
        points = signs * size
    elif kind == GEOM.mjGEOM_ELLIPSOID:
        points = np.vstack([np.eye(3), -np.eye(3)]) * size[:3]
    elif kind == GEOM.mjGEOM_CYLINDER:
        points = np.vstack([rim * size[0] + (0, 0, h) for h in (size[1], -size[1])])
    elif kind == GEOM.mjGEOM_MESH and vertices is not None:
        points = vertices
    elif kind == GEOM.mjGEOM_SPHERE:
        return np.array([[0.0, 0.0, 0.0, size[0]]])
    elif kind == GEOM.mjGEOM_CAPSULE:
        return np.array([[0.0, 0.0, size[1], size[0]], [0.0, 0.0, -size[1], size[0]]])
    else:
        return None
    return np.column_stack([points, np.zeros(len(points))])


def to_world(placement: pin.SE3, points: np.ndarray) -> np.ndarray:
    """``(k, 3)`` points in a frame → in the world, given the frame's placement."""
    return points @ placement.rotation.T + placement.translation
