"""Contacts from geometry: the feet, their soles, and the sole of a contact named by its frame.

At the standing pose, the bodies whose collision geometry reaches within
:data:`FOOT_HEIGHT_TOLERANCE_M` of the lowest point are the feet, and a foot's sole is the
rectangle around its collision points within :data:`SOLE_HEIGHT_TOLERANCE_M` of its lowest
one (the package's docstring says more).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from controller_server.models.description.bodies import Body, FoundContact
from controller_server.models.description.limits import DescriptionError, FrameNotFoundError
from controller_server.models.description.shapes import to_world
from protocol.messages import ContactSpec

__all__ = [
    "FOOT_CANDIDATE_HEIGHT_FRACTION",
    "FOOT_HEIGHT_TOLERANCE_M",
    "SOLE_HEIGHT_TOLERANCE_M",
    "body_of_frame",
    "find_feet",
    "foot_candidates",
    "named_contact",
    "subtree",
]

FOOT_HEIGHT_TOLERANCE_M = 0.02
"""A body whose collision geometry reaches this close to the lowest point (standing) is a foot."""
SOLE_HEIGHT_TOLERANCE_M = 0.005
"""A foot's collision points this close to its lowest point span its sole."""
FOOT_CANDIDATE_HEIGHT_FRACTION = 0.15
"""A URDF link whose frame (standing) is this far up the robot's height, or lower, may be a foot.

Measured from the lowest link frame, as a fraction of the span between the
lowest and the highest link frame: ankles, feet, soles and toes, not knees
nor hands hanging by the thighs. A collision mesh of such a link that cannot
be read is an error when the feet are found from the collision geometry."""


def foot_candidates(model: pin.Model, data: pin.Data, bodies: Sequence[Body]) -> list[str]:
    """The bodies that may be feet, whatever their collision geometry: the lowest frames.

    A body whose frame, at the pose of ``data``, is within
    :data:`FOOT_CANDIDATE_HEIGHT_FRACTION` of the span between the lowest and
    the highest body frame above the lowest one: ankles, feet, soles, toes.
    """
    heights = np.array([data.oMf[b.frame_id].translation[2] for b in bodies])
    limit = heights.min() + FOOT_CANDIDATE_HEIGHT_FRACTION * (heights.max() - heights.min())
    return [b.name for b, z in zip(bodies, heights, strict=True) if z <= limit + 1e-9]


def subtree(bodies: Sequence[Body], top: int) -> list[int]:
    """Indices of body ``top`` and its descendants in ``bodies`` (parents before children)."""
    inside = [top]
    for index in range(top + 1, len(bodies)):
        if bodies[index].parent in inside:
            inside.append(index)
    return inside


def _lowest_points_in_world(data: pin.Data, body: Body) -> np.ndarray:
    """Each collision point's lowest point in the world: vertices, round shapes' bottoms."""
    world = to_world(data.oMf[body.frame_id], body.collision_points)
    world[:, 2] -= body.collision_radii
    return world


def _sole(
    model: pin.Model, data: pin.Data, bodies: Sequence[Body], top: int, frame_id: int
) -> np.ndarray:
    """Corners (in the frame) of the sole rectangle of the foot ``top`` and its descendants."""
    world = np.vstack([_lowest_points_in_world(data, bodies[b]) for b in subtree(bodies, top)])
    if len(world) == 0:
        raise DescriptionError(
            f"body {bodies[top].name!r} has no collision geometry to find a sole on; "
            "give the contact's points",
            field="contacts",
        )
    low = world[world[:, 2] <= world[:, 2].min() + SOLE_HEIGHT_TOLERANCE_M]
    frame = data.oMf[frame_id]
    heading = frame.rotation[:, 0] * (1, 1, 0)
    if np.linalg.norm(heading) < 1e-6:  # the frame's x points up or down: use its z
        heading = frame.rotation[:, 2] * (1, 1, 0)
    heading /= np.linalg.norm(heading)
    lateral = np.array([-heading[1], heading[0], 0.0])
    along, across = low @ heading, low @ lateral
    corners_in_world = np.array(
        [
            a * heading + c * lateral + (0.0, 0.0, world[:, 2].min())
            for a in (along.max(), along.min())
            for c in (across.max(), across.min())
        ]
    )
    corners = (corners_in_world - frame.translation) @ frame.rotation
    # A line or point foot (spheres in a row, one sphere) has coincident corners: keep one each.
    _, first = np.unique(np.round(corners, 6), axis=0, return_index=True)
    return corners[np.sort(first)]


