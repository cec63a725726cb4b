"""Typed results: what a successful `Reply` says, for every op a client sends.

Every such op declares its result type next to its fields, and its handler in the daemon
returns it: the reply's JSON is `Result.to_dict` (its fields in order; an optional field
whose default is None is left out while None), so the type is the one description of the
reply on both sides. An op whose result the client reads typed declares it by a second
base::

    @dataclass(frozen=True)
    class Publish(Op, Answered[PublishResult], op="publish", writes=True): ...

and ``request.parse_result(reply.result)`` gives a ``PublishResult``, or raises a
`ResultFormatError` naming the op, the field, what was expected and what came. So a field
renamed on one side fails the type checker and the client's tests, not a user at run time.
Others declare ``result=ItsResult`` (their client still reads the JSON object).

A result reads every field it declares (`Result.read`, derived from the field types unless
a result says more) and ignores the rest (a newer daemon may add fields). A field the
daemon always sends is required, so that a rename is caught at once; one it may leave out,
or one an older daemon left out, has the default the client always assumed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import (Any, ClassVar, Generic, Optional, TypeVar, Union, cast, get_args,
                    get_origin, get_type_hints)

from protocol.commands.errors import CommandError, WrongTypeError
from protocol.commands.fields import MISSING, Args, check_float, check_str
from protocol.commands.values import Matrix4, ParameterValue, Stamp, matrix_from
from protocol.commands.wire import json_type, jsonable
from protocol.errors import ProtocolError

__all__ = ["AdvertiseActionResult", "Answered", "AuthenticateResult", "CallServiceResult",
           "CancelGoalResult", "DescribeRobotJointsResult", "GetLastMessageResult",
           "GetParametersResult", "HelloAuth", "HelloResult",
           "ListParametersResult", "ListServicesResult", "ListTopicsResult",
           "LookupTransformResult", "ObserveParametersResult", "ParameterOutcome",
           "PublishResult", "Result", "ResultFormatError", "read_field", "SendGoalResult",
           "SetParametersResult", "SetRobotJointsResult", "SolveIkResult"]

_U32 = (1 << 32) - 1
_COUNT_MAX = (1 << 63) - 1


class ResultFormatError(ProtocolError):
    """A successful reply whose result is not what the op's result type expects (a daemon
    of another schema, or a field renamed on one side); names ``<op>.result.<field>``."""


T = TypeVar("T", bound="Result")
R = TypeVar("R", bound="Result")


class Result:
    """Base of the typed results (frozen dataclasses): `to_dict` is the reply's JSON
    object, `read` its reader. ``large``: a reply that may be long (a listing), which the
    daemon encodes off its event loop."""

    large: ClassVar[bool] = False

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of this result: its fields in order, an optional one (default
        None) left out while None."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(cast(Any, self)):
            value = getattr(self, f.name)
            if value is None and f.default is None:
                continue
            out[f.name] = jsonable(value)
        return out

    @classmethod
    def read(cls: type[T], a: Args) -> T:  # noqa: PYI019  (3.9: no Self)
        """Each declared field, read as its type says (`read_field`); a result whose
        fields say less than the client needs reads them itself."""
        hints = get_type_hints(cls)
        values: dict[str, Any] = {}
        for f in dataclasses.fields(cast(Any, cls)):
            optional = (f.default is not dataclasses.MISSING
                        or f.default_factory is not dataclasses.MISSING)
            if optional and a.raw(f.name, False) is MISSING:
                continue  # its default
            values[f.name] = read_field(a, f.name, hints[f.name])
        return cls(**values)

    @classmethod
    def parse(cls: type[T], op: str, data: Mapping[str, Any]) -> T:  # noqa: PYI019
        """The result of `op`'s reply, or `ResultFormatError` naming the field at fault."""
        try:
            return cls.read(Args(data, f"{op}.result."))
        except CommandError as error:  # a reader's error, about the reply this time
            raise ResultFormatError(error.field, error.expected, error.got) from None


class Answered(Generic[R]):
    """Second base of an op whose result a client reads: ``Answered[ItsResult]``."""

    op: ClassVar[str]
    result_type: ClassVar[type[Result]]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        for base in cls.__dict__.get("__orig_bases__", ()):
            if get_origin(base) is Answered:
                cls.result_type = get_args(base)[0]

    def to_args(self) -> dict[str, Any]:
        raise NotImplementedError  # pragma: no cover - `Op.to_args` comes first in the MRO

    def parse_result(self, data: Mapping[str, Any]) -> R:
        """This request's reply result (`Reply.result`) as its typed result."""
        return cast(R, self.result_type.parse(self.op, data))


