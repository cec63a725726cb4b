"""Any ROS message <-> plain dict / JSON / YAML, generic over fields.

``rosidl_runtime_py`` (message_to_yaml, set_message_fields) is not on PyPI, so this module
does the same job from rclpy's own introspection: each generated message class carries
``get_fields_and_field_types()`` (field names in order) and ``SLOT_TYPES`` (the
``rosidl_parser.definition`` type of each field). A per-class field plan is built once and
cached, so converting a message walks a flat list.

Representation (documented in README.md):

* nested messages -> dicts in field order; constants are not fields and are not included;
* fixed arrays (numpy) and sequences (``array.array``/list) -> lists;
* ``uint8[]``/``byte[]``/``char[]`` (and fixed ``uint8[N]``) -> a base64 string in JSON
  (compact, the rosbridge convention) but a list of ints in YAML (``ros2 topic echo``);
  on input both a base64 string and a list of ints are accepted;
* a single ``byte`` -> int; ``builtin_interfaces/Time`` and ``Duration`` -> ``{"sec",
  "nanosec"}``; on input a number of seconds is accepted too;
* float NaN/inf stay NaN/inf (Python's json writes ``NaN``/``Infinity``).

Input is checked strictly: unknown keys, wrong JSON types (a string for a number, a float with
a fraction for an integer, a bool for a number), integers outside their type's range, wrong
array lengths and over-long bounded strings each raise `CodecError` naming the field path.
"""

from __future__ import annotations

import array
import base64
import binascii
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

from bridge.codecs.errors import CodecError
from bridge.codecs.registry import message_class, resolve_type, ros_type_of
from protocol.commands import FieldDescription, MessageDescription, WrongTypeError
from protocol.yaml_text import to_yaml

__all__ = [
    "document_to_json",
    "check_float",
    "check_int",
    "describe_message",
    "dict_to_message",
    "is_message",
    "json_to_message",
    "list_of",
    "message_from_json",
    "message_to_dict",
    "message_to_json",
    "message_to_yaml",
    "numeric_array",
]

JsonValue = Any  # str | bool | int | float | None | list | dict (recursive)

# Integer ranges and numpy dtypes of the ROS basic types.
_INT_RANGES: dict[str, tuple[int, int]] = {
    "int8": (-(2**7), 2**7 - 1),
    "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
    "octet": (0, 255),
}
_DTYPES: dict[str, str] = {
    "float": "<f4", "double": "<f8", "long double": "<f8",
    "int8": "i1", "uint8": "u1", "int16": "<i2", "uint16": "<u2",
    "int32": "<i4", "uint32": "<u4", "int64": "<i8", "uint64": "<u8",
}
_TYPECODES: dict[str, str] = {
    "float": "f", "double": "d", "int8": "b", "uint8": "B", "int16": "h", "uint16": "H",
    "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q",
}
_FLOAT32_MAX = float(np.finfo(np.float32).max)
_BYTE_TYPES = ("uint8", "octet", "char")
_TIME_TYPES = ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration")


# --------------------------------------------------------------------------- field plans

@dataclass(frozen=True)
class _Field:
    """How one field of one message class is read and written."""

    name: str
    kind: str  # "bool" | "int" | "float" | "str" | "octet" | "char" | "msg"
    base: str  # basic type name ("int32", "double", "octet"...) or "pkg/msg/Type"
    container: str | None  # None | "array" (fixed size) | "sequence"
    size: int | None  # array length, or bounded-sequence maximum
    max_string: int | None  # bounded string maximum length


def _basic_kind(t: Any) -> tuple[str, str, int | None]:
    from rosidl_parser import definition as rdef  # ROS's: only rclpy messages have plans

    if isinstance(t, rdef.BasicType):
        name = t.typename
        if name == "boolean":
            return "bool", name, None
        if name in ("float", "double", "long double"):
            return "float", name, None
        if name == "octet":
            return "octet", name, None
        if name in ("char", "wchar"):
            return "char", name, None
        return "int", name, None
    if isinstance(t, (rdef.AbstractString, rdef.AbstractWString)):
        return "str", "string", getattr(t, "maximum_size", None)
    if isinstance(t, rdef.NamespacedType):
        return "msg", "/".join([*t.namespaces, t.name]), None
    raise TypeError(f"unsupported ROS field type {t!r}")


