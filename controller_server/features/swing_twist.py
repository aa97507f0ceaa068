"""Swing–twist decomposition of ball-joint rotations and polygonal swing cones.

Macchietto 2008, §6.2: a ball joint's rotation ``q`` is split into a swing
``q_a`` that carries the rest bone axis ``a`` onto ``a' = q a q⁻¹`` along the
shortest arc, followed by a twist ``q_t`` about ``a`` (eq. 6.4)::

    q = q_a q_t

The swing is limited by a polygonal cone fixed to the parent link (Fig. 6.2),
the twist by an interval of angles. All quaternions are scalar-last
``[x, y, z, w]`` (Pinocchio, SciPy); inputs are normalised.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from controller_server.math.spatial import cross

__all__ = ["SwingCone", "compose", "cones_contain_units", "rotate", "swing_twist", "twist_angle"]

_TINY = 1e-12
_DEGENERATE_SWING = 1e-9
"""Below this ``‖(w, v·a)‖`` the rotation is a half turn about an axis ⊥ ``a``."""


def _unit(vector: np.ndarray, size: int, what: str) -> np.ndarray:
    """``vector`` as a float array of ``size`` entries, scaled to unit length."""
    array = np.asarray(vector, dtype=float)
    if array.shape != (size,):
        raise ValueError(f"{what} must have shape ({size},), got {array.shape}")
    norm = float(np.linalg.norm(array))
    if not math.isfinite(norm) or norm < _TINY:
        raise ValueError(f"{what} must be finite and non-zero, got {array!r}")
    return array / norm


def _perpendicular(axis: np.ndarray) -> np.ndarray:
    """A unit vector ⊥ the unit ``axis``, the same for the same axis."""
    helper = np.zeros(3)
    helper[int(np.argmin(np.abs(axis)))] = 1.0
    perpendicular = np.cross(axis, helper)
    return perpendicular / np.linalg.norm(perpendicular)


def _quaternion(vector: np.ndarray, scalar: float) -> np.ndarray:
    """``[x, y, z, w]`` from a vector part and a scalar part."""
    quaternion = np.empty(4)
    quaternion[:3] = vector
    quaternion[3] = scalar
    return quaternion


def compose(first_xyzw: np.ndarray, second_xyzw: np.ndarray) -> np.ndarray:
    """Hamilton product ``first ⊗ second``: rotate by ``second``, then by ``first``.

    Args:
        first_xyzw: Left quaternion ``[x, y, z, w]``.
        second_xyzw: Right quaternion ``[x, y, z, w]``.

    Returns:
        The product, not renormalised.
    """
    v1, w1 = np.asarray(first_xyzw, dtype=float)[:3], float(first_xyzw[3])
    v2, w2 = np.asarray(second_xyzw, dtype=float)[:3], float(second_xyzw[3])
    return _quaternion(w1 * v2 + w2 * v1 + cross(v1, v2), w1 * w2 - float(v1 @ v2))


def rotate(quaternion_xyzw: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """``q v q⁻¹``: ``vector`` rotated by the (normalised) quaternion."""
    q = _unit(quaternion_xyzw, 4, "quaternion_xyzw")
    v = np.asarray(vector, dtype=float)
    doubled_cross = 2.0 * cross(q[:3], v)
    return v + q[3] * doubled_cross + cross(q[:3], doubled_cross)


def swing_twist(quaternion_xyzw: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split a rotation into swing and twist, ``q = q_a q_t`` (Macchietto 2008, eq. 6.4).

    The thesis builds ``q_a`` from ``⟨a × a', acos(a · a')⟩`` and sets
    ``q_t = q_a⁻¹ q``. This computes the same pair by projecting ``q``'s vector
    part onto ``a`` (``q_t = (w, (v·a) a) / ‖·‖``, ``q_a = q q_t⁻¹``), which
    stays accurate when ``a'`` is close to ``a`` or ``−a``: the swing axis is
    ⊥ ``a`` and ``q_a a q_a⁻¹ = a'``, so ``q_a`` is the shortest arc.

    Degenerate cases: if ``a' = a`` the swing is the identity. If ``a' = −a``
    (``q`` is a half turn about an axis ⊥ ``a``) every perpendicular axis
    would do; the swing is then ``q`` itself and the twist the identity.
    ``q`` and ``−q`` give the same swing and opposite-signed twists.

    Args:
        quaternion_xyzw: Joint rotation ``q`` (child in parent), ``[x, y, z, w]``.
        axis: Rest bone axis ``a`` in the child frame (= parent frame at rest).

    Returns:
        ``(swing_xyzw, twist_xyzw)``, unit quaternions; the swing has ``w ≥ 0``.
    """
    q = _unit(quaternion_xyzw, 4, "quaternion_xyzw")
    a = _unit(axis, 3, "axis")
    along = float(q[:3] @ a)
    norm = math.hypot(along, q[3])
    if norm < _DEGENERATE_SWING:
        sign = 1.0 if q[3] >= 0.0 else -1.0
        return sign * q, np.array([0.0, 0.0, 0.0, sign])
    twist = _quaternion(along * a, q[3]) / norm
    swing = compose(q, _quaternion(-twist[:3], twist[3]))
    return swing / np.linalg.norm(swing), twist