# ---------------------------------------------------------------------------- readers


def _object(a: Args, name: str) -> dict[str, Any]:
    value = a.raw(name, True)
    if not isinstance(value, dict):
        raise WrongTypeError(a.path(name), "an object", json_type(value))
    return value


def _objects(a: Args, name: str) -> tuple[dict[str, Any], ...]:
    value = a.raw(name, True)
    if not isinstance(value, list):
        raise WrongTypeError(a.path(name), "an array of objects", json_type(value))
    for i, item in enumerate(value):
        if not isinstance(item, dict):
            raise WrongTypeError(f"{a.path(name)}[{i}]", "an object", json_type(item))
    return tuple(value)


def _numbers(a: Args, name: str) -> tuple[float, ...]:
    value = a.raw(name, True)
    if not isinstance(value, list):
        raise WrongTypeError(a.path(name), "an array of numbers", json_type(value))
    return tuple(check_float(v, f"{a.path(name)}[{i}]", float("-inf"), float("inf"), False)
                 for i, v in enumerate(value))


def _parameter_values(a: Args, name: str) -> dict[str, ParameterValue]:
    return {key: ParameterValue.from_json_value(raw, f"{a.path(name)}.{key}")
            for key, raw in _object(a, name).items()}


def _optional_of(hint: Any) -> Any:
    """X for ``Optional[X]``, else None."""
    args = get_args(hint)
    if get_origin(hint) is Union and len(args) == 2 and type(None) in args:
        return args[0] if args[1] is type(None) else args[1]
    return None


def read_field(a: Args, name: str, hint: Any) -> Any:
    """Field ``name`` of a result, read as its type ``hint`` says; an error names its path.
    Strings, numbers, flags, objects, lists of them, stamps, parameter values and nested
    results; ``Any`` as it came."""
    inner = _optional_of(hint)
    if inner is not None:
        return None if a.raw(name, False) is MISSING else read_field(a, name, inner)
    path = a.path(name)
    if hint is Any:
        return a.raw(name, True)
    if hint is str:
        return check_str(a.raw(name, True), path, 1 << 30, True, None, "")
    if hint is bool:
        return _flag(a, name)
    if hint is int:
        return a.req_int(name, low=-(1 << 63), high=_COUNT_MAX)
    if hint is float:
        return check_float(a.raw(name, True), path, float("-inf"), float("inf"), False)
    if hint == dict[str, Any]:
        return _object(a, name)
    if hint == tuple[dict[str, Any], ...]:
        return _objects(a, name)
    if hint == tuple[str, ...]:
        return a.str_list(name)
    if hint == tuple[float, ...]:
        return _numbers(a, name)
    if hint == dict[str, ParameterValue]:
        return _parameter_values(a, name)
    if hint == dict[str, float]:
        return _positions(a, name)
    if hint is Stamp:
        return Stamp.from_args(Args(_object(a, name), path + "."))
    if hint is ParameterValue:
        return ParameterValue.from_json_value(a.raw(name, True), path)
    if isinstance(hint, type) and issubclass(hint, Result):
        return hint.read(Args(_object(a, name), path + "."))
    raise TypeError(f"{path}: no reader for a field of type {hint!r}")  # a result's bug


def _or(a: Args, name: str, hint: Any, default: Any) -> Any:
    """Field ``name`` read as `read_field` reads it, or ``default`` when absent."""
    return default if a.raw(name, False) is MISSING else read_field(a, name, hint)


def _device(a: Args) -> str:
    return a.req_str("device", allow_empty=True)


def _count(a: Args, name: str) -> int:
    return a.req_int(name, low=0, high=_COUNT_MAX)


def _flag(a: Args, name: str) -> bool:
    value = a.raw(name, True)
    if not isinstance(value, bool):
        raise WrongTypeError(a.path(name), "true or false", json_type(value))
    return value


# ---------------------------------------------------------------------------- results


