"""How a controller or behaviour declares a run-time parameter.

Its own module (not in :mod:`controller_server.controllers`) so that behaviours,
which declare parameters, and controllers, which host behaviours, both import it
without importing each other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = ["ParamSpec"]


@dataclass(frozen=True)
class ParamSpec:
    """A run-time parameter: its default, kind and allowed range.

    Attributes:
        default: Value when not set (``None`` for vectors derived from the model).
        kind: ``"float"``, ``"int"``, ``"bool"``, ``"vector"``, ``"choice"`` or ``"text"``.
        minimum: Smallest allowed value (floats, vector entries).
        maximum: Largest allowed value.
        choices: Allowed strings for ``"choice"``.
        doc: One line for docs and error messages, with the unit.
    """

    default: Any
    kind: str = "float"
    minimum: float = -math.inf
    maximum: float = math.inf
    choices: tuple[str, ...] = ()
    doc: str = ""
