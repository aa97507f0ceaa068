"""Floating-base robot models, read as their vendors wrote them and served to sessions.

A :class:`RobotModel` is everything the server knows about one robot: the
Pinocchio model (free-flyer root first), the actuated joints in wire order,
torque and position limits, the contacts (feet with their sole points) and
the standing pose. It is immutable and shared by every session that uses the
same files; each session keeps its own ``pinocchio.Data``.

Sources: a built-in name (:data:`BUILTIN_MODELS`), a file in the server's
model directories (:mod:`controller_server.files`), or the file's text sent
in ``hello`` with the files it names. The reading itself — MuJoCo's compiler
for MJCF, Pinocchio's parser for URDF, contacts found from the collision
geometry, limits, keyframes — is :mod:`controller_server.models.description`,
shared with the simulators; this module adds the server's file policy (a
model in the model directories names files only inside them; a sent model
only the files sent with it), the cache and the wire descriptions.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np
import pinocchio as pin

from controller_server.errors import (
    FileTooLarge,
    FrameNotFound,
    ModelError,
    ModelNotFound,
    ModelTooLarge,
    ServerFault,
)
from controller_server.files import (
    ServerFileKind,
    display_name,
    model_directories,
    without_server_paths,
)
from controller_server.models.description import (
    DescriptionError,
    DescriptionLimitError,
    FileReader,
    FoundContact,
    FrameNotFoundError,
    RobotDescription,
    describe,
    gather_files,
    resolve_file,
    ros_package_path,
)
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

MODEL_ASSET_FILES = ServerFileKind(
    kind="file named by a model",
    field="model",
    builtin={},
    suffixes=(".xml", ".urdf", ".srdf", ".stl", ".obj", ".msh", ".ply", ".png"),
    not_found=ModelNotFound,
)
"""What a model in the model directories may name (includes, meshes, textures): files in them."""

DEFAULT_MODEL_CACHE_SIZE = 16
"""Loaded models kept (least recently used dropped first) unless set otherwise."""

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
        standing_configuration: Pinocchio ``q`` of the standing pose (the
            keyframe's or the file's), its lowest contact point at z = 0.
        ball_swing_limit: Maximum swing angle (rad) per ball joint name, from
            the MJCF ``range`` upper bound (π where the file gives none).
        description: What was read from the file (actuator kinds, warnings …).
    """

    name: str
    model: pin.Model
    model_hash: str
    joints: tuple[JointInfo, ...]
    contacts: tuple[Contact, ...]
    torque_limit: np.ndarray
    standing_configuration: np.ndarray
    ball_swing_limit: dict[str, float]
    description: RobotDescription

    @property
    def standing_position_base_in_world(self) -> np.ndarray:
        """Base position (m) of the standing pose."""
        return self.standing_configuration[:3]

    @property
    def standing_orientation_base_in_world_xyzw(self) -> np.ndarray:
        """Base orientation of the standing pose, quaternion ``[x, y, z, w]``."""
        return self.standing_configuration[3:7]

    @property
    def standing_joint_position(self) -> np.ndarray:
        """Joint positions of the standing pose, wire order (rad, m; ball: xyzw)."""
        return self.standing_configuration[7:]

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


