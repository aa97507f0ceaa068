"""``poise list``: scenarios, models, controllers, a model's joints or bodies, one per line.

Without a category, every category: the items of those that need no model,
and how to ask for the others. A scenario's description is cut to one line
(the cut ends in "…", and a line on stderr says so); ``--full`` prints each whole,
wrapped under its name.
"""

from __future__ import annotations

import argparse
import sys
import textwrap

from controller_server.cli.common import CONTROLLER_NAMES, UsageError

__all__ = ["LIST_WHAT", "add_parsers"]

LIST_WHAT = ["scenarios", "models", "controllers", "joints", "bodies"]
"""What ``poise list`` lists; ``joints`` and ``bodies`` of one model."""

DESCRIPTION_CHARS = 80
"""A scenario's description on one line of ``poise list`` (``--full``: whole)."""
CUT = "…"

_MODEL_CATEGORIES = {
    "joints": "a model's joints in wire order, with the numbers initial_joint_position takes",
    "bodies": "a model's bodies: what a push may name",
}
"""The categories that list one model's items, and what they list."""


def _list(args: argparse.Namespace) -> int:
    """Print one line per item: scenarios, models, controllers, or a model's joints or bodies."""
    if args.what is None:
        lines = _every_category_lines(args.full)
    else:
        if args.what in ("joints", "bodies") and args.model is None:
            raise UsageError(f"name the model: poise list {args.what} MODEL (poise list models)")
        if args.what not in ("joints", "bodies") and args.model is not None:
            raise UsageError(f"poise list {args.what} takes no MODEL")
        lines = _list_lines(args.what, args.model, args.full)
    for line in lines:
        print(line)
    if any(line.endswith(CUT) for line in lines):
        print(  # on stderr: the items stay one per line for a script
            f"({CUT} descriptions cut to one line: `poise list scenarios --full` shows them whole)",
            file=sys.stderr,
        )
    return 0


def _every_category_lines(full: bool) -> list[str]:
    """Every category under a heading naming its own command; joints and bodies by their command."""
    lines = []
    for what in LIST_WHAT:
        if what in _MODEL_CATEGORIES:
            lines.append(f"{what} (poise list {what} MODEL): {_MODEL_CATEGORIES[what]}")
        else:
            lines.append(f"{what} (poise list {what}):")
            lines.extend(f"  {line}" for line in _list_lines(what, None, full))
    return lines


def _list_lines(what: str, model: str | None, full: bool = False) -> list[str]:
    if what == "scenarios":
        from clients.sim.scenario import builtin_scenario_names, load_scenario

        lines = []
        for name in builtin_scenario_names():
            description = " ".join(load_scenario(name).description.split())
            if full:
                lines.append(name)
                lines.extend(
                    textwrap.wrap(
                        description, 88, initial_indent=" " * 4, subsequent_indent=" " * 4
                    )
                )
                continue
            if len(description) > DESCRIPTION_CHARS:
                description = description[: DESCRIPTION_CHARS - 1] + CUT
            lines.append(f"{name:<26}{description}".rstrip())
        return lines
    if what == "models":
        from clients.physics.model_file import builtin_model_names

        return builtin_model_names()
    if what == "controllers":
        return [f"{name}{'  (default)' if name == 'momentum' else ''}" for name in CONTROLLER_NAMES]
    from clients.physics.model_file import body_names, hello_model
    from controller_server.errors import ModelError
    from controller_server.models import load_robot_model

    try:
        if what == "bodies":
            return body_names(str(model))
        robot = load_robot_model(**hello_model(str(model)))
    except FileNotFoundError as exc:
        raise UsageError(str(exc)) from exc
    except ModelError as exc:
        raise UsageError(f"{model}: {exc}") from exc
    # One line per joint in wire order, with what initial_joint_position takes for it.
    return [
        f"{joint.name:<26}{joint.kind:<11}"
        + ("4 numbers, a quaternion [x, y, z, w]" if joint.kind == "ball" else f"{joint.nq} number")
        for joint in robot.joints
    ]


def add_parsers(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``list``."""
    listing = commands.add_parser(
        "list",
        help="list built-in scenarios, models, controllers, or a model's joints or bodies",
        description="Print one line per item: the built-in scenarios (with their description), "
        "models and controllers; the joints of MODEL in wire order (with the numbers "
        "initial_joint_position takes for each), or the bodies of MODEL (what a push may name). "
        "MODEL is a built-in name or an .xml/.urdf file. Without a category: every category, "
        "each under a heading naming its command.",
    )
    listing.add_argument(
        "what",
        nargs="?",
        choices=LIST_WHAT,
        metavar="{" + ",".join(LIST_WHAT) + "}",
        help="the category (default: every category)",
    )
    listing.add_argument("model", nargs="?", metavar="MODEL", help="for joints and bodies")
    listing.add_argument(
        "--full",
        action="store_true",
        help="scenario descriptions whole, wrapped under each name (default: one line each)",
    )
    listing.set_defaults(handler=_list)
