"""The description itself: :class:`RobotDescription` and :func:`describe`, which makes it.

:func:`describe` hands a file to its format's reader, then finds the contacts and the
standing pose and checks them; :func:`gather_files` reads every file a model names, by the
names :func:`describe` will ask for.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from controller_server.models.description.bodies import Body, Draft, FoundContact
from controller_server.models.description.feet import (
    body_of_frame,
    find_feet,
    foot_candidates,
    named_contact,
    subtree,
)
from controller_server.models.description.files import FileReader
from controller_server.models.description.limits import DescriptionError, DescriptionLimitError
from controller_server.models.description.mjcf import expand_mjcf, parse_xml
from controller_server.models.description.pinocchio_from_mujoco import read_mjcf
from controller_server.models.description.shapes import to_world
from controller_server.models.description.srdf import find_srdf, srdf_paths
from controller_server.models.description.urdf import read_urdf
from protocol.messages import MAX_CONTACT_POINTS, MAX_CONTACTS, MAX_POINTS_PER_CONTACT, ContactSpec

__all__ = [
    "RobotDescription",
    "describe",
    "gather_files",
]


def gather_files(text: bytes | str, fmt: str, read: FileReader | None) -> dict[str, bytes]:
    """Every file the model names, read now, by the name :func:`describe` will ask for.

    MJCF: includes (recursively) and assets, by their path relative to the main
    file's directory; a file that cannot be read is an error. URDF: the
    collision meshes that can be read, keyed by their ``filename`` exactly as
    written (the others are left out by :func:`describe`, with a warning or an
    error), and the SRDF if one is found (:func:`srdf_paths`).

    Raises:
        DescriptionError: An MJCF names a file that cannot be read, or is not XML.
    """
    files: dict[str, bytes] = {}

    def recording(path: str) -> bytes:
        if read is None:
            raise KeyError("no file was given with the model")
        files[path] = read(path)
        return files[path]

    if fmt == "urdf":
        root = parse_xml(text, "the URDF")
        for collision in root.iter("collision"):
            for mesh in collision.iter("mesh"):
                filename = mesh.get("filename", "")
                if filename in files:
                    continue
                try:
                    recording(filename)
                except (OSError, KeyError, ValueError):
                    continue
        find_srdf(root, recording)
    else:
        expand_mjcf(text, recording if read is not None else None)
    return files


@dataclass(frozen=True)
class RobotDescription:
    """What Poise reads from a robot file (see the module docstring).

    Attributes:
        name: Model name.
        format: ``"mjcf"`` or ``"urdf"``.
        model: Pinocchio model, joint 1 the free-flyer root with an identity placement.
        bodies: The robot's bodies (root first, parents before children).
        contacts: Supports in ``contact_flags`` order.
        torque_limit: ``(nv − 6,)`` symmetric limits (N·m, N; ``inf``: none stated).
        actuator_kind: Joint name → ``motor``, ``position``, ``velocity``,
            ``general`` (MJCF), ``effort`` (URDF) or ``none``.
        ball_swing_limit: Ball joint name → largest swing (rad; π where unlimited).
        standing_configuration: Pinocchio ``q`` of the standing pose, soles at z = 0.
        keyframes: Names of the file's keyframes.
        keyframe: The keyframe the standing pose comes from (``None``: the file's pose).
        contacts_source: Where the contacts come from: ``given``, ``sole sites``
            or ``collision geometry``.
        warnings: What a user should know (unactuated joints, converted actuators …).
        disabled_collision_pairs: Pairs of body names whose collisions a simulator
            must not simulate (an SRDF's ``disable_collisions``), each pair sorted.
    """

    name: str
    format: str
    model: pin.Model
    bodies: tuple[Body, ...]
    contacts: tuple[FoundContact, ...]
    torque_limit: np.ndarray
    actuator_kind: dict[str, str]
    ball_swing_limit: dict[str, float]
    standing_configuration: np.ndarray
    keyframes: tuple[str, ...]
    keyframe: str | None
    contacts_source: str
    warnings: tuple[str, ...] = field(default=())
    disabled_collision_pairs: tuple[tuple[str, str], ...] = field(default=())

    @property
    def joint_names(self) -> list[str]:
        """Actuated joints in wire (Pinocchio) order."""
        return list(self.model.names[2:])

    @property
    def total_mass(self) -> float:
        """Total mass (kg)."""
        return float(sum(inertia.mass for inertia in self.model.inertias))


def describe(
    text: bytes | str,
    fmt: str = "mjcf",
    *,
    read: FileReader | None = None,
    name: str = "robot",
    contacts: Sequence[ContactSpec] | None = None,
    keyframe: str | None = None,
) -> RobotDescription:
    """Read a robot file (see the module docstring).

    Args:
        text: The main MJCF or URDF file.
        fmt: ``"mjcf"`` or ``"urdf"``.
        read: Reads the files the model names (includes, meshes), relative to
            the main file's directory.
        name: Model name.
        contacts: Contacts to use instead of the found ones; one without
            points gets its sole found from its frame's body.
        keyframe: Keyframe whose pose is the standing pose (MJCF ``<key>``; URDF:
            its SRDF's ``group_state``).

    Raises:
        DescriptionError: What to change, on one line.
    """
    draft = read_urdf(text, read, name) if fmt == "urdf" else read_mjcf(text, read)
    model = draft.model
    model.name = name
    if keyframe is not None:
        if keyframe not in draft.keyframes:
            known = ", ".join(draft.keyframes) or "none"
            where = (
                " (a URDF's keyframes are its SRDF's group_states: "
                f"{' or '.join(srdf_paths(text)) or 'NAME.srdf'} beside it, or --srdf FILE)"
                if fmt == "urdf"
                else ""
            )
            raise DescriptionError(
                f"no keyframe {keyframe!r} in the model; keyframes: {known}{where}",
                field="keyframe",
            )
        draft.configuration = draft.keyframes[keyframe].copy()
    q = draft.configuration
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    if draft.unreadable_meshes:
        _check_unreadable_meshes(draft, data, contacts, model)
    if contacts is not None:
        found = [named_contact(spec, model, data, draft.bodies) for spec in contacts]
        source = "given"
    elif draft.sole_sites:
        found, source = draft.sole_sites, "sole sites"
    else:
        found, source = find_feet(model, data, draft.bodies), "collision geometry"
    if not found:
        raise DescriptionError("no contacts: name the feet (`contacts`)", field="contacts")
    _check_contacts(found, source)
    draft.warnings += [
        f"contact {c.name!r} touches at {len(c.points_in_frame)} point(s) in the standing pose, "
        "too few to balance on alone: give its points, or a keyframe with the foot flat"
        for c in found
        if source == "collision geometry" and len(c.points_in_frame) < 3
    ]
    lowest = min(
        float(to_world(data.oMf[model.getFrameId(c.frame)], c.points_in_frame)[:, 2].min())
        for c in found
    )
    q[2] -= lowest
    q.setflags(write=False)
    draft.torque_limit.setflags(write=False)
    return RobotDescription(
        name=name,
        format=fmt,
        model=model,
        bodies=tuple(draft.bodies),
        contacts=tuple(found),
        torque_limit=draft.torque_limit,
        actuator_kind=draft.actuator_kind,
        ball_swing_limit=draft.ball_swing_limit,
        standing_configuration=q,
        keyframes=tuple(draft.keyframes),
        keyframe=keyframe,
        contacts_source=source,
        warnings=tuple(draft.warnings),
        disabled_collision_pairs=draft.disabled_collision_pairs,
    )


def _check_contacts(found: Sequence[FoundContact], source: str) -> None:
    """Refuse more contacts or points than a session may have (``protocol.messages``' caps).

    Raises:
        DescriptionLimitError: Over :data:`~protocol.messages.MAX_CONTACTS`,
            :data:`~protocol.messages.MAX_POINTS_PER_CONTACT` or
            :data:`~protocol.messages.MAX_CONTACT_POINTS`.
    """
    where = f"(contacts from the {source})" if source != "given" else ""
    if len(found) > MAX_CONTACTS:
        raise DescriptionLimitError(
            f"{len(found)} contacts {where}; at most {MAX_CONTACTS}: name the feet (`contacts`)",
            field="contacts",
        )
    for contact in found:
        if len(contact.points_in_frame) > MAX_POINTS_PER_CONTACT:
            raise DescriptionLimitError(
                f"contact {contact.name[:100]!r} has {len(contact.points_in_frame)} points; at "
                f"most {MAX_POINTS_PER_CONTACT}",
                field="contacts",
            )
    total = sum(len(contact.points_in_frame) for contact in found)
    if total > MAX_CONTACT_POINTS:
        raise DescriptionLimitError(
            f"the contacts have {total} points together {where}; at most {MAX_CONTACT_POINTS}",
            field="contacts",
        )


def _check_unreadable_meshes(
    draft: Draft, data: pin.Data, contacts: Sequence[ContactSpec] | None, model: pin.Model
) -> None:
    """Refuse an unreadable collision mesh where a sole is looked for; summarise the others.

    Where a sole is looked for: on a :func:`foot_candidates` body when the feet
    are found from the collision geometry, and on a named contact's body and
    its descendants when its points are not given.

    Raises:
        DescriptionError: The first unreadable mesh where a sole is looked for:
            its file, why (the path tried), and what to do.
    """
    bodies = draft.bodies
    if contacts is None:
        looked_at = set(foot_candidates(model, data, bodies)) if not draft.sole_sites else set()
        why = "a foot candidate: one of the lowest links standing"
    else:
        looked_at = set()
        for spec in contacts:
            if spec.points_in_frame is None and model.existFrame(spec.frame):
                top = body_of_frame(model, bodies, model.getFrameId(spec.frame))
                if top is not None:
                    looked_at |= {bodies[i].name for i in subtree(bodies, top)}
        why = "part of a named foot"
    for mesh in draft.unreadable_meshes:
        if mesh.link in looked_at:
            scheme, _, rest = mesh.filename.partition("://")
            todo = (
                f"set ROS_PACKAGE_PATH to a directory that holds package {rest.split('/')[0]!r}"
                if scheme == "package" and rest
                else "make the file readable"
            )
            raise DescriptionError(
                f"the collision mesh {mesh.filename!r} of link {mesh.link!r} ({why}) cannot be "
                f"read: {mesh.reason}; {todo}, or name feet whose meshes can be read "
                "(--contacts) or give their points (`contacts` with `points_in_frame`)"
            )
    first = draft.unreadable_meshes[0]
    count = len({mesh.filename for mesh in draft.unreadable_meshes})
    draft.warnings.append(
        f"{count} collision mesh file(s) cannot be read and are left out, e.g. "
        f"{first.filename!r} of link {first.link!r}: {first.reason}"
    )
