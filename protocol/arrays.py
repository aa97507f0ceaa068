"""Numeric arrays on the wire: little-endian float64 bytes.

Arrays travel as msgpack ``bin`` values holding ``<f8`` data, so a 45-DoF
state costs 360 bytes per vector instead of 45 msgpack floats, and decoding
is a single ``numpy.frombuffer``. In Python the fields are ``numpy`` arrays;
lists are accepted when a message is built in code.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from typing import Annotated, Any

import numpy as np
from pydantic import BeforeValidator, PlainSerializer, WithJsonSchema
from pydantic_core import PydanticCustomError

__all__ = [
    "MAX_ABS_ACCELERATION",
    "MAX_ABS_JOINT_POSITION",
    "MAX_ABS_POSITION_M",
    "MAX_ABS_TIME_S",
    "MAX_ABS_VELOCITY",
    "MAX_ABS_WRENCH",
    "WIRE_DTYPE",
    "Acceleration3",
    "ArrayRule",
    "FiniteArray",
    "FloatArray",
    "JointPositionArray",
    "Position3",
    "QuaternionXYZW",
    "Vector3",
    "Velocity3",
    "VelocityArray",
    "WrenchArray",
    "array_to_bytes",
    "bounded_array",
]

WIRE_DTYPE = np.dtype("<f8")

MAX_ABS_POSITION_M = 1e4
"""Largest base position coordinate a ``state`` may carry (m)."""
MAX_ABS_JOINT_POSITION = 1e3
"""Largest joint position (rad, or m for prismatic joints): multi-turn joints fit."""
MAX_ABS_VELOCITY = 1e3
"""Largest velocity entry (rad/s and m/s): about 10⁴ rpm, beyond any actuator."""
MAX_ABS_WRENCH = 1e6
"""Largest measured contact force or torque entry (N, N·m)."""
MAX_ABS_TIME_S = 1e12
"""Largest client time (s); Unix time fits."""
MAX_ABS_ACCELERATION = 1e4
"""Largest accelerometer entry (m/s²): about 1000 g, beyond any IMU's range."""


def array_to_bytes(array: np.ndarray) -> bytes:
    """Pack a float array as little-endian float64 bytes."""
    return np.ascontiguousarray(array, dtype=WIRE_DTYPE).tobytes()


def _parse(
    value: Any, *, length: int | None, finite: bool, bound: float | None = None
) -> np.ndarray:
    if type(value) is np.ndarray and value.dtype == np.float64 and value.ndim == 1:
        array = value.copy()  # the common case in code: no conversion, no shape checks
    elif isinstance(value, bytes | bytearray | memoryview):
        raw = value if type(value) is bytes else bytes(value)
        if len(raw) % WIRE_DTYPE.itemsize:
            raise PydanticCustomError(
                "bad_shape",
                "float64 array needs a multiple of 8 bytes, got {n} bytes",
                {"n": len(raw)},
            )
        # A read-only view of the immutable bytes: no copy on little-endian machines.
        array = np.frombuffer(raw, dtype=WIRE_DTYPE)
        if not WIRE_DTYPE.isnative:
            array = array.astype(np.float64)
    elif isinstance(value, np.ndarray | list | tuple):
        try:
            array = np.array(value, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise PydanticCustomError(
                "invalid_array", "expected numbers: {error}", {"error": str(exc)}
            ) from None
        if np.ndim(value) > 1 or (isinstance(value, np.ndarray) and value.ndim != 1):
            raise PydanticCustomError("bad_shape", "expected a flat (1-D) array", {})
    else:
        raise PydanticCustomError(
            "invalid_array",
            "expected float64 bytes (little-endian), got {kind}",
            {"kind": type(value).__name__},
        )
    if length is not None and array.size != length:
        raise PydanticCustomError(
            "bad_shape",
            "expected {expected} values, got {actual}",
            {"expected": length, "actual": array.size},
        )
    if finite and not np.isfinite(array).all():
        raise PydanticCustomError(
            "non_finite",
            "values must be finite, got NaN/inf at index {index}",
            {"index": int(np.flatnonzero(~np.isfinite(array))[0])},
        )
    if bound is not None and array.size and np.abs(array).max() > bound:
        index = int(np.argmax(np.abs(array)))
        raise PydanticCustomError(
            "out_of_range",
            "|value| must be at most {bound}, got {value} at index {index}",
            {"bound": f"{bound:g}", "value": f"{float(array[index]):.3g}", "index": index},
        )
    if array.flags.writeable:
        array.setflags(write=False)
    return array


@dataclass(frozen=True)
class ArrayRule:
    """What an array field accepts: its length (any if ``None``), finiteness, bound on |x|.

    The pydantic validator of every array field. Bytes off the wire that pass
    take two numpy calls (a view, one ``max |x|``); anything else, and every
    problem, goes through the full parse, whose error names what is wrong.
    """

    length: int | None
    finite: bool
    bound: float | None = None
    _limit: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        limit = sys.float_info.max if self.bound is None else min(self.bound, sys.float_info.max)
        object.__setattr__(self, "_limit", limit)

    def __call__(self, value: Any) -> np.ndarray:
        """Parse and check one value (pydantic's ``BeforeValidator``)."""
        if (
            type(value) is bytes
            and WIRE_DTYPE.isnative
            and not len(value) % WIRE_DTYPE.itemsize
            and (self.length is None or len(value) == self.length * WIRE_DTYPE.itemsize)
        ):
            array = np.frombuffer(value, dtype=WIRE_DTYPE)  # read-only, like the full parse's
            if (not self.finite and self.bound is None) or not array.size:
                return array
            if np.abs(array).max() <= self._limit:  # False for NaN; inf exceeds any limit
                return array
        return _parse(value, length=self.length, finite=self.finite, bound=self.bound)


def _array_type(length: int | None, finite: bool, bound: float | None = None) -> Any:
    return Annotated[
        np.ndarray,
        BeforeValidator(ArrayRule(length, finite, bound)),
        PlainSerializer(array_to_bytes, return_type=bytes),
        WithJsonSchema(
            {"type": "string", "format": "binary", "description": "little-endian float64"}
        ),
    ]


def bounded_array(bound: float, length: int | None = None) -> Any:
    """A finite float64 array whose every entry satisfies ``|x| <= bound``.

    Requests use it for magnitudes no robot reaches (a joint turning at 10⁴
    rad/s is a client bug, not a state): refused at the edge with the field
    named, before a controller sees them.
    """
    return _array_type(length, finite=True, bound=bound)


FloatArray = _array_type(None, finite=False)
"""Any-length float64 array; NaN/inf allowed (used in replies only)."""
FiniteArray = _array_type(None, finite=True)
"""Any-length float64 array that must be finite (all request arrays)."""
Vector3 = _array_type(3, finite=True)
"""Three finite float64 values."""
QuaternionXYZW = _array_type(4, finite=True)
"""Unit quaternion, scalar last ``[x, y, z, w]`` (normalised by the server)."""

# Request arrays with the magnitudes of the wire contract (docs/protocol.md).
JointPositionArray = bounded_array(MAX_ABS_JOINT_POSITION)
VelocityArray = bounded_array(MAX_ABS_VELOCITY)
Velocity3 = bounded_array(MAX_ABS_VELOCITY, 3)
Position3 = bounded_array(MAX_ABS_POSITION_M, 3)
WrenchArray = bounded_array(MAX_ABS_WRENCH)
Acceleration3 = bounded_array(MAX_ABS_ACCELERATION, 3)
