"""The typed JSON command schema spoken over OpenIGTLink COMMAND / RTS_COMMAND.

A request is a COMMAND message (header v2): its NAME is the op (``"create_subscriber"``),
its text a JSON object with the op's arguments, optionally ``"schema": 1``. The answer is an
RTS_COMMAND with the same command ID and NAME, a JSON `Reply`, and metadata ``Status``
(``SUCCESS``/``FAIL``, what 3D Slicer's ``igtlioCommand::GetSuccessful`` checks) plus
``ErrorMessage`` on failure. protocol/README.md lists every op with examples.

One frozen dataclass per op (``op`` is a literal class attribute), one union `Request`, an
IntEnum `ErrorCode` and one `CommandError` subclass per way a request can be refused; each
error names the field, what was expected and what came.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from enum import IntEnum
from typing import (
    Any,
    ClassVar,
    Literal,
    NewType,
    TypeVar,
    Union,
    cast,
)

from protocol.conversions import ConversionError, validate_matrix
from protocol.errors import ProtocolError

__all__ = [
    "COMMAND_DEVICE_NAME",
    "MAX_COMMAND_TEXT_BYTES",
    "MAX_JSON_DEPTH",
    "MAX_OP_NAME_BYTES",
    "METADATA_ERROR_MESSAGE",
    "METADATA_STATUS",
    "PARAMETER_TYPES",
    "REFERENCE_TYPE_NAMES",
    "REQUEST_TYPES",
    "SCHEMA_VERSION",
    "SLICER_MAX_COMMAND_TEXT_BYTES",
    "STATUS_FAIL",
    "STATUS_SUCCESS",
    "AdvertiseService",
    "BadJsonError",
    "BroadcastTransform",
    "CallService",
    "CommandError",
    "CommandFailedError",
    "CommandId",
    "CreateParameterClient",
    "CreatePublisher",
    "CreateRobot",
    "CreateSubscriber",
    "CreateTfBroadcaster",
    "CreateTfLookup",
    "ErrorCode",
    "ErrorInfo",
    "ForbiddenError",
    "GetLastMessage",
    "GetParameters",
    "Hello",
    "ListBridges",
    "ListParameters",
    "ListRobots",
    "ListServices",
    "ListTopics",
    "LimitReachedError",
    "LookupTransform",
    "MissingFieldError",
    "ObserveParameters",
    "OutOfRangeError",
    "ParameterValue",
    "Publish",
    "QoS",
    "RemoveParameterClient",
    "RemovePublisher",
    "RemoveRobot",
    "RemoveSubscriber",
    "RemoveTfBroadcaster",
    "RemoveTfLookup",
    "Reply",
    "Request",
    "RobotSource",
    "ServerDeclareParameter",
    "ServerGetParameters",
    "ServerSetParameter",
    "ServerUndeclareParameter",
    "ServiceRequest",
    "SetParameters",
    "Stamp",
    "TooLargeError",
    "UnadvertiseService",
    "UnknownFieldError",
    "UnknownOpError",
    "UnsupportedSchemaError",
    "WrongTypeError",
    "dumps",
    "encode_request",
    "error_reply",
    "loads",
    "parse_request",
    "reply_for_exception",
    "resolve_message_type",
    "resolve_service_type",
    "status_is_success",
]

SCHEMA_VERSION = 1
# What 3D Slicer's OpenIGTLinkIO puts in the header of every COMMAND it sends.
COMMAND_DEVICE_NAME = "command"
# NAME is char[128]; OpenIGTLink's reader needs a NUL inside it.
MAX_OP_NAME_BYTES = 127
# Our own limit on a request's text; Slicer's sender refuses anything over 65535 bytes.
MAX_COMMAND_TEXT_BYTES = 1 << 20
SLICER_MAX_COMMAND_TEXT_BYTES = 0xFFFF
MAX_JSON_DEPTH = 32

METADATA_STATUS = "Status"
METADATA_ERROR_MESSAGE = "ErrorMessage"
STATUS_SUCCESS = "SUCCESS"
STATUS_FAIL = "FAIL"

CommandId = NewType("CommandId", int)  # u32 from the COMMAND body, unique per connection

_MAX_NAME = 256  # ROS names, frames, parameter names
_MAX_TEXT = 4096  # descriptions, file paths
_U32 = (1 << 32) - 1
_I64_MIN, _I64_MAX = -(1 << 63), (1 << 63) - 1


def status_is_success(value: str | None) -> bool:
    """True if an RTS_COMMAND ``Status`` metadata value means success.

    OpenIGTLinkIO writes ``SUCCESS``; its converter also reads ``TRUE``; accept both.
    """
    return value is not None and value.strip().upper() in ("SUCCESS", "TRUE")


# ---------------------------------------------------------------------------- errors


class ErrorCode(IntEnum):
    """``error.code`` of a failed `Reply`. 1-19: the request is malformed (fix the client);
    20-39: the request is well-formed but cannot be done now; 99: daemon bug."""

    BAD_JSON = 1
    TOO_LARGE = 2
    UNKNOWN_OP = 3
    UNSUPPORTED_SCHEMA = 4
    MISSING_FIELD = 5
    UNKNOWN_FIELD = 6
    WRONG_TYPE = 7
    OUT_OF_RANGE = 8
    NOT_FOUND = 20
    ALREADY_EXISTS = 21
    UNKNOWN_ROS_TYPE = 22
    ROS_ERROR = 23
    TIMEOUT = 24
    UNAVAILABLE = 25
    TRANSFORM_UNAVAILABLE = 26
    NOT_SUPPORTED = 27
    FORBIDDEN = 28
    LIMIT_REACHED = 29
    INTERNAL = 99


class CommandError(ProtocolError):
    """Base of request errors; `error_code` is what the error reply carries."""

    code: ClassVar[ErrorCode] = ErrorCode.INTERNAL

    @property
    def error_code(self) -> ErrorCode:
        return self.code


class BadJsonError(CommandError):
    """The text is not a JSON object (syntax, encoding, NaN, duplicate keys, nesting)."""

    code = ErrorCode.BAD_JSON


class TooLargeError(CommandError):
    """The text or one of its values is larger than allowed."""

    code = ErrorCode.TOO_LARGE


class UnknownOpError(CommandError):
    """The COMMAND NAME is not an op of this schema."""

    code = ErrorCode.UNKNOWN_OP


class UnsupportedSchemaError(CommandError):
    """The request asks for a schema newer than this daemon's."""

    code = ErrorCode.UNSUPPORTED_SCHEMA


class MissingFieldError(CommandError):
    """A required field is absent."""

    code = ErrorCode.MISSING_FIELD


class UnknownFieldError(CommandError):
    """A field this op does not have (usually a typo)."""

    code = ErrorCode.UNKNOWN_FIELD


class WrongTypeError(CommandError):
    """A field has the wrong JSON type."""

    code = ErrorCode.WRONG_TYPE