def body_of_frame(model: pin.Model, bodies: Sequence[Body], frame_id: int) -> int | None:
    """Index in ``bodies`` of the body a frame is on (``None``: none, e.g. the world's).

    A body's frame is its own; a joint's is the body the joint moves (the first on it);
    any other frame's is the nearest body frame it hangs from.
    """
    index = {body.frame_id: i for i, body in enumerate(bodies)}
    frame = model.frames[frame_id]
    if frame.type == pin.JOINT:
        return next(
            (
                i
                for i, b in enumerate(bodies)
                if model.frames[b.frame_id].parentJoint == frame.parentJoint
            ),
            None,
        )
    for _ in range(len(model.frames)):
        if frame_id in index:
            return index[frame_id]
        if frame_id == 0:
            return None
        frame_id = model.frames[frame_id].parentFrame
    return None


def named_contact(
    spec: ContactSpec, model: pin.Model, data: pin.Data, bodies: Sequence[Body]
) -> FoundContact:
    """A contact as given: its points if it has them, else its sole from its frame's body."""
    if not model.existFrame(spec.frame):
        raise FrameNotFoundError(
            spec.frame, [f.name for f in model.frames if f.type in (pin.BODY, pin.OP_FRAME)]
        )
    frame_id = model.getFrameId(spec.frame)
    if model.frames[frame_id].parentJoint == 0:
        raise DescriptionError(
            f"frame {spec.frame[:100]!r} is fixed in the world, not part of the robot: name a "
            "body, site or joint of the robot",
            field="contacts",
        )
    if spec.points_in_frame is not None:
        return FoundContact(
            spec.name,
            spec.frame,
            np.array(spec.points_in_frame, float),
            spec.friction_coefficient,
            reason="named, with its points",
        )
    top = body_of_frame(model, bodies, frame_id)
    if top is None:
        raise DescriptionError(
            f"frame {spec.frame[:100]!r} is on no body of the robot to find a sole on: name a "
            "body or site, or give the contact's points",
            field="contacts",
        )
    return FoundContact(
        spec.name,
        spec.frame,
        _sole(model, data, bodies, top, frame_id),
        spec.friction_coefficient,
        reason=f"named; its sole from the collision geometry of {bodies[top].name!r} and below",
    )


def find_feet(model: pin.Model, data: pin.Data, bodies: Sequence[Body]) -> list[FoundContact]:
    """The feet: lowest bodies (standing) without a lowest ancestor, named by their side."""
    lowest = {
        i: float(_lowest_points_in_world(data, b)[:, 2].min())
        for i, b in enumerate(bodies)
        if len(b.collision_points)
    }
    if not lowest:
        raise DescriptionError(
            "no body has collision geometry to find the feet on: give the contacts with their "
            "points (`contacts`)",
            field="contacts",
        )
    ground = min(lowest.values())
    touching = {i for i, z in lowest.items() if z <= ground + FOOT_HEIGHT_TOLERANCE_M}
    feet = []
    for i in sorted(touching):
        ancestor = bodies[i].parent
        while ancestor >= 0 and ancestor not in touching:
            ancestor = bodies[ancestor].parent
        if ancestor < 0:
            feet.append(i)
    # Left of the root's heading (its x axis on the ground; some files turn the root body).
    root = data.oMf[bodies[0].frame_id]
    heading = root.rotation[:, 0] * (1.0, 1.0, 0.0)
    heading = heading if np.linalg.norm(heading) > 1e-6 else np.array([1.0, 0.0, 0.0])
    lateral = np.array([-heading[1], heading[0], 0.0])
    sides = [
        float((data.oMf[bodies[i].frame_id].translation - root.translation) @ lateral) for i in feet
    ]
    lowest_reason = (
        "its collision points are among the lowest at the standing pose (within "
        f"{FOOT_HEIGHT_TOLERANCE_M:g} m of the lowest point)"
    )
    if len(feet) == 2 and sides[0] * sides[1] < 0:
        names = ["left_foot" if side > 0 else "right_foot" for side in sides]
        order = [0, 1] if names[0] == "left_foot" else [1, 0]
        feet, names = [feet[k] for k in order], [names[k] for k in order]
        sides = [sides[k] for k in order]
        reasons = [
            f"{lowest_reason}; {'left' if side > 0 else 'right'} of the root's heading "
            f"({abs(side):.3f} m)"
            for side in sides
        ]
    else:
        names = [bodies[i].name for i in feet]
        reasons = [f"{lowest_reason}; {len(feet)} such feet: named by their bodies"] * len(feet)
    # The points are in the frame the body's name resolves to (a joint of the same name
    # would come first), as every user of the contact looks it up by name.
    return [
        FoundContact(
            name,
            bodies[i].name,
            _sole(model, data, bodies, i, model.getFrameId(bodies[i].name)),
            reason=reason,
        )
        for name, i, reason in zip(names, feet, reasons, strict=True)
    ]
