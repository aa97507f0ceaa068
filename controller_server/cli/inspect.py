"""``poise inspect MODEL``: what Poise reads from a robot file, and a starter scenario.

Prints the joints in wire order with their limits and actuators, the
contacts with their points and where they came from, the mass, the standing
pose and the warnings, as the server and the simulators will see them (one
reading: :mod:`controller_server.models.description`). ``--write-scenario``
writes a scenario TOML that stands the robot in MuJoCo and pushes it.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from controller_server.cli.common import UsageError

if TYPE_CHECKING:
    from controller_server.models.description import RobotDescription

__all__ = ["add_parsers", "report_lines", "starter_scenario"]

STARTER_PUSH_SPEED_M_S = 0.1
"""The starter scenario's push changes the robot's speed by this much (impulse / mass)."""
_ACTUATOR_NOTES = {
    "position": "position servo: a torque motor in MuJoCo",
    "velocity": "velocity servo: a torque motor in MuJoCo",
    "general": "general actuator: refused in MuJoCo",
    "none": "no actuator",
}


def _inspect(args: argparse.Namespace) -> int:
    from clients.physics.model_file import describe_model
    from protocol.messages import ContactSpec

    contacts = (
        None
        if args.contacts is None
        else [ContactSpec(name=frame, frame=frame) for frame in args.contacts]
    )
    try:
        description = describe_model(
            args.model, contacts=contacts, keyframe=args.keyframe, srdf=args.srdf
        )
    except FileNotFoundError as exc:
        raise UsageError(str(exc)) from exc
    for line in report_lines(description):
        print(line)
    if args.write_scenario is not None:
        path = Path(args.write_scenario)
        if path.exists() and not args.force:
            raise UsageError(f"{path} exists; pass --force to replace it")
        # A scenario names its model relative to where `poise sim` runs, or absolutely.
        model = args.model
        if Path(model).suffix and path.resolve().parent != Path.cwd().resolve():
            model = str(Path(model).resolve())
        path.write_text(starter_scenario(description, model, args.contacts))
        print(f"wrote {path}: poise sim {path}")
    return 0


def report_lines(description: RobotDescription) -> list[str]:
    """The human-readable report of :func:`_inspect`, one string per line."""
    import numpy as np
    import pinocchio as pin

    model = description.model
    q = description.standing_configuration
    com = pin.centerOfMass(model, model.createData(), q)
    pose = f"keyframe {description.keyframe!r}" if description.keyframe else "the file's pose"
    lines = [
        f"{description.name}: {description.format.upper()}, {model.nq - 7} joint coordinates, "
        f"{description.total_mass:.2f} kg",
        f"standing pose: {pose}; base at ({q[0]:.3f}, {q[1]:.3f}, {q[2]:.3f}) m, "
        f"CM height {com[2]:.3f} m",
        f"keyframes: {', '.join(description.keyframes) or 'none'}",
        *_disabled_pairs_lines(description),
        "joints (wire order): name, kind, range (rad; prismatic: m), "
        "torque limit (N·m; prismatic: N), actuator",
    ]
    for joint_id in range(2, model.njoints):
        joint = model.joints[joint_id]
        name = model.names[joint_id]
        limit = description.torque_limit[joint.idx_v - 6]
        if joint.nq == 4:
            span = f"swing ≤ {description.ball_swing_limit.get(name, np.pi):.2f}"
        else:
            low, high = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
            span = f"[{low:.2f}, {high:.2f}]" if np.isfinite([low, high]).all() else "unlimited"
        kind = description.actuator_kind.get(name, "none")
        lines.append(
            f"  {name:<28} {_kind(joint):<10}{span:<18}"
            f"{f'{limit:g}' if np.isfinite(limit) else 'none':<8}"
            f"{_ACTUATOR_NOTES.get(kind, kind)}"
        )
    lines.append(
        f"contacts ({description.contacts_source}): name, body, sole points, "
        "sole length × width (m)"
    )
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    for contact in description.contacts:
        frame_id = model.getFrameId(contact.frame)
        frame = model.frames[frame_id]
        body = contact.frame if frame.type == pin.BODY else model.frames[frame.parentFrame].name
        length, width = _sole_size(data.oMf[frame_id], contact.points_in_frame)
        points = ", ".join(
            "(" + ", ".join(f"{c:.3f}" for c in point) + ")" for point in contact.points_in_frame
        )
        lines += [
            f"  {contact.name:<14} {body:<24} {len(contact.points_in_frame)} points  "
            f"{length:.3f} × {width:.3f}",
            f"    why: {contact.reason or description.contacts_source}",
            f"    points in frame {contact.frame} (m): {points}",
        ]
    lines += [f"warning: {warning}" for warning in description.warnings]
    return lines


def _disabled_pairs_lines(description: RobotDescription) -> list[str]:
    pairs = description.disabled_collision_pairs
    if not pairs:
        return []
    shown = ", ".join(f"{a}–{b}" for a, b in pairs[:3])
    return [
        f"disabled collision pairs (SRDF): {len(pairs)}: {shown}{', …' if len(pairs) > 3 else ''}"
    ]


def _sole_size(frame_in_world: object, points_in_frame: object) -> tuple[float, float]:
    """A sole's length along its frame's heading (x on the ground) and its width across (m)."""
    import numpy as np

    rotation = frame_in_world.rotation  # type: ignore[attr-defined]
    points = np.asarray(points_in_frame, float) @ rotation.T
    heading = rotation[:, 0] * (1.0, 1.0, 0.0)
    if np.linalg.norm(heading) < 1e-6:  # the frame's x points up or down: its z
        heading = rotation[:, 2] * (1.0, 1.0, 0.0)
    heading /= np.linalg.norm(heading)
    along = points @ heading
    across = points @ np.array([-heading[1], heading[0], 0.0])
    return float(np.ptp(along)), float(np.ptp(across))


def _kind(joint: object) -> str:
    shortname = joint.shortname()  # type: ignore[attr-defined]
    return (
        "ball"
        if "Spherical" in shortname
        else "prismatic"
        if "JointModelP" in shortname
        else ("revolute")
    )


def starter_scenario(
    description: RobotDescription, model: str, contacts: list[str] | None = None
) -> str:
    """A scenario TOML that stands the robot 5 s in MuJoCo with a push at 2 s."""
    push_N = round(description.total_mass * STARTER_PUSH_SPEED_M_S / 0.1, 1)
    root = description.bodies[0].name
    lines = [
        f"# Starter scenario for {description.name}, written by `poise inspect`.",
        '# Run it: poise sim THIS_FILE   (see the keys: docs/scenarios.md, "Scenario files")',
        f'name = "{description.name}_stand"',
        f'description = "{description.name} stands 5 s and takes a {push_N:g} N push for 0.1 s."',
        f"model = {_toml_string(model)}",
    ]
    if description.keyframe:
        lines.append(f"keyframe = {_toml_string(description.keyframe)}")
    elif description.keyframes:
        lines.append(
            f"# keyframe = {_toml_string(description.keyframes[0])}  "
            f"# the model's keyframes: {', '.join(description.keyframes)}"
        )
    lines += [
        'controller = "momentum"  # or "prioritized"',
        'backend = "mujoco"  # or "reference"',
        "duration_s = 5.0",
    ]
    if contacts:
        for frame in contacts:
            lines += [
                "",
                "[[contacts]]",
                f"name = {_toml_string(frame)}",
                f"frame = {_toml_string(frame)}",
            ]
    else:
        lines.append(
            f"# contacts: found from the {description.contacts_source}: "
            + ", ".join(f"{c.name} on {c.frame}" for c in description.contacts)
        )
    lines += [
        "",
        "[[pushes]]",
        f"body = {_toml_string(root)}",
        f"force_in_world_N = [{push_N:g}, 0.0, 0.0]",
        "start_s = 2.0",
        "duration_s = 0.1",
        "",
    ]
    return "\n".join(lines)


def _toml_string(text: str) -> str:
    import json

    return json.dumps(text)  # a JSON string is a TOML basic string


def add_parsers(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``inspect``."""
    parser = commands.add_parser(
        "inspect",
        help="show what Poise reads from a robot file (joints, limits, contacts, pose)",
        description="Print what the server and the simulators read from MODEL (a built-in "
        "name, or an MJCF — a scene with includes is fine — or URDF file): the joints in wire "
        "order with their ranges, torque limits and actuators, the contacts (each foot's body, "
        "sole points and size, and why it was chosen), the mass, the standing pose, the "
        "keyframes and warnings. A URDF's package:// meshes are found through "
        "ROS_PACKAGE_PATH, then the URDF's ancestor directories. "
        "--write-scenario writes a starter scenario for `poise sim`.",
    )
    parser.add_argument("model", metavar="MODEL", help="built-in name or .xml/.urdf file")
    parser.add_argument(
        "--keyframe",
        metavar="NAME",
        help="keyframe of the standing pose: an MJCF <key>, a URDF's SRDF group_state "
        "(default: the file's pose)",
    )
    parser.add_argument(
        "--srdf",
        metavar="FILE",
        help="a URDF's SRDF (keyframes, disabled collision pairs), instead of NAME.srdf beside "
        "the URDF or ../srdf/NAME.srdf (NAME: the URDF's <robot name>)",
    )
    parser.add_argument(
        "--contacts",
        nargs="+",
        metavar="FRAME",
        help="the feet's bodies (or sites), soles found from their collision geometry "
        "(default: found automatically)",
    )
    parser.add_argument(
        "--write-scenario", metavar="PATH", help="also write a starter scenario TOML here"
    )
    parser.add_argument("--force", action="store_true", help="replace an existing --write-scenario")
    parser.set_defaults(handler=_inspect)