class OutOfRangeError(CommandError):
    """A field has the right type but a value that is not allowed."""

    code = ErrorCode.OUT_OF_RANGE


class ForbiddenError(CommandError):
    """The daemon's security policy refuses the request (``--read-only``, or a topic,
    service or parameter glob); the field names what was refused."""

    code = ErrorCode.FORBIDDEN


class LimitReachedError(CommandError):
    """A per-client limit of the daemon is reached (``--max-bridges-per-client``)."""

    code = ErrorCode.LIMIT_REACHED


class CommandFailedError(CommandError):
    """A valid request the daemon could not carry out; the code is chosen per failure
    (NOT_FOUND, ALREADY_EXISTS, TIMEOUT...)."""

    def __init__(self, field: str, expected: str, got: object, *,
                 code: ErrorCode = ErrorCode.ROS_ERROR) -> None:
        self._code = code
        super().__init__(field, expected, got)

    @property
    def error_code(self) -> ErrorCode:
        return self._code


# ---------------------------------------------------------------------------- JSON


def _reject_constant(name: str) -> Any:
    raise BadJsonError("text", "standard JSON numbers", name)


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise BadJsonError(key, "each key once", "a duplicate key")
        out[key] = value
    return out


def _depth_ok(value: Any, limit: int) -> bool:
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, (dict, list)):
            if depth > limit:
                return False
            children = item.values() if isinstance(item, dict) else item
            stack.extend((child, depth + 1) for child in children)
    return True


def loads(text: str | bytes, *, max_bytes: int = MAX_COMMAND_TEXT_BYTES) -> dict[str, Any]:
    """Parse a command or reply text into a JSON object, refusing anything odd.

    Bytes are decoded as UTF-8 whatever the COMMAND's ENCODING says (Slicer labels every
    command US-ASCII). Empty text means ``{}`` so argument-less ops can be sent bare.
    """
    size = len(text.encode("utf-8")) if isinstance(text, str) else len(text)
    if size > max_bytes:
        raise TooLargeError("text", f"at most {max_bytes} bytes", f"{size} bytes")
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise BadJsonError("text", "UTF-8 text", f"invalid byte at {exc.start}") from None
    if not text.strip():
        return {}
    try:
        value = json.loads(text, parse_constant=_reject_constant,
                           object_pairs_hook=_no_duplicates)
    except CommandError:
        raise
    except RecursionError:
        raise BadJsonError("text", f"JSON nested at most {MAX_JSON_DEPTH} deep",
                           "deeper nesting") from None
    except ValueError as exc:  # JSONDecodeError, or an over-long integer literal
        raise BadJsonError("text", "a JSON object", str(exc)) from None
    if not isinstance(value, dict):
        raise BadJsonError("text", "a JSON object", _json_type(value))
    if not _depth_ok(value, MAX_JSON_DEPTH):
        raise BadJsonError("text", f"JSON nested at most {MAX_JSON_DEPTH} deep",
                           "deeper nesting")
    return value


def dumps(value: Mapping[str, Any]) -> str:
    """Compact, ASCII-only JSON (matches the US-ASCII encoding Slicer labels commands with);
    NaN and infinity are refused rather than written as non-standard tokens."""
    try:
        return json.dumps(value, ensure_ascii=True, allow_nan=False, separators=(",", ":"))
    except ValueError as exc:
        raise OutOfRangeError("value", "finite numbers", str(exc)) from None


def _json_type(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"boolean {value!r}".lower()
    if isinstance(value, (int, float)):
        return f"number {value!r}"
    if isinstance(value, str):
        shown = value if len(value) <= 40 else value[:37] + "..."
        return f"string {shown!r}"
    if isinstance(value, list):
        return "array"
    if isinstance(value, dict):
        return "object"
    return type(value).__name__


# ---------------------------------------------------------------------------- field reader

_MISSING = object()
_ROS_NAME = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*\Z")
_PARAM_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_./]*\Z")
_ROBOT_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_ROS_NAME_DESC = "a ROS name like /ns/name (letters, digits, _ and /)"


class _Args:
    """Reads one JSON object's fields, raising errors that name the field's full path."""

    def __init__(self, data: Mapping[str, Any], prefix: str = "") -> None:
        self._data = data
        self._prefix = prefix
        self._used: set[str] = set()

    def path(self, name: str) -> str:
        return f"{self._prefix}{name}"

    def _raw(self, name: str, required: bool) -> Any:
        self._used.add(name)
        if name not in self._data or (self._data[name] is None and not required):
            if required:
                raise MissingFieldError(self.path(name), "a value", "nothing")
            return _MISSING
        return self._data[name]

    def finish(self) -> None:
        extra = sorted(set(self._data) - self._used)
        if extra:
            allowed = ", ".join(sorted(self._used)) or "no fields"
            raise UnknownFieldError(self.path(extra[0]), f"one of: {allowed}", "an unknown field")

    # strings
    def req_str(self, name: str, *, max_len: int = _MAX_NAME, allow_empty: bool = False,
                pattern: re.Pattern[str] | None = None, desc: str = "") -> str:
        value = self._raw(name, True)
        return _check_str(value, self.path(name), max_len, allow_empty, pattern, desc)

    def opt_str(self, name: str, default: str | None = None, *, max_len: int = _MAX_NAME,
                allow_empty: bool = False, pattern: re.Pattern[str] | None = None,
                desc: str = "") -> str | None:
        value = self._raw(name, False)
        if value is _MISSING:
            return default
        return _check_str(value, self.path(name), max_len, allow_empty, pattern, desc)

    def ros_name(self, name: str) -> str:
        return self.req_str(name, pattern=_ROS_NAME, desc=_ROS_NAME_DESC)

    def frame(self, name: str) -> str:
        text = self.req_str(name)
        if "\x00" in text or text.strip() != text:
            raise OutOfRangeError(self.path(name), "a frame id without NUL or outer spaces",
                                  repr(text))
        return text

    def choice(self, name: str, choices: tuple[str, ...], default: str | None = None) -> str:
        value = self._raw(name, default is None)
        if value is _MISSING:
            return cast(str, default)
        if not isinstance(value, str):
            raise WrongTypeError(self.path(name), "a string", _json_type(value))
        if value not in choices:
            raise OutOfRangeError(self.path(name), "one of " + "|".join(choices), repr(value))
        return value

    # numbers
    def opt_int(self, name: str, default: int | None, *, low: int, high: int) -> int | None:
        value = self._raw(name, False)
        if value is _MISSING:
            return default
        return _check_int(value, self.path(name), low, high)

    def req_int(self, name: str, *, low: int, high: int) -> int:
        return _check_int(self._raw(name, True), self.path(name), low, high)

    def opt_float(self, name: str, default: float | None, *, low: float, high: float,
                  low_open: bool = False) -> float | None:
        value = self._raw(name, False)
        if value is _MISSING:
            return default
        return _check_float(value, self.path(name), low, high, low_open)

    def opt_bool(self, name: str, default: bool) -> bool:
        value = self._raw(name, False)
        if value is _MISSING:
            return default
        if not isinstance(value, bool):
            raise WrongTypeError(self.path(name), "true or false", _json_type(value))
        return value

    # containers
    def opt_obj(self, name: str) -> _Args | None:
        value = self._raw(name, False)
        if value is _MISSING:
            return None
        if not isinstance(value, dict):
            raise WrongTypeError(self.path(name), "an object", _json_type(value))
        return _Args(value, self.path(name) + ".")

    def req_obj_raw(self, name: str) -> dict[str, Any]:
        value = self._raw(name, True)
        if not isinstance(value, dict):
            raise WrongTypeError(self.path(name), "an object", _json_type(value))
        return value

    def str_list(self, name: str, *, pattern: re.Pattern[str] | None = None,
                 desc: str = "", required: bool = True) -> tuple[str, ...]:
        value = self._raw(name, required)
        if value is _MISSING:
            return ()
        if not isinstance(value, list):
            raise WrongTypeError(self.path(name), "an array of strings", _json_type(value))
        if len(value) > 10_000:
            raise TooLargeError(self.path(name), "at most 10000 names", f"{len(value)}")
        return tuple(_check_str(v, f"{self.path(name)}[{i}]", _MAX_NAME, False, pattern, desc)
                     for i, v in enumerate(value))

    def any(self, name: str) -> Any:
        return self._raw(name, True)


