"""Floating-base robot models loaded with Pinocchio.

A :class:`RobotModel` is everything the server knows about one robot: the
Pinocchio model (free-flyer root first), the actuated joints in wire order,
torque and position limits, and the contacts (feet with their sole points).
It is immutable and shared by every session that uses the same file; each
session keeps its own ``pinocchio.Data``.

Sources: a built-in name (:data:`BUILTIN_MODELS`), a file in the server's
model directories (:mod:`controller_server.files`), or the file's text sent
in ``hello``. MJCF and URDF are both read by Pinocchio; a free-flyer root is
added where the file has none. For MJCF the torque limits come from the
``<actuator>`` motors (|gear| × ctrlrange) and the default contacts from
``*_sole`` box sites (the four corners of the box's x–y rectangle). URDF
files give torque limits in ``<limit effort>`` and must name their contacts
in ``hello``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np
import pinocchio as pin

from controller_server.errors import FrameNotFound, ModelError, ModelNotFound
from controller_server.files import ServerFileKind
from protocol.messages import ContactSpec, JointInfo

__all__ = [
    "BUILTIN_MODELS",
    "DEFAULT_MODEL_CACHE_SIZE",
    "MODEL_FILES",
    "Contact",
    "RobotModel",
    "load_robot_model",
    "set_model_cache_size",
]

DATA_DIR = Path(__file__).parent / "data"
BUILTIN_MODELS: dict[str, Path] = {
    "thesis_humanoid": DATA_DIR / "thesis_humanoid.xml",
    "revolute_humanoid": DATA_DIR / "revolute_humanoid.xml",
    "dino_biped": DATA_DIR / "dino_biped.xml",
}
"""Built-in models by name (package data, MJCF so Pinocchio and MuJoCo agree)."""

MODEL_FILES = ServerFileKind(
    kind="model",
    field="model",
    builtin=BUILTIN_MODELS,
    suffixes=(".xml", ".urdf"),
    not_found=ModelNotFound,
)
"""The model files a ``hello`` may name: built-ins, or files in the model directories."""

DEFAULT_MODEL_CACHE_SIZE = 16
"""Loaded models kept (least recently used dropped first) unless set otherwise."""

# Absolute paths of two or more components, as parser messages may carry them.
_ABSOLUTE_PATH = re.compile(r"(?<![\w.~-])(?:/[\w.+~-]+){2,}/?")

_JOINT_KINDS = {
    "JointModelRX": "revolute",
    "JointModelRY": "revolute",
    "JointModelRZ": "revolute",
    "JointModelRevoluteUnaligned": "revolute",
    "JointModelPX": "prismatic",
    "JointModelPY": "prismatic",
    "JointModelPZ": "prismatic",
    "JointModelPrismaticUnaligned": "prismatic",
    "JointModelSpherical": "ball",
}


@dataclass(frozen=True)
class Contact:
    """A support of the robot: a frame and the points where it meets the ground.

    Attributes:
        name: Contact name on the wire, e.g. ``left_foot``.
        frame_name: Pinocchio frame the points are expressed in.
        frame_id: Index of that frame.
        points_in_frame: ``(k, 3)`` contact points (m) in the frame.
        friction_coefficient: Coulomb μ used for the friction pyramid.
    """

    name: str
    frame_name: str
    frame_id: int
    points_in_frame: np.ndarray
    friction_coefficient: float

    def to_spec(self) -> ContactSpec:
        """The wire description of this contact."""
        return ContactSpec(
            name=self.name,
            frame=self.frame_name,
            points_in_frame=[tuple(map(float, p)) for p in self.points_in_frame],
            friction_coefficient=self.friction_coefficient,
        )


@dataclass(frozen=True)
class RobotModel:
    """An immutable floating-base robot, shared by sessions.

    Attributes:
        name: Model name (built-in name or file stem).
        model: Pinocchio model; joint 1 is the free-flyer root.
        model_hash: SHA-256 of the model text and the contact definitions.
        joints: Actuated joints in wire order (Pinocchio order).
        contacts: Supports in ``contact_flags`` order.
        torque_limit: ``(nv - 6,)`` symmetric torque limits (N·m, N).
        standing_position_base_in_world: Base position (m) at which the
            neutral pose stands (the file's root body position).
        ball_swing_limit: Maximum swing angle (rad) per ball joint name, from
            the MJCF ``range`` upper bound (π where the file gives none).
    """

    name: str
    model: pin.Model
    model_hash: str
    joints: tuple[JointInfo, ...]
    contacts: tuple[Contact, ...]
    torque_limit: np.ndarray
    standing_position_base_in_world: np.ndarray
    ball_swing_limit: dict[str, float]

    @property
    def nq_joints(self) -> int:
        """Length of ``joint_position`` on the wire."""
        return self.model.nq - 7

    @property
    def nv_joints(self) -> int:
        """Length of ``joint_velocity`` and ``joint_torque`` on the wire."""
        return self.model.nv - 6

    @cached_property
    def total_mass(self) -> float:
        """Total mass (kg)."""
        return float(sum(inertia.mass for inertia in self.model.inertias))

    @property
    def num_contact_points(self) -> int:
        """Number of contact points over all contacts."""
        return sum(len(c.points_in_frame) for c in self.contacts)

    @cached_property
    def ball_quaternion_starts(self) -> np.ndarray:
        """Index in ``joint_position`` (wire) of each ball joint's quaternion ``[x, y, z, w]``."""
        model = self.model
        return np.array(
            [
                model.idx_qs[model.getJointId(joint.name)] - 7
                for joint in self.joints
                if joint.kind == "ball"
            ],
            dtype=int,
        )

    @cached_property
    def ball_quaternion_index(self) -> np.ndarray:
        """``ball_quaternion_starts`` expanded: the 4 indices of every ball quaternion, flat."""
        return (self.ball_quaternion_starts[:, None] + np.arange(4)).reshape(-1)


def _mjcf_torque_limits(root: ET.Element, model: pin.Model) -> np.ndarray:
    """Torque limits per DoF from MJCF ``<motor>``s: |gear| × max|ctrlrange| (or forcerange)."""
    limit = np.full(model.nv, np.inf)
    for actuator in root.iter():
        joint_name = actuator.get("joint")
        if actuator.tag not in ("motor", "general") or joint_name is None:
            continue
        if not model.existJointName(joint_name):
            raise ModelError(
                f"actuator {actuator.get('name')!r} drives unknown joint {joint_name!r}"
            )
        joint = model.joints[model.getJointId(joint_name)]
        gear = np.array([float(g) for g in actuator.get("gear", "1").split()])
        bound = np.inf
        for key in ("ctrlrange", "forcerange"):
            if key in actuator.attrib:
                # MuJoCo clamps the actuator force, then multiplies by the gear.
                lo, hi = (float(x) for x in actuator.get(key, "").split())
                bound = min(bound, np.max(np.abs(gear)) * max(abs(lo), abs(hi)))
        axes = np.flatnonzero(gear[: joint.nv]) if gear.size > 1 else np.arange(joint.nv)
        for axis in axes:
            limit[joint.idx_v + axis] = bound
    return limit[6:]


def _mjcf_ball_swing_limits(root: ET.Element) -> dict[str, float]:
    """Upper bound of ``range`` of every limited ball joint (MJCF: radians here)."""
    limits = {}
    for joint in root.iter("joint"):
        if joint.get("type") == "ball" and "range" in joint.attrib:
            limits[joint.get("name", "")] = float(joint.get("range", "0 0").split()[1])
    return limits


def _default_contacts(root: ET.Element, model: pin.Model) -> list[ContactSpec]:
    """Contacts from ``*_sole`` box sites: the four corners of their x–y rectangle."""
    specs = []
    for site in root.iter("site"):
        name = site.get("name", "")
        if not name.endswith("_sole") or site.get("type") != "box":
            continue
        half_x, half_y = (float(s) for s in site.get("size", "0 0 0").split()[:2])
        corners = [(sx * half_x, sy * half_y, 0.0) for sx in (1, -1) for sy in (1, -1)]
        specs.append(
            ContactSpec(
                name=name.removesuffix("_sole") + "_foot", frame=name, points_in_frame=corners
            )
        )
    return specs


def _mjcf_root_body_position(root: ET.Element) -> np.ndarray:
    """``pos`` of the first body under ``<worldbody>`` (zero if none)."""
    body = root.find("./worldbody/body")
    if body is None:
        return np.zeros(3)
    return np.array([float(x) for x in body.get("pos", "0 0 0").split()])


def _parser_message(exc: Exception, path: Path, name: str) -> str:
    """Pinocchio's message without server paths: the model's name for the file, no C++ trace.

    Pinocchio prefixes its C++ source file, function and line (``From file:
    … message:``); only the message is kept, the temporary file is named by
    the model's name, and any other absolute path becomes ``<path>``.
    """
    text = str(exc)
    _, marker, message = text.partition("message:")
    text = message if marker else text
    text = text.replace(str(path), repr(name))
    return " ".join(_ABSOLUTE_PATH.sub("<path>", text).split())


def _mjcf_has_free_joint(root: ET.Element) -> bool:
    """Whether a body of the MJCF's world has a free joint, in either spelling.

    ``<freejoint/>`` and ``<joint type="free"/>`` are the same joint to MuJoCo (and to
    Pinocchio's parser); vendors write both.
    """
    world = root.find("worldbody")
    if world is None:
        return False
    return any(
        element.tag == "freejoint" or (element.tag == "joint" and element.get("type") == "free")
        for element in world.iter()
    )


def _build_pinocchio(path: Path, fmt: str, name: str) -> pin.Model:
    """Parse with Pinocchio, adding a free-flyer root where the file has none.

    Raises:
        ModelError: Pinocchio refused the file (message free of server paths).
    """
    try:
        if fmt == "urdf":
            return pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
        model = pin.buildModelFromMJCF(str(path))
        if model.njoints < 2 or model.joints[1].shortname() != "JointModelFreeFlyer":
            model, _ = pin.buildModelAndLegacyConstraintsFromMJCF(
                str(path), pin.JointModelFreeFlyer(), "root"
            )
    except (RuntimeError, ValueError, IndexError) as exc:
        detail = _parser_message(exc, path, name)
        raise ModelError(f"Pinocchio could not parse the {fmt.upper()} file: {detail}") from None
    return model


def _resolve(contact: ContactSpec, model: pin.Model) -> Contact:
    if not model.existFrame(contact.frame):
        raise FrameNotFound(contact.frame, [f.name for f in model.frames])
    return Contact(
        name=contact.name,
        frame_name=contact.frame,
        frame_id=model.getFrameId(contact.frame),
        points_in_frame=np.array(contact.points_in_frame, dtype=float),
        friction_coefficient=contact.friction_coefficient,
    )


def _joint_infos(model: pin.Model, torque_limit: np.ndarray) -> tuple[JointInfo, ...]:
    infos = []
    for joint_id in range(2, model.njoints):
        joint = model.joints[joint_id]
        kind = _JOINT_KINDS.get(joint.shortname())
        if kind is None:
            raise ModelError(
                f"joint {model.names[joint_id]!r} is a {joint.shortname()}; supported: "
                "revolute, prismatic, ball"
            )
        v = slice(joint.idx_v - 6, joint.idx_v - 6 + joint.nv)
        q = slice(joint.idx_q, joint.idx_q + joint.nq)
        limited = kind != "ball"
        infos.append(
            JointInfo(
                name=model.names[joint_id],
                kind=kind,
                nq=joint.nq,
                nv=joint.nv,
                torque_limit=[float(t) for t in torque_limit[v]],
                position_lower=[float(x) for x in model.lowerPositionLimit[q]] if limited else None,
                position_upper=[float(x) for x in model.upperPositionLimit[q]] if limited else None,
            )
        )
    return tuple(infos)


def _hash(text: bytes, contacts: list[ContactSpec]) -> str:
    digest = hashlib.sha256(text)
    digest.update(_contacts_json(contacts).encode())
    return digest.hexdigest()


def load_robot_model(
    model: str | None = None,
    *,
    model_text: str | None = None,
    model_format: str = "mjcf",
    contacts: list[ContactSpec] | None = None,
) -> RobotModel:
    """Load a robot from a built-in name, a file in the model directories, or file text.

    Args:
        model: Built-in name (see :data:`BUILTIN_MODELS`) or path of a file in
            the server's model directories (see :data:`MODEL_FILES`); the
            robot's name is then the file's stem.
        model_text: Text of an MJCF/URDF file (instead of ``model``).
        model_format: ``"mjcf"`` or ``"urdf"``; a path ending in ``.urdf`` is URDF.
        contacts: Contact definitions; default: the MJCF's ``*_sole`` box sites.

    Returns:
        The model, cached: the same inputs give the same object while they are
        among the last :func:`set_model_cache_size` loaded.

    Raises:
        ModelError: Not found (one message whatever the reason), not
            parseable, unsupported joints or no contacts.
        FileTooLarge: A file over the size cap.
    """
    if model_text is not None:
        text = model_text.encode()
        name = "client_model"
    elif model is not None:
        path, text = MODEL_FILES.read_bytes(model)
        name = model if model in BUILTIN_MODELS else Path(model).stem
        if path.suffix.lower() == ".urdf":
            model_format = "urdf"
    else:
        raise ModelError("no model given: set `model` or `model_text`")
    contacts_json = None if contacts is None else _contacts_json(contacts)
    return _load_cached(text, name, model_format, contacts_json)


def _contacts_json(contacts: list[ContactSpec]) -> str:
    return json.dumps([c.model_dump() for c in contacts], sort_keys=True)


def set_model_cache_size(size: int) -> None:
    """Keep the ``size`` most recently loaded models (emptying the cache).

    Args:
        size: Number of models kept, ≥ 1; the default is :data:`DEFAULT_MODEL_CACHE_SIZE`.

    Raises:
        ValueError: ``size`` below 1.
    """
    if size < 1:
        raise ValueError(f"the model cache keeps at least one model, got {size=}")
    global _load_cached
    _load_cached = lru_cache(maxsize=size)(_load_uncached)


def _load_uncached(text: bytes, name: str, fmt: str, contacts_json: str | None) -> RobotModel:
    contacts = (
        None
        if contacts_json is None
        else [ContactSpec.model_validate(c) for c in json.loads(contacts_json)]
    )
    # Well-formed XML first: the C++ parsers are not the place to find garbage.
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ModelError(f"invalid XML: {exc}") from None
    # Pinocchio parses files, so the text goes through a private temporary file.
    with tempfile.TemporaryDirectory(prefix="poise-model-") as tmp:
        path = Path(tmp) / f"model.{'urdf' if fmt == 'urdf' else 'xml'}"
        path.write_bytes(text)
        os.chmod(path, 0o600)
        model = _build_pinocchio(path, fmt, name)
    # The wire's base position is the root body's world position (as MuJoCo's
    # free-joint qpos). Pinocchio keeps an MJCF root body's position in the
    # reference configuration "qpos0", a URDF root offset (if any) in the
    # joint placement; both become the standing base position.
    standing_position = model.jointPlacements[1].translation.copy()
    if "qpos0" in model.referenceConfigurations:
        standing_position += model.referenceConfigurations["qpos0"][:3]
    model.jointPlacements[1] = pin.SE3.Identity()
    if fmt == "mjcf":
        if not _mjcf_has_free_joint(root):
            # Pinocchio drops the root body's position when it adds the free flyer.
            standing_position = standing_position + _mjcf_root_body_position(root)
        torque_limit = _mjcf_torque_limits(root, model)
        swing_limits = _mjcf_ball_swing_limits(root)
        specs = list(contacts) if contacts is not None else _default_contacts(root, model)
    else:
        swing_limits = {}
        torque_limit = np.asarray(model.effortLimit[6:], dtype=float).copy()
        torque_limit[torque_limit <= 0] = np.inf
        specs = list(contacts or [])
    if not specs:
        raise ModelError(
            "the model defines no contacts: add `*_sole` box sites (MJCF) or send `contacts`",
            field="contacts",
        )
    model.effortLimit[6:] = torque_limit
    torque_limit.setflags(write=False)
    standing_position.setflags(write=False)
    resolved = tuple(_resolve(spec, model) for spec in specs)
    joints = _joint_infos(model, torque_limit)
    return RobotModel(
        name=name,
        model=model,
        model_hash=_hash(text, specs),
        joints=joints,
        contacts=resolved,
        torque_limit=torque_limit,
        standing_position_base_in_world=standing_position,
        ball_swing_limit={
            info.name: swing_limits.get(info.name, np.pi) for info in joints if info.kind == "ball"
        },
    )


_load_cached = lru_cache(maxsize=DEFAULT_MODEL_CACHE_SIZE)(_load_uncached)
