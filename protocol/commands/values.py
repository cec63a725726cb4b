"""Value types shared by several ops: QoS, ROS time stamps, typed parameter values, robot
description sources and 4x4 matrices in mm."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Optional, cast

from protocol.commands.errors import OutOfRangeError, WrongTypeError
from protocol.commands.fields import (MAX_TEXT, MISSING, PARAM_NAME, ROS_NAME, ROS_NAME_DESC,
                                      Args, check_float, check_str)
from protocol.commands.wire import json_type
from protocol.conversions import ConversionError, validate_matrix

__all__ = ["PARAMETER_TYPES", "Matrix4", "ParameterValue", "QoS", "RobotSource", "Stamp",
           "matrix_from", "matrix_rows"]

_U32 = (1 << 32) - 1
_I64_MIN, _I64_MAX = -(1 << 63), (1 << 63) - 1

_RELIABILITY = ("reliable", "best_effort")
_DURABILITY = ("volatile", "transient_local")


@dataclass(frozen=True)
class QoS:
    """ROS quality of service of a subscriber or publisher (KEEP_LAST history).

    ``depth`` None: the bridge's default for the message type (`DEFAULT_DEPTH`, or 1 for
    bulk types such as images and point clouds, whose older copies nobody gets)."""

    depth: Optional[int] = None
    reliability: str = "reliable"  # reliable | best_effort
    durability: str = "volatile"  # volatile | transient_local

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {} if self.depth is None else {"depth": self.depth}
        out.update(reliability=self.reliability, durability=self.durability)
        return out

    def with_default_depth(self, depth: int) -> QoS:
        """This QoS with ``depth`` filled in if the client left it to the bridge."""
        return self if self.depth is not None else dataclasses.replace(self, depth=depth)

    @classmethod
    def from_args(cls, a: Args) -> QoS:
        qos = cls(
            depth=a.opt_int("depth", None, low=1, high=10_000),
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
    def from_ns(cls, ns: int) -> Stamp:
        """Nanoseconds since 1970 as a stamp."""
        sec, nanosec = divmod(ns, 1_000_000_000)
        return cls(sec, nanosec)

    @classmethod
    def from_args(cls, a: Args) -> Stamp:
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
            raise WrongTypeError(path, "true or false", json_type(value))
        return value
    if kind == "integer":
        # Exact int only: a double 3.0 must not silently become an integer parameter.
        if isinstance(value, bool) or not isinstance(value, int):
            raise WrongTypeError(path, "an integer", json_type(value))
        if not _I64_MIN <= value <= _I64_MAX:
            raise OutOfRangeError(path, "a 64-bit signed integer", str(value))
        return value
    if kind == "double":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise WrongTypeError(path, "a number", json_type(value))
        number = float(value)
        if not math.isfinite(number):
            raise OutOfRangeError(path, "a finite number", repr(value))
        return number
    if kind == "string":
        return check_str(value, path, 1 << 20, True, None, "")
    if kind == "byte":
        if isinstance(value, bool) or not isinstance(value, int):
            raise WrongTypeError(path, "an integer 0..255", json_type(value))
        if not 0 <= value <= 255:
            raise OutOfRangeError(path, "an integer 0..255", str(value))
        return value
    raise OutOfRangeError(path, "a parameter type", repr(kind))  # pragma: no cover


def _check_parameter(kind: Any, value: Any, path: str) -> Any:
    if not isinstance(kind, str):
        raise WrongTypeError(f"{path}.type", "a string", json_type(kind))
    if kind not in PARAMETER_TYPES:
        raise OutOfRangeError(f"{path}.type", "one of " + "|".join(PARAMETER_TYPES), repr(kind))
    vpath = f"{path}.value"
    if kind == "not_set":
        if value is not None:
            raise WrongTypeError(vpath, "null for not_set", json_type(value))
        return None
    if not kind.endswith("_array"):
        return _param_scalar(kind, value, vpath)
    if isinstance(value, (bytes, bytearray)) and kind == "byte_array":
        value = list(value)
    if not isinstance(value, (list, tuple)):
        raise WrongTypeError(vpath, "an array", json_type(value))
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
            raise WrongTypeError(path, 'an object {"type": ..., "value": ...}', json_type(data))
        a = Args(data, path + ".")
        kind = a.req_str("type")
        raw = a.raw("value", kind != "not_set")
        a.finish()
        checked = _check_parameter(kind, None if raw is MISSING else raw, path)
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
    def from_args(cls, a: Args) -> RobotSource:
        kind = a.choice("kind", _ROBOT_SOURCES, "parameter")
        if kind == "parameter":
            src = cls(kind, node=cast(str, a.opt_str("node", "/robot_state_publisher",
                                                     pattern=ROS_NAME, desc=ROS_NAME_DESC)),
                      parameter=cast(str, a.opt_str("parameter", "robot_description",
                                                    pattern=PARAM_NAME)))
        elif kind == "topic":
            src = cls(kind, topic=cast(str, a.opt_str("topic", "/robot_description",
                                                      pattern=ROS_NAME, desc=ROS_NAME_DESC)))
        else:
            src = cls(kind, path=a.req_str("path", max_len=MAX_TEXT))
        a.finish()
        return src


Matrix4 = tuple[tuple[float, float, float, float], ...]


def matrix_rows(rows: Any) -> Matrix4:
    """A 4x4 array (numpy's, or lists) as a result's matrix: rows of 4 floats."""
    return tuple((float(row[0]), float(row[1]), float(row[2]), float(row[3])) for row in rows)


def matrix_from(value: Any, path: str, *, rigid: bool = True) -> Matrix4:
    """4 rows of 4 finite numbers; with `rigid`, a rigid transform (as a request's)."""
    if not isinstance(value, list) or len(value) != 4:
        raise WrongTypeError(path, "4 rows of 4 numbers (mm)", json_type(value))
    rows = []
    for i, row in enumerate(value):
        if not isinstance(row, list) or len(row) != 4:
            raise WrongTypeError(f"{path}[{i}]", "a row of 4 numbers", json_type(row))
        rows.append(tuple(check_float(v, f"{path}[{i}][{j}]", -math.inf, math.inf, False)
                          for j, v in enumerate(row)))
    try:
        if rigid:
            validate_matrix(rows, field=path)
    except ConversionError as exc:
        raise OutOfRangeError(exc.field, exc.expected, exc.got) from None
    return cast(Matrix4, tuple(rows))