def _check_str(value: Any, path: str, max_len: int, allow_empty: bool,
               pattern: re.Pattern[str] | None, desc: str) -> str:
    if not isinstance(value, str):
        raise WrongTypeError(path, "a string", _json_type(value))
    if not value and not allow_empty:
        raise OutOfRangeError(path, "a non-empty string", "an empty string")
    if len(value) > max_len:
        raise TooLargeError(path, f"at most {max_len} characters", f"{len(value)} characters")
    if pattern is not None and value and not pattern.match(value):
        raise OutOfRangeError(path, desc or f"text matching {pattern.pattern}", repr(value))
    return value


def _check_int(value: Any, path: str, low: int, high: int) -> int:
    # JSON has no int/float split; accept 3.0 for an integer field only when exact.
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise WrongTypeError(path, "an integer", _json_type(value))
    if isinstance(value, float):
        if not value.is_integer():
            raise WrongTypeError(path, "an integer", _json_type(value))
        value = int(value)
    if not low <= value <= high:
        raise OutOfRangeError(path, f"an integer in [{low}, {high}]", str(value))
    return int(value)


def _check_float(value: Any, path: str, low: float, high: float, low_open: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise WrongTypeError(path, "a number", _json_type(value))
    number = float(value)
    too_low = number <= low if low_open else number < low
    if not math.isfinite(number) or too_low or number > high:
        bracket = "(" if low_open else "["
        raise OutOfRangeError(path, f"a number in {bracket}{low:g}, {high:g}]", repr(value))
    return number


# ---------------------------------------------------------------------------- value types

_RELIABILITY = ("reliable", "best_effort")
_DURABILITY = ("volatile", "transient_local")


@dataclass(frozen=True)
class QoS:
    """ROS quality of service of a subscriber or publisher (KEEP_LAST history)."""

    depth: int = 10
    reliability: str = "reliable"  # reliable | best_effort
    durability: str = "volatile"  # volatile | transient_local

    def to_dict(self) -> dict[str, Any]:
        return {"depth": self.depth, "reliability": self.reliability,
                "durability": self.durability}

    @classmethod
    def from_args(cls, a: _Args) -> QoS:
        qos = cls(
            depth=cast(int, a.opt_int("depth", 10, low=1, high=10_000)),
            reliability=a.choice("reliability", _RELIABILITY, "reliable"),
            durability=a.choice("durability", _DURABILITY, "volatile"),
        )
        a.finish()
        return qos


@dataclass(frozen=True)
class Stamp:
    """A ROS time (builtin_interfaces/Time): seconds since 1970 and nanoseconds."""

    sec: int
    nanosec: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {"sec": self.sec, "nanosec": self.nanosec}

    @classmethod
    def from_args(cls, a: _Args) -> Stamp:
        stamp = cls(sec=a.req_int("sec", low=0, high=_U32),
                    nanosec=cast(int, a.opt_int("nanosec", 0, low=0, high=999_999_999)))
        a.finish()
        return stamp


PARAMETER_TYPES: tuple[str, ...] = (
    "not_set", "bool", "integer", "double", "string", "byte_array",
    "bool_array", "integer_array", "double_array", "string_array",
)


def _param_scalar(kind: str, value: Any, path: str) -> Any:
    if kind == "bool":
        if not isinstance(value, bool):
            raise WrongTypeError(path, "true or false", _json_type(value))
        return value
    if kind == "integer":
        # Exact int only: a double 3.0 must not silently become an integer parameter.
        if isinstance(value, bool) or not isinstance(value, int):
            raise WrongTypeError(path, "an integer", _json_type(value))
        if not _I64_MIN <= value <= _I64_MAX:
            raise OutOfRangeError(path, "a 64-bit signed integer", str(value))
        return value
    if kind == "double":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise WrongTypeError(path, "a number", _json_type(value))
        number = float(value)
        if not math.isfinite(number):
            raise OutOfRangeError(path, "a finite number", repr(value))
        return number
    if kind == "string":
        return _check_str(value, path, 1 << 20, True, None, "")
    if kind == "byte":
        if isinstance(value, bool) or not isinstance(value, int):
            raise WrongTypeError(path, "an integer 0..255", _json_type(value))
        if not 0 <= value <= 255:
            raise OutOfRangeError(path, "an integer 0..255", str(value))
        return value
    raise OutOfRangeError(path, "a parameter type", repr(kind))  # pragma: no cover


def _check_parameter(kind: Any, value: Any, path: str) -> Any:
    if not isinstance(kind, str):
        raise WrongTypeError(f"{path}.type", "a string", _json_type(kind))
    if kind not in PARAMETER_TYPES:
        raise OutOfRangeError(f"{path}.type", "one of " + "|".join(PARAMETER_TYPES), repr(kind))
    vpath = f"{path}.value"
    if kind == "not_set":
        if value is not None:
            raise WrongTypeError(vpath, "null for not_set", _json_type(value))
        return None
    if not kind.endswith("_array"):
        return _param_scalar(kind, value, vpath)
    if isinstance(value, (bytes, bytearray)) and kind == "byte_array":
        value = list(value)
    if not isinstance(value, (list, tuple)):
        raise WrongTypeError(vpath, "an array", _json_type(value))
    element = kind[: -len("_array")]
    return tuple(_param_scalar(element, v, f"{vpath}[{i}]") for i, v in enumerate(value))


@dataclass(frozen=True)
class ParameterValue:
    """A typed ROS parameter value, as in the reference's ``GetParameterType``.

    ``type`` is one of `PARAMETER_TYPES`. Arrays are stored as tuples; a ``double`` always
    holds a float and an ``integer`` an int, so ``integer 3`` and ``double 3.0`` stay apart
    through JSON (the type travels next to the value).
    """

    type: str
    value: Any = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", _check_parameter(self.type, self.value, "value"))

    def to_dict(self) -> dict[str, Any]:
        value = list(self.value) if isinstance(self.value, tuple) else self.value
        return {"type": self.type, "value": value}

    @classmethod
    def from_json_value(cls, data: Any, path: str = "value") -> ParameterValue:
        if not isinstance(data, dict):
            raise WrongTypeError(path, 'an object {"type": ..., "value": ...}', _json_type(data))
        a = _Args(data, path + ".")
        kind = a.req_str("type")
        raw = a._raw("value", kind != "not_set")
        a.finish()
        checked = _check_parameter(kind, None if raw is _MISSING else raw, path)
        return cls(kind, checked)

    @classmethod
    def infer(cls, value: Any) -> ParameterValue:
        """The natural parameter type of a Python value (bool before int; bytes -> byte_array;
        an empty list -> string_array, the ROS convention is ambiguous there)."""
        if value is None:
            return cls("not_set")
        for kind, py in (("bool", bool), ("integer", int), ("double", float), ("string", str)):
            if isinstance(value, py):
                return cls(kind, value)
        if isinstance(value, (bytes, bytearray)):
            return cls("byte_array", value)
        if isinstance(value, (list, tuple)):
            items = list(value)
            for kind, py in (("bool_array", bool), ("integer_array", int),
                             ("double_array", float), ("string_array", str)):
                if items and all(isinstance(v, py) and (py is bool or not isinstance(v, bool))
                                 for v in items):
                    return cls(kind, items)
            if items and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                             for v in items):
                return cls("double_array", [float(v) for v in items])
            if not items:
                return cls("string_array", ())
        raise WrongTypeError("value", "a bool, int, float, str, bytes or a list of one of them",
                             type(value).__name__)


