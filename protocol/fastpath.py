"""The codec's fast path: readers compiled from the message models, for the 1 kHz messages.

pydantic validated a ``state`` in about 25 µs, most of it one Python
validator call and several numpy calls per array. A *reader* checks a
decoded msgpack map against the rules of the model — exact types, literal
values, integer and float constraints, string and list lengths, array
lengths, missing and unknown keys — checks every finite array of the message
at once with one vectorised ``|x| ≤ bound``, and builds the message as
``model_construct`` does.

A reader accepts only values of the exact type pydantic keeps as they are (a
``float`` field takes a ``float``, an array ``bytes``); anything else —
another type pydantic might convert, a value out of range, a NaN, a missing
or unknown key — raises :class:`Fallback`, and :func:`protocol.codec.decode`
runs pydantic, whose error names the field. So the fast path never accepts
what pydantic refuses and never words an error itself. A model with
validators of its own or a field of another kind (a union, a tuple, a mutable
default) gets no reader: pydantic reads it.

:func:`construct` is ``model_construct`` without its per-field alias lookups,
for the replies a server builds from its own, already checked, values.
"""

from __future__ import annotations

import enum
import math
import sys
import types
import typing
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np
from annotated_types import Ge, Gt, Le, MaxLen, MinLen
from pydantic import (
    AllowInfNan,
    BaseModel,
    BeforeValidator,
    PlainSerializer,
    Strict,
    WithJsonSchema,
)
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

from protocol.arrays import WIRE_DTYPE, ArrayRule, array_to_bytes

__all__ = ["Fallback", "Reader", "construct", "reader"]

Reader = Callable[[dict[str, Any]], BaseModel]
"""Builds a validated message from its decoded msgpack map, or raises :class:`Fallback`."""

_Pending = list[tuple[bytes, float]]
"""Arrays of the message still to check: their bytes and the bound on |x|."""
_Convert = Callable[[Any, _Pending], Any]
_FLOAT_MAX = sys.float_info.max
_INT_LIMIT = 2**63
_REQUIRED = object()
_IMMUTABLE_DEFAULTS = (int, float, str, bool, type(None))
_Model = TypeVar("_Model", bound=BaseModel)


class Fallback(Exception):
    """The fast path cannot vouch for this payload: pydantic validates it."""


class _Unsupported(Exception):
    """A field kind the readers do not handle: its model gets no reader."""


_FALLBACK = Fallback()
"""Raised as is: bad input is common in a fuzzer, and nothing is built for it. Its catcher,
:func:`protocol.codec.decode`, drops the traceback each raise adds, which would otherwise
keep every fallen-back request's frames alive."""


def _array_rule(annotation: Any, metadata: list[Any]) -> ArrayRule | None:
    """The rule of an array field (in its metadata or its ``Annotated`` type), else ``None``.

    Raises:
        _Unsupported: An array with validators or serialisers other than its own.
    """
    if typing.get_origin(annotation) is typing.Annotated:
        annotation, metadata = typing.get_args(annotation)[0], [*annotation.__metadata__, *metadata]
    if annotation is not np.ndarray:
        return None
    rules = [meta.func for meta in metadata if isinstance(meta, BeforeValidator)]
    others = [meta for meta in metadata if not isinstance(meta, BeforeValidator | WithJsonSchema)]
    if (
        len(rules) != 1
        or not isinstance(rules[0], ArrayRule)
        or len(others) != 1
        or not isinstance(others[0], PlainSerializer)
        or others[0].func is not array_to_bytes
        or not WIRE_DTYPE.isnative
        or (rules[0].bound is not None and not rules[0].finite)
    ):
        raise _Unsupported(annotation)
    return rules[0]


def _array_checks(rule: ArrayRule) -> tuple[int, float | None]:
    """Byte size the rule requires (0: any multiple of 8) and the bound on |x| (``None``: none)."""
    size = 0 if rule.length is None else rule.length * WIRE_DTYPE.itemsize
    if not rule.finite:
        return size, None
    return size, _FLOAT_MAX if rule.bound is None else min(rule.bound, _FLOAT_MAX)


def _constraints(metadata: list[Any]) -> tuple[Any, Any, bool, bool, int, int]:
    """The constraints in a field's metadata.

    Returns lower and upper bound (``None``: none), whether the lower one is
    strict, whether NaN/inf are refused, least and most length.

    Raises:
        _Unsupported: A constraint the readers do not know.
    """
    low = high = None
    strict_low = finite = False
    min_length, max_length = 0, sys.maxsize
    for meta in metadata:
        if isinstance(meta, Ge):
            low = meta.ge
        elif isinstance(meta, Gt):
            low, strict_low = meta.gt, True
        elif isinstance(meta, Le):
            high = meta.le
        elif isinstance(meta, MinLen):
            min_length = meta.min_length
        elif isinstance(meta, MaxLen):
            max_length = meta.max_length
        elif isinstance(meta, AllowInfNan):
            finite = not meta.allow_inf_nan
        elif not isinstance(meta, Strict):  # readers take exact types only anyway
            raise _Unsupported(meta)
    return low, high, strict_low, finite, min_length, max_length