def twist_angle(twist_xyzw: np.ndarray, axis: np.ndarray) -> float:
    """Angle (rad) of a twist about ``axis``, in ``(−π, π]``, right-handed about ``axis``.

    Only the twist's vector component along ``axis`` is used, so a quaternion
    that is not a pure twist gives the angle of its twist part's projection.
    """
    t = _unit(twist_xyzw, 4, "twist_xyzw")
    a = _unit(axis, 3, "axis")
    along, w = float(t[:3] @ a), float(t[3])
    if w < 0.0:  # q and −q are the same rotation
        along, w = -along, -w
    angle = 2.0 * math.atan2(along, w)
    return math.pi if angle <= -math.pi else angle


@dataclass(frozen=True, eq=False)
class SwingCone:
    """Polygonal cone of allowed bone directions in the parent frame (Macchietto 2008, Fig. 6.2).

    A convex cone (``reflex=False``) is the intersection of the half-spaces
    ``a' · n_i ≤ 0`` of its outward face normals ``n_i``. The thesis writes the
    test as ``a' · n_i < π``, a typo for ``≤ 0``. A reflex cone (``reflex=True``)
    is more than a half-space: it allows ``a'`` unless ``a' · n_i > 0`` for all
    faces, i.e. it is the complement of the convex cone ``{a' · n_i > 0}``.
    No faces means no limit.

    Attributes:
        face_normals_in_parent: ``(k, 3)`` unit outward normals, in cyclic
            order around the cone (``k = 0`` or ``k ≥ 3``).
        reflex: Whether the cone is the complement of a convex forbidden cone.
        edges_in_parent: ``(k, 3)`` unit edge rays of a convex cone, edge ``i``
            between faces ``i`` and ``i + 1`` (empty for reflex cones).
    """

    face_normals_in_parent: np.ndarray
    reflex: bool = False
    edges_in_parent: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        normals = np.array(self.face_normals_in_parent, dtype=float).reshape(-1, 3)
        if len(normals) in (1, 2):
            raise ValueError(f"a swing cone needs 0 or at least 3 faces, got {len(normals)}")
        lengths = np.linalg.norm(normals, axis=1)
        if not np.all(np.isfinite(lengths) & (lengths > _TINY)):
            raise ValueError(f"face normals must be finite and non-zero, got {normals!r}")
        normals /= lengths[:, None]
        edges = np.zeros((0, 3))
        if not self.reflex and len(normals):
            edges = np.cross(normals, np.roll(normals, -1, axis=0))
            edge_lengths = np.linalg.norm(edges, axis=1)
            if np.any(edge_lengths < _TINY):
                raise ValueError("adjacent face normals must not be parallel")
            edges /= edge_lengths[:, None]
            # Each edge ray is the sign of the cross product that lies in every half-space.
            flip = (normals @ edges.T).max(axis=0) > (-normals @ edges.T).max(axis=0)
            edges[flip] *= -1.0
            if (normals @ edges.T).max() > 1e-9:
                raise ValueError(
                    "face normals must be in cyclic order and bound a pointed convex cone"
                )
        normals.setflags(write=False)
        edges.setflags(write=False)
        object.__setattr__(self, "face_normals_in_parent", normals)
        object.__setattr__(self, "edges_in_parent", edges)

    @classmethod
    def regular(cls, axis: np.ndarray, half_angle_rad: float, sides: int = 8) -> SwingCone:
        """A regular ``sides``-gon cone inscribed in the circular cone of ``half_angle_rad``.

        Inscribed means every allowed direction is within ``half_angle_rad`` of
        ``axis``: the soft limit never lets a joint swing further than the
        circular limit (e.g. MuJoCo's ball ``range``). For ``half_angle_rad <
        π/2`` the edges lie on the circle and the faces cut inside it by up to
        ``half_angle − atan(tan(half_angle) cos(π / sides))``. For
        ``half_angle_rad ≥ π/2`` the cone is reflex: the forbidden region is a
        convex cone around ``−axis`` circumscribed about the circle of
        half-angle ``π − half_angle_rad``, so the allowed boundary touches the
        circle at the face centres. ``half_angle_rad ≥ π`` means no limit.

        Args:
            axis: Cone axis (rest bone axis) in the parent frame.
            half_angle_rad: Maximum swing angle, ``> 0``.
            sides: Number of faces, ``≥ 3``.

        Returns:
            The cone; the first face is centred at azimuth ``π / sides`` (convex)
            or ``0`` (reflex), measured from a fixed perpendicular to ``axis``.
        """
        a = _unit(axis, 3, "axis")
        if not half_angle_rad > 0.0:
            raise ValueError(f"{half_angle_rad=} must be > 0")
        if sides < 3:
            raise ValueError(f"{sides=} must be at least 3")
        if half_angle_rad >= math.pi:
            return cls(np.zeros((0, 3)))
        first = _perpendicular(a)
        azimuth = 2.0 * math.pi * np.arange(sides) / sides
        if half_angle_rad < math.pi / 2:
            azimuth = azimuth + math.pi / sides
        radial = np.outer(np.cos(azimuth), first) + np.outer(np.sin(azimuth), np.cross(a, first))
        if half_angle_rad < math.pi / 2:
            tilt = math.atan(math.tan(half_angle_rad) * math.cos(math.pi / sides))
            return cls(-math.sin(tilt) * a + math.cos(tilt) * radial)
        forbidden = math.pi - half_angle_rad
        return cls(-math.sin(forbidden) * a - math.cos(forbidden) * radial, reflex=True)

    def contains(self, direction: np.ndarray) -> bool:
        """Whether the bone direction ``a'`` is allowed (``a' · n_i ≤ 0``, Macchietto 2008 §6.2)."""
        return self.contains_unit(_unit(direction, 3, "direction"))

    def contains_unit(self, unit_direction: np.ndarray) -> bool:
        """:meth:`contains` for a direction already known to be a unit 3-vector (no checks)."""
        if not len(self.face_normals_in_parent):
            return True
        projections = self.face_normals_in_parent @ unit_direction
        if self.reflex:
            return bool(projections.min() <= _TINY)
        return bool(projections.max() <= _TINY)

    def violation(self, direction: np.ndarray) -> float:
        """Axis limit error ``e_axis = acos(a' · a'_pr)`` (rad) (Macchietto 2008, §6.2).

        ``a'_pr`` is the nearest direction on the cone boundary, so this is the
        exact angular distance from ``a'`` to the allowed region: ``0`` inside,
        growing continuously outside (up to ``π`` minus the cone's reach).

        Args:
            direction: Bone direction ``a'`` in the parent frame.

        Returns:
            ``e_axis`` in rad, ``≥ 0``.
        """
        d = _unit(direction, 3, "direction")
        normals = self.face_normals_in_parent
        if not len(normals) or self.contains(d):
            return 0.0
        projections = normals @ d
        if self.reflex:
            # d is inside the convex forbidden cone; its nearest boundary point is on
            # the nearest face plane.
            face = int(np.argmin(projections))
            return _angle_to_plane(d, normals[face], projections[face])
        # Outside a convex cone the nearest point is on an edge ray or is the foot of
        # the perpendicular on a face that d is outside of, if that foot is in the cone.
        nearest = float(np.arccos(np.clip(self.edges_in_parent @ d, -1.0, 1.0)).min())
        feet = d - projections[:, None] * normals
        feet_length = np.linalg.norm(feet, axis=1)
        on_cone = (feet @ normals.T).max(axis=1) <= 1e-12 * feet_length
        usable = (projections > 0.0) & (feet_length > _TINY) & on_cone
        if np.any(usable):
            face = int(np.flatnonzero(usable)[np.argmin(projections[usable])])
            nearest = min(nearest, _angle_to_plane(d, normals[face], projections[face]))
        return nearest


def cones_contain_units(
    face_normals: np.ndarray, reflex: np.ndarray, unlimited: np.ndarray, directions: np.ndarray
) -> np.ndarray:
    """:meth:`SwingCone.contains_unit` for ``B`` cones and one unit direction each, at once.

    Args:
        face_normals: ``(B, S, 3)``, each cone's normals, padded to ``S`` rows by
            repeating one of its own (padding leaves the max and min projection unchanged).
        reflex: ``(B,)`` :attr:`SwingCone.reflex`.
        unlimited: ``(B,)`` cones without faces (every direction allowed).
        directions: ``(B, 3)`` unit directions.
    """
    projections = np.einsum("bsk,bk->bs", face_normals, directions)
    inside = np.where(reflex, projections.min(axis=1) <= _TINY, projections.max(axis=1) <= _TINY)
    return inside | unlimited


def _angle_to_plane(direction: np.ndarray, normal: np.ndarray, projection: float) -> float:
    """Angle between a unit direction and a plane through the origin (atan2: exact near π/2)."""
    in_plane = np.linalg.norm(direction - projection * normal)
    return float(np.arctan2(projection, in_plane))