def _resolve(contact: FoundContact, model: pin.Model) -> Contact:
    return Contact(
        name=contact.name,
        frame_name=contact.frame,
        frame_id=model.getFrameId(contact.frame),
        points_in_frame=contact.points_in_frame,
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


def _hash(text: bytes, files: dict[str, bytes], contacts: str, keyframe: str | None) -> str:
    digest = hashlib.sha256(text)
    for path in sorted(files):
        digest.update(f"\0{path}\0".encode())
        digest.update(files[path])
    digest.update(contacts.encode())
    if keyframe is not None:
        digest.update(f"\0keyframe\0{keyframe}".encode())
    return digest.hexdigest()


def load_robot_model(
    model: str | None = None,
    *,
    model_text: str | None = None,
    model_format: str = "mjcf",
    model_assets: dict[str, bytes] | None = None,
    contacts: list[ContactSpec] | None = None,
    keyframe: str | None = None,
) -> RobotModel:
    """Load a robot from a built-in name, a file in the model directories, or file text.

    The file is read as its vendor wrote it (:mod:`controller_server.models.description`):
    the files it names (includes, meshes) come from beside it in the model
    directories, or for ``model_text`` from ``model_assets`` only.

    Args:
        model: Built-in name (see :data:`BUILTIN_MODELS`) or path of a file in
            the server's model directories (see :data:`MODEL_FILES`); the
            robot's name is then the file's stem.
        model_text: Text of an MJCF/URDF file (instead of ``model``).
        model_format: ``"mjcf"`` or ``"urdf"``; a path ending in ``.urdf`` is URDF.
        model_assets: Files ``model_text`` names, by the path it names them with.
        contacts: Contact definitions; default: ``*_sole`` box sites, else the
            feet found from the collision geometry.
        keyframe: MJCF keyframe of the standing pose (default: the file's pose).

    Returns:
        The model, cached: the same inputs give the same object while they are
        among the last :func:`set_model_cache_size` loaded.

    Raises:
        ModelError: Not found (one message whatever the reason), not
            parseable, unsupported joints, no contacts or no such keyframe.
        ModelTooLarge: Over a cap of :mod:`~controller_server.models.description`
            (XML nesting and elements, bodies, DoF, file bytes, image pixels) or of
            ``protocol.messages`` (contacts and their points).
        FileTooLarge: A file over the size cap.

        Each detail names a file as the client knows it: by the name it sent, by the
        name the model gives it, or by its path relative to a model directory; no
        server directory (:func:`~controller_server.files.without_server_paths`).
    """
    # A name refused here is shown as the client sent it, as every name is (files.py).
    main_file = MODEL_FILES.read_bytes(model) if model_text is None and model is not None else None
    try:
        return _load(model, main_file, model_text, model_format, model_assets, contacts, keyframe)
    except ServerFault as exc:
        # The one way out for every error of a model: MuJoCo's and the system's
        # messages may quote a server directory, which no client may see.
        exc.detail = without_server_paths(exc.detail)
        exc.args = (f"{exc.field}: {exc.detail}",)
        raise


def _load(
    model: str | None,
    main_file: tuple[Path, bytes] | None,
    model_text: str | None,
    model_format: str,
    model_assets: dict[str, bytes] | None,
    contacts: list[ContactSpec] | None,
    keyframe: str | None,
) -> RobotModel:
    """:func:`load_robot_model` once a named model's file is read (``main_file``: path, bytes)."""
    if model_text is not None:
        text = model_text.encode()
        name = "client_model"
        files = dict(model_assets or {})
        read = _reader(files)
    elif model is not None and main_file is not None:
        path, text = main_file
        name = model if model in BUILTIN_MODELS else Path(model).stem
        if path.suffix.lower() == ".urdf":
            model_format = "urdf"
        read = _server_reader(path.parent)
    else:
        raise ModelError("no model given: set `model` or `model_text`")
    # Every file the model names is read now, so the cache key covers them all; for a
    # model on the server, why a file could not be read is kept for the messages.
    refused: dict[str, str] = {}

    def reading(name: str) -> bytes:
        try:
            return read(name)
        except DescriptionError as exc:
            if model_text is None:
                refused[name] = str(exc)
            raise

    try:
        files = gather_files(text, model_format, reading)
    except DescriptionLimitError as exc:
        raise ModelTooLarge(str(exc), field=exc.field) from None
    except DescriptionError as exc:
        raise ModelError(str(exc)) from None
    contacts_json = None if contacts is None else _contacts_json(contacts)
    return _load_cached(
        text,
        tuple(sorted(files.items())),
        name,
        model_format,
        contacts_json,
        keyframe,
        tuple(sorted(refused.items())),
    )


def _reader(files: dict[str, bytes], refused: dict[str, str] | None = None) -> FileReader:
    """Reads ``files`` only; a name in ``refused`` says why it could not be read."""

    def read(path: str) -> bytes:
        if refused and path in refused:
            raise DescriptionError(refused[path])
        if path not in files:
            raise DescriptionError(
                "it is not among the files sent with the model (`model_assets`); a sent "
                "model reads no other file"
            )
        return files[path]

    return read


def _server_reader(directory: Path) -> Callable[[str], bytes]:
    """Reads what a model in ``directory`` names, only from the model directories.

    Paths are relative to ``directory``. A ``package://`` URI is found as ROS
    tools find it (:func:`~controller_server.models.description.find_package`),
    but only in the model directories: the entries of the server's
    ``ROS_PACKAGE_PATH`` inside them, then the model's ancestors inside them.
    The file is then read under the same rule as any other (a path resolving
    outside is refused as a missing file is). The server reads no ``file://``
    URI.
    """
    roots = model_directories()
    search_path = [entry for entry in ros_package_path() if _inside_any(entry, roots)]
    packages: dict[str, Path | None] = {}

    def read(name: str) -> bytes:
        try:
            path = resolve_file(
                name,
                directory,
                search_path=search_path,
                within=roots,
                file_uris=False,
                packages=packages,
            )
        except DescriptionError:
            raise DescriptionError(
                f"it is not a readable file in the server's model directories "
                f"({display_name(name)} names no file in them)"
            ) from None
        try:
            return MODEL_ASSET_FILES.read_bytes(str(path))[1]
        except FileTooLarge as exc:
            raise DescriptionError(exc.detail) from None
        except ServerFault:
            # Not the refusal's text: it would quote the resolved, absolute path.
            raise DescriptionError(
                f"it is not a readable file in the server's model directories "
                f"({display_name(name)} names no {' or '.join(MODEL_ASSET_FILES.suffixes)} "
                "file in them)"
            ) from None

    return read


def _inside_any(path: Path, roots: tuple[Path, ...]) -> bool:
    try:
        resolved = path.resolve()
    except (OSError, RuntimeError):
        return False
    return any(resolved.is_relative_to(root) for root in roots)


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


def _load_uncached(
    text: bytes,
    files: tuple[tuple[str, bytes], ...],
    name: str,
    fmt: str,
    contacts_json: str | None,
    keyframe: str | None,
    refused: tuple[tuple[str, str], ...] = (),
) -> RobotModel:
    contacts = (
        None
        if contacts_json is None
        else [ContactSpec.model_validate(c) for c in json.loads(contacts_json)]
    )
    try:
        description = describe(
            text,
            fmt,
            read=_reader(dict(files), dict(refused)),
            name=name,
            contacts=contacts,
            keyframe=keyframe,
        )
    except FrameNotFoundError as exc:
        raise FrameNotFound(exc.frame, exc.available) from None
    except DescriptionLimitError as exc:
        raise ModelTooLarge(str(exc), field=exc.field) from None
    except DescriptionError as exc:
        raise ModelError(str(exc), field=exc.field) from None
    model = description.model
    torque_limit = description.torque_limit
    model.effortLimit[6:] = torque_limit
    contacts = tuple(_resolve(c, model) for c in description.contacts)
    joints = _joint_infos(model, torque_limit)
    return RobotModel(
        name=name,
        model=model,
        model_hash=_hash(
            text, dict(files), _contacts_json([c.to_spec() for c in contacts]), keyframe
        ),
        joints=joints,
        contacts=contacts,
        torque_limit=torque_limit,
        standing_configuration=description.standing_configuration,
        ball_swing_limit={
            info.name: description.ball_swing_limit.get(info.name, np.pi)
            for info in joints
            if info.kind == "ball"
        },
        description=description,
    )


_load_cached = lru_cache(maxsize=DEFAULT_MODEL_CACHE_SIZE)(_load_uncached)