@dataclass(frozen=True)
class HelloAuth(Result):
    """What a connection may do: whether it writes, and when not, why, and the challenge
    the daemon's key answers (`Authenticate`), if it has one."""

    writes: bool = True
    why: Optional[str] = None
    challenge: Optional[str] = None

    @classmethod
    def read(cls, a: Args) -> HelloAuth:
        return cls(writes=a.opt_bool("writes", True),
                   why=a.opt_str("why", None, max_len=1 << 16, allow_empty=True),
                   challenge=a.opt_str("challenge", None, max_len=1024,
                                       allow_empty=True) or None)


@dataclass(frozen=True)
class HelloResult(Result):
    """The handshake: the daemon's schema, version, node and ops, what this connection may
    do (``auth``; absent for the operator's start-up config), its heartbeat, the clock of
    stream stamps, and the display rate its streams are paced to."""

    schema: int = 1
    version: str = ""
    node: str = ""
    ops: tuple[str, ...] = ()
    auth: Optional[HelloAuth] = None
    heartbeat: Optional[float] = None
    clock_ms: Optional[int] = None
    display_hz: Optional[float] = None

    @property
    def writes(self) -> bool:
        return self.auth.writes if self.auth is not None else True

    @property
    def challenge(self) -> Optional[str]:
        return self.auth.challenge if self.auth is not None else None

    @classmethod
    def read(cls, a: Args) -> HelloResult:
        auth = a.opt_obj("auth")
        return cls(schema=cast(int, a.opt_int("schema", 1, low=0, high=_U32)),
                   version=cast(str, a.opt_str("version", "", allow_empty=True)),
                   node=cast(str, a.opt_str("node", "", allow_empty=True)),
                   ops=a.str_list("ops", required=False),
                   auth=HelloAuth.read(auth) if auth is not None else None,
                   heartbeat=a.opt_float("heartbeat", None, low=0.0, high=3600.0),
                   clock_ms=a.opt_int("clock_ms", None, low=0, high=_U32),
                   display_hz=a.opt_float("display_hz", None, low=0.0, high=1e6))


@dataclass(frozen=True)
class AuthenticateResult(Result):
    writes: bool

    @classmethod
    def read(cls, a: Args) -> AuthenticateResult:
        return cls(writes=_flag(a, "writes"))


@dataclass(frozen=True)
class ListTopicsResult(Result):
    """The graph's topics, each an object (``topic``, ``types``, ``publishers``), as the
    daemon lists them."""

    large = True

    topics: tuple[dict[str, Any], ...]

    @classmethod
    def read(cls, a: Args) -> ListTopicsResult:
        return cls(topics=_objects(a, "topics"))


@dataclass(frozen=True)
class ListServicesResult(Result):
    large = True

    services: tuple[dict[str, Any], ...]

    @classmethod
    def read(cls, a: Args) -> ListServicesResult:
        return cls(services=_objects(a, "services"))


@dataclass(frozen=True)
class PublishResult(Result):
    topic: str
    subscribers: int

    @classmethod
    def read(cls, a: Args) -> PublishResult:
        return cls(topic=_or(a, "topic", str, ""), subscribers=_count(a, "subscribers"))


@dataclass(frozen=True)
class GetLastMessageResult(Result):
    """The subscriber's message count and whether it holds a last message; if so, its
    ``text`` (YAML or JSON) and ``value`` (as a client's value holds it); "" before any."""

    topic: str
    type: str
    count: int
    received: bool
    text: str = ""
    value: Any = None

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        if self.received:  # a message's value may be null: it is sent all the same
            out["value"] = self.value
        else:
            del out["text"]
        return out

    @classmethod
    def read(cls, a: Args) -> GetLastMessageResult:
        text = cast(str, a.opt_str("text", "", max_len=1 << 30, allow_empty=True))
        return cls(topic=_or(a, "topic", str, ""), type=_or(a, "type", str, ""),
                   count=_count(a, "count"), received=_or(a, "received", bool, bool(text)),
                   text=text, value=a.raw("value", True) if "value" in a.keys() else None)


def _node(a: Args) -> str:
    """The node a parameter result names (older daemons did not say: "")."""
    return cast(str, a.opt_str("node", "", allow_empty=True))


@dataclass(frozen=True)
class ListParametersResult(Result):
    """The node's parameters a client may see, and each one's type."""

    node: str
    names: tuple[str, ...]
    types: dict[str, str]

    @classmethod
    def read(cls, a: Args) -> ListParametersResult:
        types = _object(a, "types") if a.raw("types", False) is not MISSING else {}
        return cls(node=_node(a), names=a.str_list("names"),
                   types={k: v for k, v in types.items() if isinstance(v, str)})