@cache
def _plan(cls: Any) -> tuple[_Field, ...]:
    from rosidl_parser import definition as rdef  # ROS's: only rclpy messages have plans

    fields = []
    for name, slot in zip(cls.get_fields_and_field_types().keys(), cls.SLOT_TYPES):
        container: str | None = None
        size: int | None = None
        t = slot
        if isinstance(slot, rdef.Array):
            container, size, t = "array", slot.size, slot.value_type
        elif isinstance(slot, rdef.AbstractSequence):
            container, t = "sequence", slot.value_type
            size = getattr(slot, "maximum_size", None)
        kind, base, max_string = _basic_kind(t)
        fields.append(_Field(name, kind, base, container, size, max_string))
    return tuple(fields)


def is_message(value: Any) -> bool:
    """True for an rclpy message instance."""
    return hasattr(type(value), "get_fields_and_field_types") and not isinstance(value, type)


# --------------------------------------------------------------------------- to dict

def _bytes_out(raw: bytes, bytes_as: str) -> JsonValue:
    if bytes_as == "base64":
        return base64.b64encode(raw).decode("ascii")
    return list(raw)


def _value_out(f: _Field, v: Any, bytes_as: str) -> JsonValue:
    if f.container is None:
        if f.kind == "msg":
            return message_to_dict(v, bytes_as=bytes_as)
        if f.kind == "octet":
            return v[0] if isinstance(v, (bytes, bytearray)) else int(v)
        if f.kind == "float":
            return float(v)
        return v
    # Arrays and sequences.
    if f.base in _BYTE_TYPES:
        if isinstance(v, (np.ndarray, array.array)):
            raw = v.tobytes() if not isinstance(v, np.ndarray) else v.astype(np.uint8).tobytes()
        elif isinstance(v, (bytes, bytearray)):
            raw = bytes(v)
        else:  # list of 1-byte bytes (octet) or of ints / 1-char str (char)
            raw = bytes(x[0] if isinstance(x, (bytes, bytearray)) else
                        (ord(x) if isinstance(x, str) else int(x)) for x in v)
        return _bytes_out(raw, bytes_as)
    if f.kind == "msg":
        return [message_to_dict(x, bytes_as=bytes_as) for x in v]
    if isinstance(v, (np.ndarray, array.array)):
        return v.tolist()
    return list(v)


def message_to_dict(msg: Any, *, bytes_as: str = "base64") -> dict[str, JsonValue]:
    """A message as a plain dict (JSON-able), fields in declaration order.

    ``bytes_as``: ``"base64"`` (default, for JSON) or ``"list"`` (for YAML/readability) for
    ``uint8[]``/``byte[]`` fields.
    """
    if not is_message(msg):
        raise CodecError(field="message", expected="a ROS message", got=type(msg).__name__)
    # (mypy does not take a class for Hashable, which @cache's arguments must be.)
    return {f.name: _value_out(f, getattr(msg, f.name), bytes_as)
            for f in _plan(type(msg))}  # type: ignore[arg-type]


def message_to_json(msg: Any) -> str:
    """A message as compact JSON text (see `message_to_dict`)."""
    return document_to_json(message_to_dict(msg))


def document_to_json(document: Mapping[str, JsonValue]) -> str:
    """A message's dict (`message_to_dict`'s form) as compact JSON text."""
    return json.dumps(document, separators=(",", ":"), ensure_ascii=False)


def message_to_yaml(msg: Any) -> str:
    """A message as YAML in the style of ``ros2 topic echo`` (block style, field order,
    ``uint8[]`` as lists of ints)."""
    return to_yaml(message_to_dict(msg, bytes_as="list"))


# --------------------------------------------------------------------------- descriptions

# IDL names of basic types (what SLOT_TYPES carries) -> the names of .msg files.
_MSG_FILE_NAMES = {"boolean": "bool", "octet": "byte", "float": "float32", "double": "float64",
                   "long double": "float64", "wchar": "char"}


