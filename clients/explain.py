"""One line per file a user wrote: pydantic's validation errors with what to write instead.

Shared by every client that reads a user's TOML file (scenarios, bridge maps).
"""

from __future__ import annotations

from types import UnionType
from typing import Any, Union, get_args, get_origin

from pydantic import BaseModel, ValidationError

from protocol.errors import did_you_mean

__all__ = ["explain"]


def explain(error: ValidationError, root: type[BaseModel]) -> str:
    """A file's validation errors on one line, each with what to write instead.

    An unknown key gets the closest known key of the table it is in ("did
    you mean"), a joint position given as a number the shape it needs; the
    others pydantic's message, the key path and the value given.

    Args:
        error: What pydantic found.
        root: The model the whole file validates as.
    """
    return "; ".join(_explain_one(details, root) for details in error.errors())


def _record_at(root: type[BaseModel], location: tuple[Any, ...]) -> type[BaseModel]:
    """The model of the table at ``location`` (field names, list indices, dict keys)."""
    current: Any = root
    for part in location:
        if isinstance(current, type) and issubclass(current, BaseModel):
            field = current.model_fields.get(str(part))
            if field is None:
                return root
            current = field.annotation
        else:  # an item of a list or a value of a dict: its (last) type argument
            arguments = [arg for arg in get_args(current) if arg is not type(None)]
            current = arguments[-1] if arguments else None
        # list[X] | None: unwrap the optional
        arguments = [arg for arg in get_args(current) if arg is not type(None)]
        if get_origin(current) in (Union, UnionType) and len(arguments) == 1:
            current = arguments[0]
    return current if isinstance(current, type) and issubclass(current, BaseModel) else root


def _explain_one(details: Any, root: type[BaseModel]) -> str:
    location = tuple(details["loc"])
    where = ".".join(str(part) for part in location)
    if details["type"] == "extra_forbidden":
        known = list(_record_at(root, location[:-1]).model_fields)
        hint = did_you_mean(str(location[-1]), known).rstrip()
        return f"unknown key {where!r}; {hint or 'known keys: ' + ', '.join(known)}"
    if location[:1] == ("initial_joint_position",) and len(location) == 2:
        return (
            f"{where} = {details['input']!r}: give a list with one number per coordinate of "
            "the joint, e.g. [0.3] for a hinge, [x, y, z, w] (a quaternion) for a ball joint"
        )
    if details["type"] == "missing":
        return f"missing key {where!r}"
    message = str(details["msg"]).removeprefix("Value error, ")
    return f"{where}: {message} (got {details['input']!r})" if where else message