@dataclass(frozen=True)
class GetParametersResult(Result):
    """Parameter values of a node (`get_parameters`), or of the daemon's own
    (`server_get_parameters`)."""

    node: str
    values: dict[str, ParameterValue]

    @classmethod
    def read(cls, a: Args) -> GetParametersResult:
        return cls(node=_node(a), values=_parameter_values(a, "values"))


@dataclass(frozen=True)
class ParameterOutcome(Result):
    """One parameter of a `SetParameters`: set, or refused by the node (and why)."""

    ok: bool
    reason: str = ""


@dataclass(frozen=True)
class SetParametersResult(Result):
    node: str
    results: dict[str, ParameterOutcome]

    @classmethod
    def read(cls, a: Args) -> SetParametersResult:
        results = {}
        for name, raw in _object(a, "results").items():
            if not isinstance(raw, dict):
                raise WrongTypeError(f"{a.path('results')}.{name}", "an object",
                                     json_type(raw))
            outcome = Args(raw, f"{a.path('results')}.{name}.")
            results[name] = ParameterOutcome(
                ok=outcome.opt_bool("ok", False),
                reason=cast(str, outcome.opt_str("reason", "", max_len=1 << 16,
                                                 allow_empty=True)))
        return cls(node=_node(a), results=results)


@dataclass(frozen=True)
class ObserveParametersResult(Result):
    """The parameter client's device, the names it observes, whether the node answers
    now, and the observed parameters' values so far."""

    node: str
    device: str
    observed: tuple[str, ...]
    ready: bool
    values: dict[str, ParameterValue]

    @classmethod
    def read(cls, a: Args) -> ObserveParametersResult:
        observed = a.str_list("observed", required=False)
        return cls(node=_node(a), device=cast(str, a.opt_str("device", "", allow_empty=True)),
                   observed=observed, ready=_flag(a, "ready"),
                   values=_parameter_values(a, "values"))


@dataclass(frozen=True)
class LookupTransformResult(Result):
    """The transform parent <- child: as a matrix (mm, rows), as tf holds it (translation
    in m, quaternion x y z w), and its stamp."""

    parent: str
    child: str
    matrix: Matrix4  # mm, rows
    translation: tuple[float, ...]
    rotation: tuple[float, ...]
    stamp: Stamp

    @classmethod
    def read(cls, a: Args) -> LookupTransformResult:
        # The matrix is what a client reads; the rest as a daemon before 2026-11 left out.
        matrix = matrix_from(a.any("matrix"), a.path("matrix"), rigid=False)
        return cls(parent=_or(a, "parent", str, ""), child=_or(a, "child", str, ""),
                   matrix=matrix, translation=_or(a, "translation", tuple[float, ...], ()),
                   rotation=_or(a, "rotation", tuple[float, ...], ()),
                   stamp=_or(a, "stamp", Stamp, Stamp(0)))


@dataclass(frozen=True)
class CallServiceResult(Result):
    service: str
    type: str
    response: dict[str, Any]

    @classmethod
    def read(cls, a: Args) -> CallServiceResult:
        return cls(service=_or(a, "service", str, ""), type=_or(a, "type", str, ""),
                   response=_object(a, "response"))


@dataclass(frozen=True)
class DescribeRobotJointsResult(Result):
    """Where the robot's state publisher listens, and its joints as the daemon describes
    them (objects with ``name``, ``type``, limits, ``mimic``, ``actuated``)."""

    name: str
    robot: str  # the URDF's own name
    joint_states_topic: str
    joints: tuple[dict[str, Any], ...]

    @classmethod
    def read(cls, a: Args) -> DescribeRobotJointsResult:
        return cls(name=_or(a, "name", str, ""), robot=_or(a, "robot", str, ""),
                   joint_states_topic=a.req_str("joint_states_topic"),
                   joints=_objects(a, "joints"))


@dataclass(frozen=True)
class SetRobotJointsResult(Result):
    """The joint positions published, the added mimic joints included."""

    name: str
    topic: str
    positions: dict[str, float]
    subscribers: int

    @classmethod
    def read(cls, a: Args) -> SetRobotJointsResult:
        return cls(name=_or(a, "name", str, ""), topic=_or(a, "topic", str, ""),
                   positions=_positions(a), subscribers=_or(a, "subscribers", int, 0))