_ROBOT_SOURCES = ("parameter", "topic", "file")


@dataclass(frozen=True)
class RobotSource:
    """Where a robot's URDF comes from: a node's parameter (default
    ``/robot_state_publisher`` ``robot_description``), a latched topic, or a file on the
    daemon's machine. Relative node and topic names resolve in the robot's namespace."""

    kind: str = "parameter"  # parameter | topic | file
    node: str = "/robot_state_publisher"
    parameter: str = "robot_description"
    topic: str = "/robot_description"
    path: str = ""

    def to_dict(self) -> dict[str, Any]:
        if self.kind == "parameter":
            return {"kind": "parameter", "node": self.node, "parameter": self.parameter}
        if self.kind == "topic":
            return {"kind": "topic", "topic": self.topic}
        return {"kind": "file", "path": self.path}

    @classmethod
    def from_args(cls, a: _Args) -> RobotSource:
        kind = a.choice("kind", _ROBOT_SOURCES, "parameter")
        if kind == "parameter":
            src = cls(kind, node=cast(str, a.opt_str("node", "/robot_state_publisher",
                                                     pattern=_ROS_NAME, desc=_ROS_NAME_DESC)),
                      parameter=cast(str, a.opt_str("parameter", "robot_description",
                                                    pattern=_PARAM_NAME)))
        elif kind == "topic":
            src = cls(kind, topic=cast(str, a.opt_str("topic", "/robot_description",
                                                      pattern=_ROS_NAME, desc=_ROS_NAME_DESC)))
        else:
            src = cls(kind, path=a.req_str("path", max_len=_MAX_TEXT))
        a.finish()
        return src


Matrix4 = tuple[tuple[float, float, float, float], ...]


def _matrix_from(value: Any, path: str) -> Matrix4:
    if not isinstance(value, list) or len(value) != 4:
        raise WrongTypeError(path, "4 rows of 4 numbers (mm)", _json_type(value))
    rows = []
    for i, row in enumerate(value):
        if not isinstance(row, list) or len(row) != 4:
            raise WrongTypeError(f"{path}[{i}]", "a row of 4 numbers", _json_type(row))
        rows.append(tuple(_check_float(v, f"{path}[{i}][{j}]", -math.inf, math.inf, False)
                          for j, v in enumerate(row)))
    try:
        validate_matrix(rows, field=path)
    except ConversionError as exc:
        raise OutOfRangeError(exc.field, exc.expected, exc.got) from None
    return cast(Matrix4, tuple(rows))


# ---------------------------------------------------------------------------- message types

# The reference SlicerROS2's short names (and its class-name stems) -> ROS message type.
# Several share a type (a vtkTable and a vtkDoubleArray both travel as Float64MultiArray).
REFERENCE_TYPE_NAMES: dict[str, str] = {
    "Empty": "std_msgs/msg/Empty",
    "String": "std_msgs/msg/String",
    "Bool": "std_msgs/msg/Bool",
    "Int": "std_msgs/msg/Int64",
    "Int64": "std_msgs/msg/Int64",
    "Double": "std_msgs/msg/Float64",
    "Float": "std_msgs/msg/Float64",
    "Float64": "std_msgs/msg/Float64",
    "IntArray": "std_msgs/msg/Int64MultiArray",
    "IntTable": "std_msgs/msg/Int64MultiArray",
    "IntNArray": "std_msgs/msg/Int64MultiArray",
    "Int64MultiArray": "std_msgs/msg/Int64MultiArray",
    "DoubleArray": "std_msgs/msg/Float64MultiArray",
    "FloatArray": "std_msgs/msg/Float64MultiArray",
    "DoubleTable": "std_msgs/msg/Float64MultiArray",
    "Float64MultiArray": "std_msgs/msg/Float64MultiArray",
    "Pose": "geometry_msgs/msg/Pose",
    "PoseStamped": "geometry_msgs/msg/PoseStamped",
    "PoseArray": "geometry_msgs/msg/PoseArray",
    "Transform": "geometry_msgs/msg/Transform",
    "TransformStamped": "geometry_msgs/msg/TransformStamped",
    "Wrench": "geometry_msgs/msg/Wrench",
    "WrenchStamped": "geometry_msgs/msg/WrenchStamped",
    "Point": "geometry_msgs/msg/Point",
    "PointStamped": "geometry_msgs/msg/PointStamped",
    "JointState": "sensor_msgs/msg/JointState",
    "Joy": "sensor_msgs/msg/Joy",
    "JoyV2": "sensor_msgs/msg/Joy",
    "Image": "sensor_msgs/msg/Image",
    "UInt8Image": "sensor_msgs/msg/Image",
    "PointCloud": "sensor_msgs/msg/PointCloud",
    "PointCloud2": "sensor_msgs/msg/PointCloud2",
}
_FULL_TYPE = re.compile(r"([a-z][a-z0-9_]*)/(?:(msg|srv)/)?([A-Z][A-Za-z0-9]*)\Z")
_CLASS_NAME = re.compile(r"vtkMRMLROS2(?:Subscriber|Publisher)([A-Za-z0-9]+)Node\Z")


