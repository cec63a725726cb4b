"""Interface type ops: what a message, service or action type is made of.

`DescribeType` answers with a `TypeDescription`: every message type the asked type is
built from, each with its fields in order, its default value and its constants. A client
builds message objects from it at run time (the reference SlicerROS2 generates one class
per type at build time) and knows, without asking again, which text is a byte array and
which number is an integer.

Field types use the names of ``.msg`` files: ``bool``, ``byte``, ``char``, ``float32``,
``float64``, ``int8`` ... ``uint64``, ``string``, ``wstring``, or a message type
``pkg/msg/Type``. ``array`` is None (a single value), ``"fixed"`` (``T[N]``, ``size`` N) or
``"sequence"`` (``T[]``, or ``T[<=N]`` with ``size`` N).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Optional, cast

from protocol.commands.errors import OutOfRangeError, WrongTypeError
from protocol.commands.fields import MISSING, Args
from protocol.commands.op import Example, Op, Resource
from protocol.commands.results import Result
from protocol.commands.wire import json_type

__all__ = ["BASIC_FIELD_TYPES", "INTERFACE_KINDS", "DescribeType", "FieldDescription",
           "MessageDescription", "TypeDescription"]

INTERFACE_KINDS = ("message", "service", "action")
# The parts of each kind of interface, in the order a client shows them.
_PARTS = {"message": ("message",), "service": ("request", "response"),
          "action": ("goal", "result", "feedback")}
BASIC_FIELD_TYPES = ("bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16",
                     "uint16", "int32", "uint32", "int64", "uint64", "string", "wstring")
_ARRAYS = (None, "fixed", "sequence")
# Bounds on a description a client accepts (a real one is far below them).
_MAX_MESSAGES = 10_000
_MAX_FIELDS = 10_000


@dataclass(frozen=True)
class FieldDescription:
    name: str
    type: str
    array: Optional[str] = None
    size: Optional[int] = None
    string_max: Optional[int] = None

    @property
    def is_message(self) -> bool:
        return "/" in self.type

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "type": self.type}
        for key in ("array", "size", "string_max"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        return out

    @classmethod
    def from_dict(cls, data: Any, path: str) -> FieldDescription:
        a = _args(data, path)
        name = a.req_str("name")
        kind = a.req_str("type")
        if "/" not in kind and kind not in BASIC_FIELD_TYPES:
            raise OutOfRangeError(a.path("type"), "a basic field type or pkg/msg/Type",
                                  repr(kind))
        array = a.opt_str("array")
        if array not in _ARRAYS:
            raise OutOfRangeError(a.path("array"), "fixed or sequence", repr(array))
        size = a.opt_int("size", None, low=0, high=1 << 31)
        string_max = a.opt_int("string_max", None, low=0, high=1 << 31)
        a.finish()
        return cls(name, kind, array, size, string_max)


@dataclass(frozen=True)
class MessageDescription:
    """One message type: its fields in order, the message with every field at its default
    (generic JSON, ROS units), and its constants."""

    type: str
    fields: tuple[FieldDescription, ...]
    default: Mapping[str, Any]
    constants: Mapping[str, Any]

    def field(self, name: str) -> FieldDescription:
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(f"{self.type} has no field {name!r}; its fields: "
                       f"{', '.join(f.name for f in self.fields)}")

    def to_dict(self) -> dict[str, Any]:
        return {"fields": [f.to_dict() for f in self.fields], "default": dict(self.default),
                "constants": dict(self.constants)}

    @classmethod
    def from_dict(cls, type_name: str, data: Any, path: str) -> MessageDescription:
        a = _args(data, path)
        raw = a.raw("fields", True)
        if not isinstance(raw, list) or len(raw) > _MAX_FIELDS:
            raise WrongTypeError(a.path("fields"), f"a list of at most {_MAX_FIELDS} fields",
                                 json_type(raw))
        fields = tuple(FieldDescription.from_dict(f, f"{a.path('fields')}[{i}]")
                       for i, f in enumerate(raw))
        default = a.req_obj_raw("default")
        constants = a.raw("constants", False)
        if constants is MISSING:
            constants = {}
        elif not isinstance(constants, dict):
            raise WrongTypeError(a.path("constants"), "an object", json_type(constants))
        a.finish()
        return cls(type_name, fields, default, constants)


@dataclass(frozen=True)
class TypeDescription(Result):
    """The reply to `DescribeType`: the resolved type, its parts (``message``; ``request``
    and ``response``; ``goal``, ``result`` and ``feedback``), each a message type, and
    every message type they are made of."""

    type: str
    kind: str
    parts: Mapping[str, str]
    messages: Mapping[str, MessageDescription]

    def part(self, name: str) -> MessageDescription:
        return self.messages[self.parts[name]]

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type, "kind": self.kind, "parts": dict(self.parts),
                "messages": {name: m.to_dict() for name, m in self.messages.items()}}

    @classmethod
    def from_dict(cls, data: Any, path: str = "result") -> TypeDescription:
        a = _args(data, path)
        type_name = a.req_str("type")
        kind = a.choice("kind", INTERFACE_KINDS)
        parts_raw = a.req_obj_raw("parts")
        parts = {name: cast(str, parts_raw.get(name)) for name in _PARTS[kind]}
        messages_raw = a.req_obj_raw("messages")
        if len(messages_raw) > _MAX_MESSAGES:
            raise OutOfRangeError(a.path("messages"), f"at most {_MAX_MESSAGES} types",
                                  str(len(messages_raw)))
        a.finish()
        messages = {name: MessageDescription.from_dict(name, m, f"{path}.messages.{name}")
                    for name, m in messages_raw.items()}
        for part, name in parts.items():
            if name not in messages:
                raise OutOfRangeError(f"{path}.parts.{part}", "a type listed in messages",
                                      repr(name))
        for m in messages.values():
            for f in m.fields:
                if f.is_message and f.type not in messages:
                    raise OutOfRangeError(f"{path}.messages.{m.type}", "every nested type "
                                          "listed in messages", repr(f.type))
        return cls(type_name, kind, parts, messages)


def _args(data: Any, path: str) -> Args:
    if not isinstance(data, dict):
        raise WrongTypeError(path, "an object", json_type(data))
    return Args(data, path + ".")


@dataclass(frozen=True)
class DescribeType(Op, op="describe_type", writes=False, result=TypeDescription):
    """Describe an installed interface type: ``kind`` message (``pkg/msg/Type``, a short
    name), service (``pkg/srv/Type``, or a reference service client class name such as
    ``vtkMRMLROS2ServiceClientSpawnNode``) or action (``pkg/action/Type``)."""

    examples = (Example({"type": "PoseArray"}),)

    type: str
    kind: str = "message"

    def resources(self) -> tuple[Resource, ...]:
        return ()  # installed type definitions: no ROS graph resource

    @classmethod
    def from_args(cls, a: Args) -> DescribeType:
        return cls(type=a.req_str("type"), kind=a.choice("kind", INTERFACE_KINDS, "message"))