def _positions(a: Args, name: str = "positions") -> dict[str, float]:
    """A result's ``positions``: joint -> a finite number."""
    path = a.path(name)
    positions = {}
    for joint, value in _object(a, name).items():
        check_str(joint, path, 1 << 10, False, None, "")
        positions[joint] = check_float(value, f"{path}.{joint}", float("-inf"), float("inf"),
                                       False)
    return positions


@dataclass(frozen=True)
class SendGoalResult(Result):
    """The accepted goal's device, where its feedback and result events come."""

    action: str
    type: str
    goal_id: str
    device: str
    status: str  # "accepted"
    stamp: dict[str, Any]  # when the server accepted it (builtin_interfaces/Time)

    @classmethod
    def read(cls, a: Args) -> SendGoalResult:
        device = _device(a)
        return cls(action=_or(a, "action", str, ""), type=_or(a, "type", str, ""),
                   goal_id=_or(a, "goal_id", str, ""), device=device,
                   status=_or(a, "status", str, "accepted"),
                   stamp=_or(a, "stamp", dict[str, Any], {}))


@dataclass(frozen=True)
class CancelGoalResult(Result):
    """Whether the server is cancelling the goal, and its return code (name)."""

    action: str
    goal_id: str
    accepted: bool
    return_code: int
    return_name: str

    @classmethod
    def read(cls, a: Args) -> CancelGoalResult:
        accepted = _flag(a, "accepted")
        return cls(action=_or(a, "action", str, ""), goal_id=_or(a, "goal_id", str, ""),
                   accepted=accepted, return_code=_or(a, "return_code", int, 0),
                   return_name=_or(a, "return_name", str, ""))


@dataclass(frozen=True)
class AdvertiseActionResult(Result):
    """A served action, as `advertise_action` and `list_bridges` describe it: the device
    its goals, decisions and cancels come on, the goals it received, whether it decides
    (accepts or rejects) goals itself."""

    kind: str  # "served_action"
    action: str
    type: str
    device: str
    goals: int
    decides: bool

    @classmethod
    def read(cls, a: Args) -> AdvertiseActionResult:
        device = _device(a)
        return cls(kind=_or(a, "kind", str, "served_action"), action=_or(a, "action", str, ""),
                   type=_or(a, "type", str, ""), device=device,
                   goals=_or(a, "goals", int, 0), decides=_or(a, "decides", bool, False))


@dataclass(frozen=True)
class SolveIkResult(Result):
    """A solve_ik answer: ``solved``, the actuated joints' ``positions`` (of the solution,
    or of the best attempt), the residual of that attempt (mm, degrees), and when not
    solved the ``failure`` (``reason``: unreachable, joint_limit or collision; ``text``;
    ``joints`` past their limits; ``link`` and ``obstacle`` in contact)."""

    name: str
    tip: str
    solved: bool
    positions: dict[str, float]
    residual_mm: float
    residual_deg: float
    iterations: int
    attempts: int
    seed: str  # where the start came from: "given", "joint_states" or "zero"
    # Each link's pose at those positions, in the root link's frame (mm): a preview's.
    links: dict[str, Matrix4]
    failure: Optional[dict[str, Any]] = None
    # Obstacles this solve could not take into account, and why (none: left out).
    unplaced: Optional[tuple[dict[str, Any], ...]] = None

    @classmethod
    def read(cls, a: Args) -> SolveIkResult:
        links_path = a.path("links")
        links = {}
        for link, rows in (_object(a, "links") if a.raw("links", False) is not None
                           else {}).items():
            check_str(link, links_path, 1 << 10, False, None, "")
            links[link] = matrix_from(rows, f"{links_path}.{link}")
        failure = a.raw("failure", False)
        return cls(name=_or(a, "name", str, ""), tip=_or(a, "tip", str, ""),
                   solved=a.opt_bool("solved", False), positions=_positions(a),
                   residual_mm=cast(float, a.opt_float("residual_mm", 0.0, low=0.0,
                                                       high=float("inf"))),
                   residual_deg=cast(float, a.opt_float("residual_deg", 0.0, low=0.0,
                                                        high=180.0)),
                   iterations=a.req_int("iterations", low=0, high=_COUNT_MAX),
                   attempts=a.req_int("attempts", low=0, high=_COUNT_MAX),
                   seed=a.req_str("seed"),
                   failure=dict(failure) if isinstance(failure, dict) else None,
                   links=links,
                   unplaced=_or(a, "unplaced", tuple[dict[str, Any], ...], None))