def resolve_message_type(text: str, field: str = "type") -> str:
    """``pkg/msg/Type``, ``pkg/Type``, a reference short name (``PoseStamped``, ``Int``)
    or class name (``vtkMRMLROS2SubscriberStringNode``) -> ``pkg/msg/Type``."""
    class_match = _CLASS_NAME.match(text)
    stem = class_match.group(1) if class_match else text
    if stem in REFERENCE_TYPE_NAMES:
        return REFERENCE_TYPE_NAMES[stem]
    full = _FULL_TYPE.match(text)
    if full and full.group(2) in (None, "msg"):
        return f"{full.group(1)}/msg/{full.group(3)}"
    raise OutOfRangeError(field, "pkg/msg/Type, pkg/Type, or a short name such as "
                          "String or PoseStamped", repr(text))


def resolve_service_type(text: str, field: str = "type") -> str:
    """``pkg/srv/Type`` or ``pkg/Type`` -> ``pkg/srv/Type``."""
    full = _FULL_TYPE.match(text)
    if full and full.group(2) in (None, "srv"):
        return f"{full.group(1)}/srv/{full.group(3)}"
    raise OutOfRangeError(field, "a service type pkg/srv/Type", repr(text))


# ---------------------------------------------------------------------------- requests

R = TypeVar("R", bound="_RequestBase")


