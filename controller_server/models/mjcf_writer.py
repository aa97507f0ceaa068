"""Write a robot of box bodies as MJCF that Pinocchio and MuJoCo read alike (the built-ins).

:class:`Body` and :class:`Joint` describe a tree of solid boxes of uniform density;
:func:`render` writes it with the conventions of
:mod:`controller_server.models.build_mjcf` (one box geom and an explicit inertial per body,
joints at body origins, motors per DoF, sole sites on the feet).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = [
    "Body",
    "Joint",
    "Vec3",
    "box_inertia_kgm2",
    "fmt",
    "pitch_quat",
    "render",
    "render_body",
    "side",
    "water_box_m",
]

Vec3 = tuple[float, float, float]

WATER_DENSITY_KG_M3 = 1000.0
FOOT_FRICTION = "0.8 0.005 0.0001"
SOLE_HALF_THICKNESS_M = 0.001


@dataclass(frozen=True)
class Joint:
    """A non-root joint at its body's origin.

    Attributes:
        name: Joint name (also the motor name, or the motor name prefix for ball joints).
        kind: ``"hinge"`` or ``"ball"``.
        range_rad: Hinge ``(lo, hi)``; for a ball joint ``(0, max_swing)``.
        torque_limit_nm: Symmetric motor torque limit per DOF in N·m.
        axis: Hinge axis in the body frame (ignored for ball joints).
    """

    name: str
    kind: str
    range_rad: tuple[float, float]
    torque_limit_nm: float
    axis: Vec3 = (0.0, 1.0, 0.0)


@dataclass
class Body:
    """A rigid body carrying one solid box.

    Attributes:
        name: Body name.
        pos_m: Body origin in the parent body frame.
        size_m: Full box extents along the body x, y, z axes.
        mass_kg: Box mass.
        center_m: Box center (= center of mass) in the body frame.
        joint: Joint connecting the body to its parent (None only for the root).
        children: Child bodies.
        quat: Optional body orientation in the parent frame (w, x, y, z).
        sole: Whether this is a foot: adds the sole site and foot friction.
    """

    name: str
    pos_m: Vec3
    size_m: Vec3
    mass_kg: float
    center_m: Vec3
    joint: Joint | None
    children: list[Body] = field(default_factory=list)
    quat: tuple[float, float, float, float] | None = None
    sole: bool = False


def water_box_m(mass_kg: float, x_m: float | None, y_m: float | None, z_m: float | None) -> Vec3:
    """Return full box extents of water density, solving the one extent given as None."""
    given = [x_m, y_m, z_m]
    solved_m = mass_kg / (WATER_DENSITY_KG_M3 * math.prod(d for d in given if d is not None))
    x, y, z = (solved_m if d is None else d for d in given)
    return (x, y, z)


def box_inertia_kgm2(mass_kg: float, size_m: Vec3) -> Vec3:
    """Return the principal moments of a solid box of full extents ``size_m`` about its center."""
    a, b, c = size_m
    return (
        mass_kg * (b * b + c * c) / 12,
        mass_kg * (a * a + c * c) / 12,
        mass_kg * (a * a + b * b) / 12,
    )


def pitch_quat(angle_rad: float) -> tuple[float, float, float, float]:
    """Return the (w, x, y, z) quaternion of a rotation by ``angle_rad`` about +y."""
    return (math.cos(angle_rad / 2), 0.0, math.sin(angle_rad / 2), 0.0)


def fmt(*values: float) -> str:
    """Format numbers compactly and deterministically (12 significant digits, no -0)."""
    return " ".join("0" if abs(v) < 1e-15 else f"{v:.12g}" for v in values)


def side(sign: float) -> str:
    """``left`` for a positive sign, else ``right``."""
    return "left" if sign > 0 else "right"


def render_body(body: Body, depth: int, lines: list[str], joints: list[Joint]) -> None:
    """Append ``body`` and its subtree to ``lines`` at ``depth``, its joints to ``joints``."""
    pad = "  " * depth
    quat = f' quat="{fmt(*body.quat)}"' if body.quat is not None else ""
    lines.append(f'{pad}<body name="{body.name}" pos="{fmt(*body.pos_m)}"{quat}>')
    inner, joint = pad + "  ", body.joint
    if joint is None:
        lines.append(f'{inner}<freejoint name="root"/>')
    else:
        joints.append(joint)
        axis = f' axis="{fmt(*joint.axis)}"' if joint.kind == "hinge" else ""
        lines.append(
            f'{inner}<joint name="{joint.name}" type="{joint.kind}"{axis} '
            f'limited="true" range="{fmt(*joint.range_rad)}"/>'
        )
    half_m = tuple(v / 2 for v in body.size_m)
    inertia = box_inertia_kgm2(body.mass_kg, body.size_m)
    lines.append(
        f'{inner}<inertial pos="{fmt(*body.center_m)}" mass="{fmt(body.mass_kg)}" '
        f'diaginertia="{fmt(*inertia)}"/>'
    )
    friction = f' friction="{FOOT_FRICTION}"' if body.sole else ""
    rgba = "0.25 0.25 0.3 1" if body.sole else "0.7 0.7 0.75 1"
    lines.append(
        f'{inner}<geom name="{body.name}_box" type="box" size="{fmt(*half_m)}" '
        f'pos="{fmt(*body.center_m)}" contype="1" conaffinity="0"{friction} '
        f'rgba="{rgba}"/>'
    )
    if body.sole:  # the site is the bottom face of the foot box
        (cx, cy, cz), (hx, hy, hz) = body.center_m, half_m
        site = body.name.replace("_foot", "_sole")
        lines.append(
            f'{inner}<site name="{site}" type="box" pos="{fmt(cx, cy, cz - hz)}" '
            f'size="{fmt(hx, hy, SOLE_HALF_THICKNESS_M)}"/>'
        )
    for child in body.children:
        render_body(child, depth + 1, lines, joints)
    lines.append(f"{pad}</body>")


def render(model_name: str, root: Body) -> str:
    """Render a body tree as an MJCF document with one motor per actuated DOF."""
    lines = [
        "<!-- Generated by controller_server/models/build_mjcf.py: edit that script, "
        "not this file. -->",
        f'<mujoco model="{model_name}">',
        '  <compiler angle="radian"/>',
        '  <option timestep="0.001" gravity="0 0 -9.81"/>',
        "  <worldbody>",
        '    <geom name="floor" type="plane" size="0 0 1" contype="0" conaffinity="1"/>',
    ]
    joints: list[Joint] = []
    render_body(root, 2, lines, joints)
    lines += ["  </worldbody>", "  <actuator>"]
    for joint in joints:
        limit_nm = joint.torque_limit_nm
        limit = f'ctrllimited="true" ctrlrange="{fmt(-limit_nm, limit_nm)}"'
        if joint.kind == "hinge":
            lines.append(f'    <motor name="{joint.name}" joint="{joint.name}" gear="1" {limit}/>')
        else:
            for axis, gear in (("x", "1 0 0 0 0 0"), ("y", "0 1 0 0 0 0"), ("z", "0 0 1 0 0 0")):
                lines.append(
                    f'    <motor name="{joint.name}_{axis}" joint="{joint.name}" '
                    f'gear="{gear}" {limit}/>'
                )
    lines += ["  </actuator>", "</mujoco>", ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# (a) Thesis humanoid: de Leva (1996) male segments scaled to 1.70 m / 65 kg, water density.
# --------------------------------------------------------------------------------------------