def _convert(annotation: Any, metadata: list[Any]) -> _Convert:
    """A converter for one field: the value pydantic would produce, or :class:`Fallback`.

    Raises:
        _Unsupported: A field kind the readers do not handle.
    """
    rule = _array_rule(annotation, metadata)
    if rule is not None:
        size, bound = _array_checks(rule)

        def array(value: Any, pending: _Pending) -> Any:
            if type(value) is not bytes or len(value) % 8 or (size and len(value) != size):
                raise _FALLBACK
            if bound is not None:
                pending.append((value, bound))
            return np.frombuffer(value, WIRE_DTYPE)

        return array
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin in (typing.Union, types.UnionType) and len(args) == 2 and type(None) in args:
        inner = _convert(next(arg for arg in args if arg is not type(None)), metadata)
        return lambda value, pending: None if value is None else inner(value, pending)
    if origin is typing.Literal and all(type(arg) is str for arg in args):
        return _scalar(str, lambda value: value in args)
    low, high, strict_low, finite, min_length, max_length = _constraints(metadata)
    if annotation is int:
        if not all(bound is None or type(bound) is int for bound in (low, high)):
            raise _Unsupported(annotation)
        least = -_INT_LIMIT if low is None else low + strict_low
        most = _INT_LIMIT - 1 if high is None else high
        return _scalar(int, lambda value: least <= value <= most)
    if annotation is float:
        if not (finite or low is not None or high is not None):
            return _scalar(float, None)  # pydantic takes NaN and inf here
        least = -math.inf if low is None else low
        most = math.inf if high is None else high
        if strict_low:
            return _scalar(float, lambda value: math.isfinite(value) and least < value <= most)
        return _scalar(float, lambda value: math.isfinite(value) and least <= value <= most)
    if annotation is str:
        return _scalar(str, lambda value: min_length <= len(value) <= max_length)
    if annotation is bool and not metadata:
        return _scalar(bool, None)
    if isinstance(annotation, type) and issubclass(annotation, enum.IntEnum) and not metadata:
        members = annotation._value2member_map_

        def int_enum(value: Any, pending: _Pending) -> Any:
            if type(value) is not int or value not in members:
                raise _FALLBACK
            return members[value]

        return int_enum
    if origin is list and len(args) == 1 and args[0] in (bool, str, float):
        (item,) = args

        def plain_list(value: Any, pending: _Pending) -> Any:
            if type(value) is not list or not min_length <= len(value) <= max_length:
                raise _FALLBACK
            for entry in value:
                if type(entry) is not item:
                    raise _FALLBACK
            return value

        return plain_list
    if metadata:
        raise _Unsupported(metadata)
    if origin is list and len(args) == 1 and isinstance(args[0], type):
        build = _model_reader(args[0])

        def model_list(value: Any, pending: _Pending) -> Any:
            if type(value) is not list:
                raise _FALLBACK
            return [build(entry, pending) for entry in value]

        return model_list
    if origin is dict and args == (str, float):

        def float_map(value: Any, pending: _Pending) -> Any:
            if type(value) is not dict:
                raise _FALLBACK
            for key, entry in value.items():
                if type(key) is not str or type(entry) is not float:
                    raise _FALLBACK
            return value

        return float_map
    if isinstance(annotation, type):
        return _model_reader(annotation)
    raise _Unsupported(annotation)


def _scalar(kind: type, valid: Callable[[Any], bool] | None) -> _Convert:
    """A converter taking values of exactly ``kind`` for which ``valid`` holds."""

    def scalar(value: Any, pending: _Pending) -> Any:
        if type(value) is not kind or (valid is not None and not valid(value)):
            raise _FALLBACK
        return value

    return scalar


def _fields(model: type) -> dict[str, FieldInfo]:
    """The fields of a model a reader can build, as ``model_construct`` would.

    Raises:
        _Unsupported: Not a pydantic model, or one with validators, serialisers,
            aliases, extra fields or private attributes.
    """
    if not issubclass(model, BaseModel):
        raise _Unsupported(model)
    decorators = model.__pydantic_decorators__
    fields = model.model_fields
    if (
        decorators.model_validators
        or decorators.field_validators
        or decorators.field_serializers
        or decorators.model_serializers
        or model.model_config.get("extra") != "forbid"
        or model.__pydantic_post_init__
        or model.__private_attributes__
        or any(f.alias or f.validation_alias for f in fields.values())
    ):
        raise _Unsupported(model)
    return fields


