"""URDF through Pinocchio's parser: links, collision shapes, torque limits, the SRDF.

Collision meshes are loaded by MuJoCo; one that cannot be read is recorded, for ``describe``
to leave out or refuse.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pinocchio as pin

from controller_server.models.description.bodies import Body, Draft, UnreadableMesh
from controller_server.models.description.files import FileReader
from controller_server.models.description.limits import (
    DescriptionError,
    DescriptionLimitError,
    check_size,
)
from controller_server.models.description.mjcf import Cost, mujoco_message, parse_xml, safe_suffix
from controller_server.models.description.shapes import (
    GEOM,
    mesh_vertices,
    placed,
    se3,
    shape_points,
)
from controller_server.models.description.srdf import find_srdf, read_srdf

__all__ = [
    "read_urdf",
]


def read_urdf(text: bytes | str, read: FileReader | None, name: str) -> Draft:
    """A URDF parsed by Pinocchio, its collision shapes and SRDF read, for ``describe``."""
    root = parse_xml(text, "the URDF")
    if root.tag != "robot":
        raise DescriptionError(f"a URDF file's root element is <robot>, not <{root.tag}>")
    check_size(len(root.findall("link")), 0, "links")
    try:
        model = pin.buildModelFromXML(
            text.decode() if isinstance(text, bytes) else text, pin.JointModelFreeFlyer()
        )
    except (RuntimeError, ValueError, IndexError) as exc:
        message = str(exc).partition("message:")[2] or str(exc)
        raise DescriptionError(
            f"Pinocchio could not parse the URDF {name!r}: {' '.join(message.split())}"
        ) from None
    check_size(len(root.findall("link")), model.nv, "links")
    read = _counting(read)
    root_offset = model.jointPlacements[1].copy()
    model.jointPlacements[1] = pin.SE3.Identity()
    torque_limit = np.asarray(model.effortLimit[6:], dtype=float).copy()
    torque_limit[torque_limit <= 0] = np.inf
    model.effortLimit[6:] = torque_limit
    links = {link.get("name", ""): link for link in root.iter("link")}
    parents = {
        j.find("child").get("link"): j.find("parent").get("link")
        for j in root.iter("joint")
        if j.find("child") is not None and j.find("parent") is not None
    }
    order = [f.name for f in model.frames if f.type == pin.BODY and f.name in links]
    warnings: list[str] = []
    unreadable: list[UnreadableMesh] = []
    bodies: list[Body] = []
    for name in order:
        shapes = []
        for collision in links[name].findall("collision"):
            shape, problem = _urdf_collision_shape(collision, read)
            if problem is not None:
                unreadable.append(UnreadableMesh(name, *problem))
            if shape is not None:
                shapes.append(shape)
        parent_name = parents.get(name)
        parent = next((i for i, b in enumerate(bodies) if b.name == parent_name), -1)
        bodies.append(Body.with_shapes(name, parent, model.getFrameId(name, pin.BODY), shapes))
    q = pin.neutral(model)
    q[:3] = root_offset.translation
    q[3:7] = pin.Quaternion(root_offset.rotation).coeffs()
    kinds = {
        model.names[i]: "effort" if np.isfinite(torque_limit[model.joints[i].idx_v - 6]) else "none"
        for i in range(2, model.njoints)
    }
    warnings += [
        f"joint {name!r} has no <limit effort>" for name, kind in kinds.items() if kind == "none"
    ]
    keyframes: dict[str, np.ndarray] = {}
    disabled: tuple[tuple[str, str], ...] = ()
    found = find_srdf(root, read)
    if found is not None:
        keyframes, disabled, srdf_warnings = read_srdf(*found, root, model, q)
        warnings += srdf_warnings
    draft = Draft(model, bodies, torque_limit, kinds, {}, q, keyframes, [], warnings)
    draft.unreadable_meshes = unreadable
    draft.disabled_collision_pairs = disabled
    return draft


def _counting(read: FileReader | None) -> FileReader | None:
    """``read``, refusing once the bytes it returned exceed :data:`MAX_ASSET_BYTES`.

    A URDF names a mesh once per collision element, and each naming is loaded by MuJoCo.
    """
    if read is None:
        return None
    cost = Cost()

    def counted(path: str) -> bytes:
        data = read(path)
        cost.add_file(path, data, 1)
        return data

    return counted


def _urdf_collision_shape(
    collision: ET.Element, read: FileReader | None
) -> tuple[np.ndarray | None, tuple[str, str] | None]:
    """A URDF ``<collision>``'s points and radii in its link frame (meshes read by MuJoCo).

    Returns:
        The shape (``None``: none, or an unreadable mesh), and for an unreadable
        mesh its ``filename`` and why it cannot be read.
    """
    origin = collision.find("origin")
    xyz = np.array((origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split(), float)
    rpy = np.array((origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split(), float)
    rotation = pin.rpy.rpyToMatrix(*rpy)
    geometry = collision.find("geometry")
    shape = None if geometry is None or len(geometry) == 0 else geometry[0]
    if shape is None:
        return None, None

    def numbers(key: str) -> np.ndarray:
        return np.array(shape.get(key, "1 1 1").split(), float)

    if shape.tag == "box":
        local = shape_points(GEOM.mjGEOM_BOX, numbers("size") / 2, None)
    elif shape.tag == "sphere":
        local = shape_points(GEOM.mjGEOM_SPHERE, np.array([float(shape.get("radius", 0))]), None)
    elif shape.tag == "cylinder":
        radius, length = float(shape.get("radius", 0)), float(shape.get("length", 0))
        local = shape_points(GEOM.mjGEOM_CYLINDER, np.array([radius, length / 2]), None)
    elif shape.tag == "mesh":
        try:
            local = _urdf_mesh_points(shape, read)
        except DescriptionLimitError:
            raise
        except DescriptionError as exc:
            return None, (shape.get("filename", ""), str(exc))
    else:
        return None, None
    return (None if local is None else placed(local, pin.SE3(rotation, xyz))), None


def _urdf_mesh_points(mesh: ET.Element, read: FileReader | None) -> np.ndarray | None:
    """A URDF mesh's vertices (scaled, own frame), loaded by MuJoCo.

    Raises:
        DescriptionError: The file cannot be read, or MuJoCo cannot load it.
    """
    filename = mesh.get("filename", "")
    key = f"mesh{safe_suffix(filename)}"  # the file's name never reaches MuJoCo's parser
    data = _read_or_say_why(read, filename)
    try:
        # Numbers only into the XML: the URDF's text never reaches MuJoCo's parser.
        scale = " ".join(repr(float(x)) for x in mesh.get("scale", "1 1 1").split()[:3])
        xml = (
            f'<mujoco><asset><mesh name="m" file="{key}" scale="{scale}"/></asset>'
            '<worldbody><geom type="mesh" mesh="m"/></worldbody></mujoco>'
        )
        mj = mujoco.MjSpec.from_string(xml, assets={key: data}).compile()
    except ValueError as exc:
        detail = mujoco_message(exc, {key: filename})
        raise DescriptionError(f"MuJoCo cannot load {filename!r}: {detail}") from None
    shape = shape_points(GEOM.mjGEOM_MESH, np.zeros(3), mesh_vertices(mj, 0))
    return None if shape is None else placed(shape, se3(mj.geom_pos[0], mj.geom_quat[0]))


def _read_or_say_why(read: FileReader | None, path: str) -> bytes:
    """``read(path)``; a file that cannot be read raises why, with the path tried.

    Raises:
        DescriptionError: Why the file cannot be read (no reader, the reader's
            refusal, the system's error and the file tried).
    """
    if read is None:
        raise DescriptionError("no file was given with the model")
    try:
        return read(path)
    except DescriptionError:
        raise
    except OSError as exc:
        reason = exc.strerror or str(exc)
        tried = f" (tried {str(exc.filename)!r})" if exc.filename is not None else ""
        raise DescriptionError(f"{reason}{tried}") from None
    except (KeyError, ValueError) as exc:
        raise DescriptionError(str(exc)) from None