def describe_message(cls: Any, into: dict[str, MessageDescription]) -> str:
    """Add the description of message class `cls`, and of every message type it is made
    of, to `into` (keyed by ``pkg/msg/Type``); returns its own type name."""
    ros_type = ros_type_of(cls)
    if ros_type in into:
        return ros_type
    fields = []
    nested = []
    for f in _plan(cls):
        array = {None: None, "array": "fixed", "sequence": "sequence"}[f.container]
        fields.append(FieldDescription(f.name, _MSG_FILE_NAMES.get(f.base, f.base), array,
                                       f.size, f.max_string))
        if f.kind == "msg":
            nested.append(f.base)
    meta = type(cls)
    constants = getattr(meta, f"_{meta.__name__}__constants", {})
    into[ros_type] = MessageDescription(
        ros_type, tuple(fields), message_to_dict(cls()),
        {k: _value_of_constant(v) for k, v in constants.items() if not k.endswith("__DEFAULT")})
    for name in nested:
        describe_message(message_class(name), into)
    return ros_type


def _value_of_constant(value: Any) -> JsonValue:
    if isinstance(value, (bytes, bytearray)):
        return value[0] if len(value) == 1 else list(value)
    return value


# --------------------------------------------------------------------------- checks

def _describe(value: Any) -> str:
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{type(value).__name__} {text}"


def check_int(value: Any, field: str, base: str = "int64") -> int:
    """``value`` as an int of ROS type ``base`` (range checked), or `CodecError`.

    Integral floats (``3.0``) are accepted since JSON writers differ; bools are not.
    """
    low, high = _INT_RANGES[base]
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise CodecError(field=field, expected=f"an integer ({base})", got=_describe(value))
    if isinstance(value, (float, np.floating)) and not (
            math.isfinite(value) and float(value).is_integer()):
        raise CodecError(field=field, expected=f"an integer ({base})", got=_describe(value))
    iv = int(value)
    if not low <= iv <= high:
        raise CodecError(field=field, expected=f"an integer in [{low}, {high}] ({base})",
                         got=str(iv))
    return iv