def _jsonable(value: Any) -> Any:
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if isinstance(value, tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    return value


@dataclass(frozen=True)
class _RequestBase:
    """Shared encoding: fields become JSON keys (None fields are left out)."""

    op: ClassVar[str] = ""

    def to_args(self) -> dict[str, Any]:
        out: dict[str, Any] = {"schema": SCHEMA_VERSION}
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None or f.default is not None:  # omit unset optionals only
                out[f.name] = _jsonable(value)
        return out

    def to_json(self) -> str:
        """The COMMAND text for this request (the op goes in the COMMAND NAME)."""
        return dumps(self.to_args())

    @classmethod
    def from_args(cls, a: _Args) -> _RequestBase:
        raise NotImplementedError  # pragma: no cover

    @classmethod
    def from_json(cls: type[R], text: str | bytes) -> R:  # noqa: PYI019  (3.9: no Self)
        """Parse and validate this op's COMMAND text."""
        return cast(R, parse_request(cls.op, text))


def _qos(a: _Args) -> QoS:
    sub = a.opt_obj("qos")
    return QoS.from_args(sub) if sub is not None else QoS()


def _stamp(a: _Args, name: str) -> Stamp | None:
    sub = a.opt_obj(name)
    return Stamp.from_args(sub) if sub is not None else None


def _rate(a: _Args) -> float | None:
    return a.opt_float("rate_hz", None, low=0.0, high=10_000.0, low_open=True)


def _msg_type(a: _Args) -> str:
    text = a.req_str("type")
    resolve_message_type(text, a.path("type"))
    return text


def _srv_type(a: _Args) -> str:
    text = a.req_str("type")
    resolve_service_type(text, a.path("type"))
    return text


def _json_object(a: _Args, name: str) -> dict[str, Any]:
    return a.req_obj_raw(name)


@dataclass(frozen=True)
class Hello(_RequestBase):
    """Handshake: the reply says the daemon's schema, version, node name and ops."""

    op: ClassVar[Literal["hello"]] = "hello"
    client: str | None = None

    @classmethod
    def from_args(cls, a: _Args) -> Hello:
        return cls(client=a.opt_str("client", max_len=_MAX_NAME))


@dataclass(frozen=True)
class ListBridges(_RequestBase):
    """Everything this daemon currently bridges, with device names."""

    op: ClassVar[Literal["list_bridges"]] = "list_bridges"

    @classmethod
    def from_args(cls, a: _Args) -> ListBridges:
        return cls()


@dataclass(frozen=True)
class ListTopics(_RequestBase):
    """The ROS graph's topics and their types."""

    op: ClassVar[Literal["list_topics"]] = "list_topics"

    @classmethod
    def from_args(cls, a: _Args) -> ListTopics:
        return cls()


@dataclass(frozen=True)
class ListServices(_RequestBase):
    """The ROS graph's services and their types."""

    op: ClassVar[Literal["list_services"]] = "list_services"

    @classmethod
    def from_args(cls, a: _Args) -> ListServices:
        return cls()


@dataclass(frozen=True)
class CreateSubscriber(_RequestBase):
    """Subscribe to a ROS topic; messages then flow to clients as OpenIGTLink messages.

    ``type`` is kept as given (the reference's ``IntTable`` vs ``IntArray`` choose the
    Slicer representation); `ros_type` is the resolved ``pkg/msg/Type``."""

    op: ClassVar[Literal["create_subscriber"]] = "create_subscriber"
    topic: str
    type: str
    qos: QoS = QoS()
    rate_hz: float | None = None

    @property
    def ros_type(self) -> str:
        return resolve_message_type(self.type)

    @classmethod
    def from_args(cls, a: _Args) -> CreateSubscriber:
        return cls(topic=a.ros_name("topic"), type=_msg_type(a), qos=_qos(a), rate_hz=_rate(a))


@dataclass(frozen=True)
class RemoveSubscriber(_RequestBase):
    op: ClassVar[Literal["remove_subscriber"]] = "remove_subscriber"
    topic: str

    @classmethod
    def from_args(cls, a: _Args) -> RemoveSubscriber:
        return cls(topic=a.ros_name("topic"))


@dataclass(frozen=True)
class CreatePublisher(_RequestBase):
    """Create a ROS publisher; clients feed it with `Publish` or by sending OpenIGTLink
    messages under the device name the reply gives."""

    op: ClassVar[Literal["create_publisher"]] = "create_publisher"
    topic: str
    type: str
    qos: QoS = QoS()

    @property
    def ros_type(self) -> str:
        return resolve_message_type(self.type)

    @classmethod
    def from_args(cls, a: _Args) -> CreatePublisher:
        return cls(topic=a.ros_name("topic"), type=_msg_type(a), qos=_qos(a))


@dataclass(frozen=True)
class RemovePublisher(_RequestBase):
    op: ClassVar[Literal["remove_publisher"]] = "remove_publisher"
    topic: str

    @classmethod
    def from_args(cls, a: _Args) -> RemovePublisher:
        return cls(topic=a.ros_name("topic"))


@dataclass(frozen=True)
class Publish(_RequestBase):
    """Publish one message on an existing publisher. ``value`` is the message as a JSON
    object of its fields, or a bare value for one-field types (String: "text", Int: 3, a
    4x4 mm matrix for Pose/PoseStamped/Transform...). Reply: subscriber count."""

    op: ClassVar[Literal["publish"]] = "publish"
    topic: str
    value: Any

    @classmethod
    def from_args(cls, a: _Args) -> Publish:
        return cls(topic=a.ros_name("topic"), value=a.any("value"))


@dataclass(frozen=True)
class GetLastMessage(_RequestBase):
    """The last message a subscriber received, as YAML or JSON text, and the count."""

    op: ClassVar[Literal["get_last_message"]] = "get_last_message"
    topic: str
    format: str = "yaml"  # yaml | json

    @classmethod
    def from_args(cls, a: _Args) -> GetLastMessage:
        return cls(topic=a.ros_name("topic"), format=a.choice("format", ("yaml", "json"), "yaml"))


@dataclass(frozen=True)
class CreateParameterClient(_RequestBase):
    """Watch another node's parameters (``/robot_state_publisher`` or ``ns/node``)."""

    op: ClassVar[Literal["create_parameter_client"]] = "create_parameter_client"
    node: str

    @classmethod
    def from_args(cls, a: _Args) -> CreateParameterClient:
        return cls(node=a.ros_name("node"))


@dataclass(frozen=True)
class RemoveParameterClient(_RequestBase):
    op: ClassVar[Literal["remove_parameter_client"]] = "remove_parameter_client"
    node: str

    @classmethod
    def from_args(cls, a: _Args) -> RemoveParameterClient:
        return cls(node=a.ros_name("node"))


@dataclass(frozen=True)
class ListParameters(_RequestBase):
    op: ClassVar[Literal["list_parameters"]] = "list_parameters"
    node: str

    @classmethod
    def from_args(cls, a: _Args) -> ListParameters:
        return cls(node=a.ros_name("node"))


@dataclass(frozen=True)
class GetParameters(_RequestBase):
    """Values of a remote node's parameters (unknown ones come back ``not_set``)."""

    op: ClassVar[Literal["get_parameters"]] = "get_parameters"
    node: str
    names: tuple[str, ...]

    @classmethod
    def from_args(cls, a: _Args) -> GetParameters:
        return cls(node=a.ros_name("node"), names=a.str_list("names", pattern=_PARAM_NAME))


def _param_values(a: _Args, name: str) -> dict[str, ParameterValue]:
    raw = a.req_obj_raw(name)
    out: dict[str, ParameterValue] = {}
    for key, value in raw.items():
        path = f"{a.path(name)}.{key}"
        _check_str(key, path, _MAX_NAME, False, _PARAM_NAME, "a parameter name")
        out[key] = ParameterValue.from_json_value(value, path)
    if not out:
        raise OutOfRangeError(a.path(name), "at least one parameter", "an empty object")
    return out


@dataclass(frozen=True)
class SetParameters(_RequestBase):
    """Set a remote node's parameters; the reply gives each one's outcome."""

    op: ClassVar[Literal["set_parameters"]] = "set_parameters"
    node: str
    values: dict[str, ParameterValue]

    @classmethod
    def from_args(cls, a: _Args) -> SetParameters:
        return cls(node=a.ros_name("node"), values=_param_values(a, "values"))


@dataclass(frozen=True)
class ObserveParameters(_RequestBase):
    """Replace the set of a parameter client's parameters whose changes are pushed to
    the client (a STRING message under the client's device name); ``[]`` stops."""

    op: ClassVar[Literal["observe_parameters"]] = "observe_parameters"
    node: str
    names: tuple[str, ...]

    @classmethod
    def from_args(cls, a: _Args) -> ObserveParameters:
        return cls(node=a.ros_name("node"), names=a.str_list("names", pattern=_PARAM_NAME))


@dataclass(frozen=True)
class ServerDeclareParameter(_RequestBase):
    """Declare a parameter on the daemon's own ROS node (a parameter server for Slicer)."""

    op: ClassVar[Literal["server_declare_parameter"]] = "server_declare_parameter"
    name: str
    value: ParameterValue
    read_only: bool = False
    description: str = ""

    @classmethod
    def from_args(cls, a: _Args) -> ServerDeclareParameter:
        return cls(name=a.req_str("name", pattern=_PARAM_NAME),
                   value=ParameterValue.from_json_value(a.any("value"), a.path("value")),
                   read_only=a.opt_bool("read_only", False),
                   description=cast(str, a.opt_str("description", "", max_len=_MAX_TEXT,
                                                    allow_empty=True)))


@dataclass(frozen=True)
class ServerSetParameter(_RequestBase):
    op: ClassVar[Literal["server_set_parameter"]] = "server_set_parameter"
    name: str
    value: ParameterValue

    @classmethod
    def from_args(cls, a: _Args) -> ServerSetParameter:
        return cls(name=a.req_str("name", pattern=_PARAM_NAME),
                   value=ParameterValue.from_json_value(a.any("value"), a.path("value")))


@dataclass(frozen=True)
class ServerGetParameters(_RequestBase):
    """Values of the daemon's own parameters; ``names`` omitted or empty = all."""

    op: ClassVar[Literal["server_get_parameters"]] = "server_get_parameters"
    names: tuple[str, ...] = ()

    @classmethod
    def from_args(cls, a: _Args) -> ServerGetParameters:
        return cls(names=a.str_list("names", pattern=_PARAM_NAME, required=False))


@dataclass(frozen=True)
class ServerUndeclareParameter(_RequestBase):
    op: ClassVar[Literal["server_undeclare_parameter"]] = "server_undeclare_parameter"
    name: str

    @classmethod
    def from_args(cls, a: _Args) -> ServerUndeclareParameter:
        return cls(name=a.req_str("name", pattern=_PARAM_NAME))


@dataclass(frozen=True)
class CreateTfLookup(_RequestBase):
    """Stream parent->child as a TRANSFORM (mm) whenever it changes, at most ``rate_hz``."""

    op: ClassVar[Literal["create_tf_lookup"]] = "create_tf_lookup"
    parent: str
    child: str
    rate_hz: float | None = None

    @classmethod
    def from_args(cls, a: _Args) -> CreateTfLookup:
        return cls(parent=a.frame("parent"), child=a.frame("child"), rate_hz=_rate(a))


@dataclass(frozen=True)
class RemoveTfLookup(_RequestBase):
    op: ClassVar[Literal["remove_tf_lookup"]] = "remove_tf_lookup"
    parent: str
    child: str

    @classmethod
    def from_args(cls, a: _Args) -> RemoveTfLookup:
        return cls(parent=a.frame("parent"), child=a.frame("child"))


@dataclass(frozen=True)
class LookupTransform(_RequestBase):
    """One tf lookup; ``time`` omitted = latest; waits up to ``timeout`` seconds."""

    op: ClassVar[Literal["lookup_transform"]] = "lookup_transform"
    parent: str
    child: str
    time: Stamp | None = None
    timeout: float = 0.0

    @classmethod
    def from_args(cls, a: _Args) -> LookupTransform:
        return cls(parent=a.frame("parent"), child=a.frame("child"), time=_stamp(a, "time"),
                   timeout=cast(float, a.opt_float("timeout", 0.0, low=0.0, high=60.0)))


@dataclass(frozen=True)
class CreateTfBroadcaster(_RequestBase):
    """Broadcast parent->child; ``static`` uses /tf_static (latched)."""

    op: ClassVar[Literal["create_tf_broadcaster"]] = "create_tf_broadcaster"
    parent: str
    child: str
    static: bool = False

    @classmethod
    def from_args(cls, a: _Args) -> CreateTfBroadcaster:
        return cls(parent=a.frame("parent"), child=a.frame("child"),
                   static=a.opt_bool("static", False))


@dataclass(frozen=True)
class RemoveTfBroadcaster(_RequestBase):
    op: ClassVar[Literal["remove_tf_broadcaster"]] = "remove_tf_broadcaster"
    parent: str
    child: str

    @classmethod
    def from_args(cls, a: _Args) -> RemoveTfBroadcaster:
        return cls(parent=a.frame("parent"), child=a.frame("child"))


@dataclass(frozen=True)
class BroadcastTransform(_RequestBase):
    """Broadcast one parent->child transform given as a rigid 4x4 matrix in mm (rows);
    ``stamp`` omitted = the daemon's current time."""

    op: ClassVar[Literal["broadcast_transform"]] = "broadcast_transform"
    parent: str
    child: str
    matrix: Matrix4
    stamp: Stamp | None = None

    @classmethod
    def from_args(cls, a: _Args) -> BroadcastTransform:
        return cls(parent=a.frame("parent"), child=a.frame("child"),
                   matrix=_matrix_from(a.any("matrix"), a.path("matrix")),
                   stamp=_stamp(a, "stamp"))


@dataclass(frozen=True)
class CreateRobot(_RequestBase):
    """Load a robot from its URDF: one model per link visual, placed by tf lookups from
    ``fixed_frame`` (omitted = the URDF's root link) to ``tf_prefix`` + link."""

    op: ClassVar[Literal["create_robot"]] = "create_robot"
    name: str
    source: RobotSource = RobotSource()
    fixed_frame: str | None = None
    tf_prefix: str = ""
    namespace: str = ""

    @classmethod
    def from_args(cls, a: _Args) -> CreateRobot:
        sub = a.opt_obj("source")
        fixed = a.opt_str("fixed_frame")
        return cls(
            name=a.req_str("name", max_len=64, pattern=_ROBOT_NAME,
                           desc="a robot name of letters, digits and _"),
            source=RobotSource.from_args(sub) if sub is not None else RobotSource(),
            fixed_frame=fixed,
            tf_prefix=cast(str, a.opt_str("tf_prefix", "", allow_empty=True)),
            namespace=cast(str, a.opt_str("namespace", "", allow_empty=True, pattern=_ROS_NAME,
                                          desc=_ROS_NAME_DESC)),
        )


@dataclass(frozen=True)
class RemoveRobot(_RequestBase):
    op: ClassVar[Literal["remove_robot"]] = "remove_robot"
    name: str

    @classmethod
    def from_args(cls, a: _Args) -> RemoveRobot:
        return cls(name=a.req_str("name", max_len=64, pattern=_ROBOT_NAME,
                                  desc="a robot name of letters, digits and _"))


@dataclass(frozen=True)
class ListRobots(_RequestBase):
    op: ClassVar[Literal["list_robots"]] = "list_robots"

    @classmethod
    def from_args(cls, a: _Args) -> ListRobots:
        return cls()


@dataclass(frozen=True)
class CallService(_RequestBase):
    """Call a ROS service. Keep ``timeout`` below the client's own command timeout
    (3D Slicer's default is 5 s) so the daemon's TIMEOUT reply arrives first."""

    op: ClassVar[Literal["call_service"]] = "call_service"
    service: str
    type: str
    request: dict[str, Any] = field(default_factory=dict)
    timeout: float = 4.0

    @property
    def ros_type(self) -> str:
        return resolve_service_type(self.type)

    @classmethod
    def from_args(cls, a: _Args) -> CallService:
        service, kind = a.ros_name("service"), _srv_type(a)
        raw = a._raw("request", False)
        if raw is _MISSING:
            raw = {}
        elif not isinstance(raw, dict):
            raise WrongTypeError(a.path("request"), "an object", _json_type(raw))
        return cls(service=service, type=kind, request=raw,
                   timeout=cast(float, a.opt_float("timeout", 4.0, low=0.0, high=300.0,
                                                   low_open=True)))


@dataclass(frozen=True)
class AdvertiseService(_RequestBase):
    """Offer a ROS service served by this client: each call reaches the client as a
    `ServiceRequest` COMMAND, answered with an RTS_COMMAND reply ``{"response": {...}}``."""

    op: ClassVar[Literal["advertise_service"]] = "advertise_service"
    service: str
    type: str

    @property
    def ros_type(self) -> str:
        return resolve_service_type(self.type)

    @classmethod
    def from_args(cls, a: _Args) -> AdvertiseService:
        return cls(service=a.ros_name("service"), type=_srv_type(a))


@dataclass(frozen=True)
class UnadvertiseService(_RequestBase):
    op: ClassVar[Literal["unadvertise_service"]] = "unadvertise_service"
    service: str

    @classmethod
    def from_args(cls, a: _Args) -> UnadvertiseService:
        return cls(service=a.ros_name("service"))


@dataclass(frozen=True)
class ServiceRequest(_RequestBase):
    """Sent by the daemon to the client that advertised ``service``: one ROS call to serve
    within ``timeout`` seconds."""

    op: ClassVar[Literal["service_request"]] = "service_request"
    service: str
    type: str
    request: dict[str, Any] = field(default_factory=dict)
    timeout: float = 4.0

    @classmethod
    def from_args(cls, a: _Args) -> ServiceRequest:
        service, kind = a.ros_name("service"), _srv_type(a)
        return cls(service=service, type=kind, request=_json_object(a, "request"),
                   timeout=cast(float, a.opt_float("timeout", 4.0, low=0.0, high=300.0,
                                                   low_open=True)))


Request = Union[
    Hello, ListBridges, ListTopics, ListServices,
    CreateSubscriber, RemoveSubscriber, CreatePublisher, RemovePublisher, Publish,
    GetLastMessage,
    CreateParameterClient, RemoveParameterClient, ListParameters, GetParameters,
    SetParameters, ObserveParameters,
    ServerDeclareParameter, ServerSetParameter, ServerGetParameters, ServerUndeclareParameter,
    CreateTfLookup, RemoveTfLookup, LookupTransform, CreateTfBroadcaster, RemoveTfBroadcaster,
    BroadcastTransform,
    CreateRobot, RemoveRobot, ListRobots,
    CallService, AdvertiseService, UnadvertiseService, ServiceRequest,
]

_ALL_REQUESTS: tuple[type[_RequestBase], ...] = (
    Hello, ListBridges, ListTopics, ListServices,
    CreateSubscriber, RemoveSubscriber, CreatePublisher, RemovePublisher, Publish,
    GetLastMessage,
    CreateParameterClient, RemoveParameterClient, ListParameters, GetParameters,
    SetParameters, ObserveParameters,
    ServerDeclareParameter, ServerSetParameter, ServerGetParameters, ServerUndeclareParameter,
    CreateTfLookup, RemoveTfLookup, LookupTransform, CreateTfBroadcaster, RemoveTfBroadcaster,
    BroadcastTransform,
    CreateRobot, RemoveRobot, ListRobots,
    CallService, AdvertiseService, UnadvertiseService, ServiceRequest,
)
REQUEST_TYPES: dict[str, type[_RequestBase]] = {cls.op: cls for cls in _ALL_REQUESTS}


def _check_schema(data: Mapping[str, Any]) -> None:
    if "schema" not in data:
        return
    value = data["schema"]
    if isinstance(value, bool) or not isinstance(value, int):
        raise WrongTypeError("schema", "an integer", _json_type(value))
    if not 1 <= value <= SCHEMA_VERSION:
        raise UnsupportedSchemaError("schema", f"1..{SCHEMA_VERSION}", str(value))


def parse_request(op: str, text: str | bytes) -> Request:
    """COMMAND NAME + text -> a validated request object, or a `CommandError`."""
    if len(op.encode("utf-8")) > MAX_OP_NAME_BYTES:
        raise TooLargeError("op", f"at most {MAX_OP_NAME_BYTES} bytes", f"{len(op)} characters")
    cls = REQUEST_TYPES.get(op)
    if cls is None:
        raise UnknownOpError("op", "one of " + ", ".join(sorted(REQUEST_TYPES)), repr(op))
    data = loads(text)
    _check_schema(data)
    args = _Args(data)
    args._used.add("schema")
    request = cls.from_args(args)
    args.finish()
    return cast(Request, request)


def encode_request(request: Request) -> tuple[str, str]:
    """A request -> (COMMAND NAME, COMMAND text)."""
    return request.op, request.to_json()


# ---------------------------------------------------------------------------- replies


@dataclass(frozen=True)
class ErrorInfo:
    """Why a request failed: a code, a readable message and the field at fault (or "")."""

    code: ErrorCode
    message: str
    field: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"code": int(self.code), "name": self.code.name, "message": self.message,
                "field": self.field}

    @classmethod
    def from_dict(cls, data: Any, path: str = "error") -> ErrorInfo:
        if not isinstance(data, dict):
            raise WrongTypeError(path, "an object", _json_type(data))
        a = _Args(data, path + ".")
        number = a.req_int("code", low=0, high=65535)
        a.opt_str("name", allow_empty=True)  # informative only
        message = cast(str, a.opt_str("message", "", max_len=1 << 16, allow_empty=True))
        fld = cast(str, a.opt_str("field", "", allow_empty=True))
        a.finish()
        try:
            code = ErrorCode(number)
        except ValueError:  # a newer daemon's code: keep the reply readable
            code = ErrorCode.INTERNAL
        return cls(code, message, fld)