def _model_reader(model: type) -> _Convert:
    """A converter building ``model`` from a map.

    Raises:
        _Unsupported: The model, or one of its fields, is of a kind readers do not handle.
    """
    plan = []
    for name, field in _fields(model).items():
        default = _REQUIRED if field.is_required() else field.default
        if field.default_factory is not None or (
            default is not _REQUIRED and type(default) not in _IMMUTABLE_DEFAULTS
        ):
            raise _Unsupported(model)  # pydantic copies such defaults: keep it simple
        rule = _array_rule(field.annotation, field.metadata)
        if rule is not None:  # inline, without a call: a tick's messages are mostly arrays
            plan.append((name, None, default, *_array_checks(rule)))
        else:
            plan.append((name, _convert(field.annotation, field.metadata), default, 0, None))
    names = frozenset(name for name, *_ in plan)
    new, set_attribute, frombuffer = object.__new__, object.__setattr__, np.frombuffer

    def build(payload: Any, pending: _Pending) -> Any:
        if type(payload) is not dict or not payload.keys() <= names:
            raise _FALLBACK
        values = {}
        for name, convert, default, size, bound in plan:
            if name not in payload:
                if default is _REQUIRED:
                    raise _FALLBACK
                values[name] = default
                continue
            value = payload[name]
            if convert is not None:
                values[name] = convert(value, pending)
                continue
            if type(value) is not bytes or len(value) % 8 or (size and len(value) != size):
                raise _FALLBACK
            if bound is not None:
                pending.append((value, bound))
            values[name] = frombuffer(value, WIRE_DTYPE)  # read-only, like pydantic's
        # What ``model_construct`` does for a model without aliases or private attributes.
        message = new(model)
        set_attribute(message, "__dict__", values)
        set_attribute(message, "__pydantic_fields_set__", set(payload))
        set_attribute(message, "__pydantic_extra__", None)
        set_attribute(message, "__pydantic_private__", None)
        return message

    return build


def _check_arrays(pending: _Pending) -> None:
    """Every pending array finite and within its bound: one check for all, else one each."""
    if not pending:
        return
    if len(pending) == 1:
        ((raw, bound),) = pending
        values = np.frombuffer(raw, WIRE_DTYPE)
    else:
        values = np.frombuffer(b"".join([raw for raw, _ in pending]), WIRE_DTYPE)
        bound = min([bound for _, bound in pending])
    if not values.size or np.abs(values).max() <= bound:  # False for NaN; inf exceeds any bound
        return
    for raw, bound in pending:  # some array exceeds the smallest bound: is it its own?
        values = np.frombuffer(raw, WIRE_DTYPE)
        if values.size and not np.abs(values).max() <= bound:
            raise _FALLBACK


def reader(model: type[BaseModel]) -> Reader | None:
    """The fast reader of a message class, or ``None`` if pydantic must read it."""
    try:
        build = _model_reader(model)
    except _Unsupported:
        return None

    def read(payload: dict[str, Any]) -> BaseModel:
        pending: _Pending = []
        message = build(payload, pending)
        _check_arrays(pending)
        return message

    return read


_DEFAULTS: dict[type[BaseModel], list[tuple[str, Any, Callable[[], Any] | None]]] = {}


def construct(cls: type[_Model], /, **values: Any) -> _Model:
    """``cls.model_construct(**values)`` for a model without aliases, three times faster.

    No validation: for messages built from values already checked. Missing
    fields take their defaults; names that are not fields are ignored, as
    ``model_construct`` ignores them.
    """
    defaults = _DEFAULTS.get(cls)
    if defaults is None:
        if any(f.alias or f.validation_alias for f in cls.model_fields.values()):
            raise TypeError(f"{cls.__name__} has aliases: use model_construct")
        defaults = _DEFAULTS[cls] = [
            (name, field.default, field.default_factory)  # type: ignore[misc]
            for name, field in cls.model_fields.items()
        ]
    fields = {}
    fields_set = set()
    for name, default, factory in defaults:
        if name in values:
            fields[name] = values[name]
            fields_set.add(name)
        elif factory is not None:
            fields[name] = factory()  # type: ignore[call-arg]
        elif default is not PydanticUndefined:
            fields[name] = default
    message = object.__new__(cls)
    object.__setattr__(message, "__dict__", fields)
    object.__setattr__(message, "__pydantic_fields_set__", fields_set)
    if not cls.__pydantic_root_model__:
        object.__setattr__(message, "__pydantic_extra__", None)
        object.__setattr__(message, "__pydantic_private__", None)
    return message