def check_float(value: Any, field: str, base: str = "double", *, finite: bool = False) -> float:
    """``value`` as a float (ints accepted, bools and strings not), or `CodecError`."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise CodecError(field=field, expected="a number", got=_describe(value))
    fv = float(value)
    if finite and not math.isfinite(fv):
        raise CodecError(field=field, expected="a finite number", got=repr(fv))
    if base == "float" and math.isfinite(fv) and abs(fv) > _FLOAT32_MAX:
        raise CodecError(field=field, expected="a number within float32 range", got=repr(fv))
    return fv


def _check_str(value: Any, field: str, max_len: int | None) -> str:
    if not isinstance(value, str):
        raise CodecError(field=field, expected="a string", got=_describe(value))
    if max_len is not None and len(value) > max_len:
        raise CodecError(field=field, expected=f"a string of at most {max_len} characters",
                         got=f"{len(value)} characters")
    return value


def _bytes_in(value: Any, field: str) -> bytes:
    if isinstance(value, str):
        try:
            return base64.b64decode(value.encode("ascii"), validate=True)
        except (binascii.Error, UnicodeEncodeError, ValueError):
            raise CodecError(field=field, expected="base64 text or a list of ints 0..255",
                             got=_describe(value)) from None
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    if isinstance(value, (list, tuple, np.ndarray)):
        arr = numeric_array(value, field, "uint8")
        return arr.astype(np.uint8).tobytes()
    raise CodecError(field=field, expected="base64 text or a list of ints 0..255",
                     got=_describe(value))


def _index_text(index: tuple[int, ...]) -> str:
    return "".join(f"[{i}]" for i in index)


def numeric_array(value: Any, field: str, base: str, *, ndim: int | None = 1) -> np.ndarray:
    """A (nested) list of numbers -> a checked numpy array of ROS type ``base``.

    ``ndim``: required number of dimensions (None: any rectangular nesting). Bools, strings,
    ragged nesting, fractions for integer types and out-of-range values raise `CodecError`
    naming the element (``data[1][2]``). Vectorised except for the Python-object type scan,
    which a list parsed from JSON needs anyway (numpy would silently turn True into 1).
    """
    if not isinstance(value, (list, tuple, np.ndarray, array.array)):
        raise CodecError(field=field, expected=f"a list of {base}", got=_describe(value))
    try:
        arr = np.asarray(value)
    except ValueError:
        raise CodecError(field=field, expected=f"a rectangular list of {base}",
                         got="a ragged nested list") from None
    if ndim is not None and arr.size == 0 and arr.ndim <= ndim:
        return np.zeros((0,) * ndim if arr.ndim < ndim else arr.shape, dtype=_DTYPES[base])
    if ndim is not None and arr.ndim != ndim:
        raise CodecError(field=field, expected=f"a {ndim}-D list of {base}",
                         got=f"shape {arr.shape}")
    if isinstance(value, (list, tuple)) or arr.dtype.kind not in "iuf":
        obj = np.empty(arr.shape, dtype=object)
        obj[...] = value if arr.ndim else arr.item()
        ok = np.frompyfunc(lambda x: isinstance(x, (int, float, np.integer, np.floating))
                           and not isinstance(x, (bool, np.bool_)), 1, 1)(obj)
        bad = np.argwhere(~np.asarray(ok, dtype=bool))
        if bad.size:
            idx = tuple(int(i) for i in bad[0])
            raise CodecError(field=field + _index_text(idx), expected=f"a number ({base})",
                             got=_describe(obj[idx]))
        exact_ints = base in _INT_RANGES and not any(
            isinstance(x, (float, np.floating)) for x in obj.flat)
        if arr.dtype.kind not in "iuf" or (exact_ints and arr.dtype.kind == "f"):
            # Python ints that numpy could not hold exactly (beyond 64 bits, or promoted to
            # float next to a huge one): check them as Python ints, no rounding.
            low, high = _INT_RANGES.get(base, (-(2**63), 2**64 - 1))
            out = np.argwhere(np.frompyfunc(lambda x: not low <= int(x) <= high, 1, 1)(obj)
                              .astype(bool))
            if out.size or base not in _INT_RANGES:
                idx = tuple(int(i) for i in out[0]) if out.size else ()
                raise CodecError(field=field + _index_text(idx),
                                 expected=f"an integer in [{low}, {high}] ({base})"
                                 if base in _INT_RANGES else f"a number ({base})",
                                 got=str(obj[idx]) if idx else "a huge integer")
            return obj.astype(_DTYPES[base])
    if base in _INT_RANGES:
        low, high = _INT_RANGES[base]
        if arr.dtype.kind == "f":
            bad = np.argwhere(~np.isfinite(arr) | (arr != np.round(arr)))
            if bad.size:
                idx = tuple(int(i) for i in bad[0])
                raise CodecError(field=field + _index_text(idx), expected=f"an integer ({base})",
                                 got=repr(float(arr[idx])))
        if arr.dtype.kind == "u":
            out = np.argwhere(arr > high)
        elif arr.dtype.kind == "f":  # float(high) may round up to high + 1: compare >= that
            out = np.argwhere((arr < low) | (arr >= float(high) + 1.0))
        else:
            out = np.argwhere((arr < low) | (arr > high))
        if out.size:
            idx = tuple(int(i) for i in out[0])
            raise CodecError(field=field + _index_text(idx),
                             expected=f"an integer in [{low}, {high}] ({base})",
                             got=str(arr[idx]))
    elif base == "float":
        big = np.argwhere(np.isfinite(arr) & (np.abs(arr.astype(np.float64)) > _FLOAT32_MAX))
        if big.size:
            idx = tuple(int(i) for i in big[0])
            raise CodecError(field=field + _index_text(idx),
                             expected="a number within float32 range", got=repr(float(arr[idx])))
    return arr.astype(_DTYPES[base])


# --------------------------------------------------------------------------- from dict

def _time_from_seconds(cls: Any, value: Any, field: str) -> Any:
    seconds = check_float(value, field, finite=True)
    sec = math.floor(seconds)
    nanosec = round((seconds - sec) * 1e9)
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, 0
    check_int(sec, f"{field}.sec", "int32")
    return cls(sec=sec, nanosec=nanosec)


def _single_in(f: _Field, value: Any, field: str) -> Any:
    if f.kind == "msg":
        cls = message_class(f.base)
        if f.base in _TIME_TYPES and not isinstance(value, Mapping):
            return _time_from_seconds(cls, value, field)
        return dict_to_message(cls, value, _path=field)
    if f.kind == "bool":
        if not isinstance(value, (bool, np.bool_)):
            raise CodecError(field=field, expected="true or false", got=_describe(value))
        return bool(value)
    if f.kind == "int":
        return check_int(value, field, f.base)
    if f.kind == "float":
        return check_float(value, field, f.base)
    if f.kind == "str":
        return _check_str(value, field, f.max_string)
    if f.kind == "octet":
        if isinstance(value, (bytes, bytearray)) and len(value) == 1:
            return bytes(value)
        return bytes([check_int(value, field, "octet")])
    if f.kind == "char":
        if isinstance(value, str) and len(value) == 1:
            value = ord(value)
        return check_int(value, field, "uint8")
    raise CodecError(field=field, expected="a supported field type", got=f.kind)


def _container_in(f: _Field, value: Any, field: str) -> Any:
    if f.base in _BYTE_TYPES:
        raw = _bytes_in(value, field)
        n = len(raw)
        arr_or_list: Any
        if f.kind == "octet":
            arr_or_list = [raw[i:i + 1] for i in range(n)]
        elif f.container == "array":
            arr_or_list = np.frombuffer(raw, dtype=np.uint8).copy()
        else:
            arr_or_list = array.array("B", raw)
        _check_length(f, n, field)
        return arr_or_list
    if f.kind in ("int", "float"):
        arr = numeric_array(value, field, f.base)
        _check_length(f, int(arr.size), field)
        if f.container == "array":
            return arr.astype(np.dtype(_DTYPES[f.base]).newbyteorder("="))
        out = array.array(_TYPECODES[f.base])
        out.frombytes(arr.astype(np.dtype(_DTYPES[f.base]).newbyteorder("=")).tobytes())
        return out
    if not isinstance(value, (list, tuple)):
        raise CodecError(field=field, expected="a list", got=_describe(value))
    _check_length(f, len(value), field)
    return [_single_in(f, item, f"{field}[{i}]") for i, item in enumerate(value)]


def _check_length(f: _Field, n: int, field: str) -> None:
    if f.container == "array" and n != f.size:
        raise CodecError(field=field, expected=f"exactly {f.size} elements", got=f"{n} elements")
    if f.container == "sequence" and f.size is not None and n > f.size:
        raise CodecError(field=field, expected=f"at most {f.size} elements", got=f"{n} elements")


def dict_to_message(ros_type_or_class: str | Any, d: Mapping[str, Any], *,
                    _path: str = "") -> Any:
    """Build a message from a dict as written by `message_to_dict` (missing fields keep
    their defaults). Raises `CodecError` naming the first bad field path."""
    if isinstance(ros_type_or_class, str):
        cls = message_class(resolve_type(ros_type_or_class))
    else:
        cls = ros_type_or_class
    where = _path or ros_type_of(cls)
    if not isinstance(d, Mapping):
        raise CodecError(field=where, expected=f"an object with the fields of {ros_type_of(cls)}",
                         got=_describe(d))
    plan = {f.name: f for f in _plan(cls)}
    unknown = [k for k in d if k not in plan]
    if unknown:
        key = unknown[0]
        raise CodecError(field=f"{_path}.{key}" if _path else str(key),
                         expected=f"a field of {ros_type_of(cls)}: {', '.join(plan) or '(none)'}",
                         got="an unknown field")
    msg = cls()
    for key, value in d.items():
        f = plan[key]
        field = f"{_path}.{key}" if _path else key
        converted = (_single_in(f, value, field) if f.container is None
                     else _container_in(f, value, field))
        try:
            setattr(msg, key, converted)
        except (AssertionError, TypeError, ValueError) as exc:  # the setter's own checks
            raise CodecError(field=field, expected=f"a valid {f.base}", got=str(exc)) from None
    return msg


def json_to_message(ros_type_or_class: str | Any, text: str | bytes) -> Any:
    """Parse JSON text into a message; bad JSON or bad fields raise `CodecError`."""
    try:
        value = json.loads(text)
    except (ValueError, UnicodeDecodeError) as exc:
        raise CodecError(field="text", expected="JSON text", got=f"invalid JSON ({exc})") from None
    return dict_to_message(ros_type_or_class, value)


def list_of(value: Any, field: str, expected: str = "a list") -> list[Any]:
    """``value`` if it is a list/tuple, else `CodecError`."""
    if not isinstance(value, (list, tuple)):
        raise CodecError(field=field, expected=expected, got=_describe(value))
    return list(value)


def message_from_json(cls: Any, data: dict[str, Any], path: str) -> Any:
    """A message of `cls` from a client's JSON fields; `WrongTypeError` naming the field
    under `path` (``request.data``)."""
    try:
        return dict_to_message(cls, data)
    except CodecError as error:
        raise WrongTypeError(f"{path}.{error.field}" if error.field else path,
                             error.expected, error.got) from None