@dataclass(frozen=True)
class Reply:
    """The JSON text of an RTS_COMMAND: ``{"schema", "op", "ok", "result" | "error"}``."""

    ok: bool
    op: str = ""
    result: dict[str, Any] = field(default_factory=dict)
    error: ErrorInfo | None = None
    schema: int = SCHEMA_VERSION

    def __post_init__(self) -> None:
        if self.ok and self.error is not None:
            raise OutOfRangeError("error", "no error on a successful reply", "an error")
        if not self.ok and self.error is None:
            raise MissingFieldError("error", "an error on a failed reply", "nothing")

    @classmethod
    def success(cls, op: str, result: Mapping[str, Any] | None = None) -> Reply:
        return cls(ok=True, op=op, result=dict(result or {}))

    @classmethod
    def failure(cls, op: str, code: ErrorCode, message: str, field: str = "") -> Reply:
        return cls(ok=False, op=op, error=ErrorInfo(code, message, field))

    @property
    def status(self) -> str:
        """The ``Status`` metadata value of the RTS_COMMAND."""
        return STATUS_SUCCESS if self.ok else STATUS_FAIL

    def metadata(self) -> dict[str, str]:
        """Metadata for the RTS_COMMAND header v2: Status, and ErrorMessage on failure
        (what OpenIGTLinkIO's ``igtlioCommand::GetErrorMessage`` returns)."""
        meta = {METADATA_STATUS: self.status}
        if self.error is not None:
            meta[METADATA_ERROR_MESSAGE] = self.error.message
        return meta

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"schema": self.schema, "op": self.op, "ok": self.ok}
        if self.ok:
            out["result"] = self.result
        else:
            out["error"] = cast(ErrorInfo, self.error).to_dict()
        return out

    def to_json(self) -> str:
        return dumps(self.to_dict())

    @classmethod
    def from_json(cls, text: str | bytes, *, max_bytes: int = 1 << 30) -> Reply:
        """Parse a reply (replies can be large: a last message, a parameter list)."""
        data = loads(text, max_bytes=max_bytes)
        a = _Args(data)
        schema = cast(int, a.opt_int("schema", SCHEMA_VERSION, low=1, high=1 << 16))
        op = cast(str, a.opt_str("op", "", max_len=MAX_OP_NAME_BYTES, allow_empty=True))
        ok = a._raw("ok", True)
        if not isinstance(ok, bool):
            raise WrongTypeError("ok", "true or false", _json_type(ok))
        if ok:
            raw = a._raw("result", False)
            result: dict[str, Any] = {} if raw is _MISSING else raw
            if not isinstance(result, dict):
                raise WrongTypeError("result", "an object", _json_type(result))
            a.finish()
            return cls(ok=True, op=op, result=result, schema=schema)
        error = ErrorInfo.from_dict(a._raw("error", True))
        a.finish()
        return cls(ok=False, op=op, error=error, schema=schema)


def error_reply(op: str, exc: CommandError) -> Reply:
    """The failed reply for a refused request, naming the field, expectation and value."""
    return Reply.failure(op, exc.error_code, str(exc), exc.field)


def reply_for_exception(op: str, exc: BaseException) -> Reply:
    """Any exception -> failed reply: a `CommandError` keeps its code and field, anything
    else is INTERNAL (the daemon should also log it: it is a bug)."""
    if isinstance(exc, CommandError):
        return error_reply(op, exc)
    if isinstance(exc, ProtocolError):
        return Reply.failure(op, ErrorCode.OUT_OF_RANGE, str(exc), exc.field)
    return Reply.failure(op, ErrorCode.INTERNAL, f"{type(exc).__name__}: {exc}")

