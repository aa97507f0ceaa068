"""SRDF: where a URDF's SRDF is looked for, its keyframes and its disabled collisions.

A ``group_state`` is a keyframe of the URDF; ``disable_collisions`` pairs are the pairs of
links a simulator must not collide.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

from controller_server.models.description.files import FileReader
from controller_server.models.description.limits import DescriptionError
from controller_server.models.description.mjcf import parse_xml
from protocol.errors import did_you_mean

__all__ = [
    "find_srdf",
    "read_srdf",
    "srdf_paths",
]


def srdf_paths(urdf: bytes | str | ET.Element) -> list[str]:
    """Where a URDF's SRDF is looked for, in order, by the names its reader is asked for.

    For ``<robot name="N">``: ``N.srdf`` beside the URDF, then
    ``../srdf/N.srdf`` (example-robot-data's ``robots/`` and ``srdf/``
    directories). A reader may serve another file under the first name
    (``poise inspect --srdf FILE``). Empty for a robot without a name.
    """
    root = urdf if isinstance(urdf, ET.Element) else parse_xml(urdf, "the URDF")
    name = (root.get("name") or "").strip()
    if not name or "/" in name or "\\" in name or name in (".", ".."):
        return []
    return [f"{name}.srdf", f"../srdf/{name}.srdf"]


def find_srdf(root: ET.Element, read: FileReader | None) -> tuple[str, bytes] | None:
    """The first of :func:`srdf_paths` the reader serves, and its bytes (``None``: none)."""
    if read is None:
        return None
    for path in srdf_paths(root):
        try:
            return path, read(path)
        except (OSError, KeyError, ValueError):  # DescriptionError is a ValueError
            continue
    return None


def read_srdf(
    path: str, text: bytes, urdf: ET.Element, model: pin.Model, neutral: np.ndarray
) -> tuple[dict[str, np.ndarray], tuple[tuple[str, str], ...], list[str]]:
    """An SRDF's keyframes (``group_state``) and ``disable_collisions`` pairs.

    Each ``group_state`` is a configuration: the URDF's neutral one with the
    named joints set; states of one name in several groups merge, in file
    order. Joints the URDF fixes and the SRDF's virtual joints carry no value
    and are passed over. ``disable_collisions`` pairs become sorted pairs of
    link names; pairs naming a link the URDF lacks are left out, with one
    warning.

    Raises:
        DescriptionError: Not XML, not ``<robot>``, a ``group_state`` naming a
            joint the URDF lacks, or a value that is not numbers of the joint's size.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise DescriptionError(f"the SRDF {path!r} is not valid XML: {exc}") from None
    if root.tag != "robot":
        raise DescriptionError(
            f"an SRDF file's root element is <robot>, not <{root.tag}> ({path!r})"
        )
    urdf_joints = {j.get("name", "") for j in urdf.iter("joint")}
    virtual = {j.get("name", "") for j in root.iter("virtual_joint")}
    links = {link.get("name", "") for link in urdf.iter("link")}
    keyframes: dict[str, np.ndarray] = {}
    for state in root.iter("group_state"):
        name = state.get("name", "")
        q = keyframes.setdefault(name, neutral.copy())
        for joint in state.iter("joint"):
            joint_name = joint.get("name", "")
            if model.existJointName(joint_name) and model.getJointId(joint_name) > 1:
                _set_joint(q, model, model.getJointId(joint_name), joint, name, path)
            elif joint_name not in urdf_joints and joint_name not in virtual:
                hint = did_you_mean(joint_name, model.names[2:]).rstrip()
                raise DescriptionError(
                    f"the SRDF {path!r}: group_state {name!r} sets joint {joint_name!r}, which "
                    f"the URDF does not have{'; ' + hint if hint else ''}"
                )
    pairs: set[tuple[str, str]] = set()
    unknown: list[str] = []
    for disabled in root.iter("disable_collisions"):
        pair = (disabled.get("link1", ""), disabled.get("link2", ""))
        missing = [link for link in pair if link not in links]
        if missing:
            unknown += [link for link in missing if link not in unknown]
        elif pair[0] != pair[1]:
            pairs.add(tuple(sorted(pair)))  # type: ignore[arg-type]
    warnings = []
    if unknown:
        warnings.append(
            f"the SRDF {path!r} disables collisions of {len(unknown)} link(s) the URDF does not "
            f"have ({', '.join(repr(u) for u in unknown[:3])}{', …' if len(unknown) > 3 else ''})"
            ": those pairs are ignored"
        )
    return keyframes, tuple(sorted(pairs)), warnings


def _set_joint(
    q: np.ndarray, model: pin.Model, joint_id: int, element: ET.Element, state: str, path: str
) -> None:
    """Set one joint of ``q`` from an SRDF ``<joint value>`` (a continuous joint: its angle)."""
    joint = model.joints[joint_id]
    try:
        values = [float(v) for v in element.get("value", "").split()]
    except ValueError:
        values = []
    size = 1 if joint.nq == 2 else joint.nq
    if len(values) != size:
        raise DescriptionError(
            f"the SRDF {path!r}: group_state {state!r} gives joint {model.names[joint_id]!r} "
            f"the value {element.get('value', '')!r}; write {size} number(s)"
        )
    if joint.nq == 2:  # continuous: cos, sin
        q[joint.idx_q : joint.idx_q + 2] = np.cos(values[0]), np.sin(values[0])
    else:
        q[joint.idx_q : joint.idx_q + joint.nq] = values
