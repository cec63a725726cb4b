"""Typed results: what a successful `Reply` says, for the ops whose result a client reads.

An op declares its result type next to its fields, by a second base::

    @dataclass(frozen=True)
    class Publish(Op, Answered[PublishResult], op="publish", writes=True): ...

and ``request.parse_result(reply.result)`` gives a ``PublishResult``, or raises a
`ResultFormatError` naming the op, the field, what was expected and what came. So a field
renamed on one side fails the type checker and the client's tests, not a user at run time.

Results read only the fields a client uses and ignore the rest (a newer daemon may add
fields). A field the daemon always sends is required, so that a rename is caught at once;
one it may leave out has the default the client always assumed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Generic, Optional, TypeVar, cast, get_args, get_origin

from protocol.commands.errors import CommandError, WrongTypeError
from protocol.commands.fields import Args, check_float, check_str
from protocol.commands.values import Matrix4, ParameterValue, matrix_from
from protocol.commands.wire import json_type
from protocol.errors import ProtocolError

__all__ = ["AdvertiseActionResult", "Answered", "AuthenticateResult", "CallServiceResult",
           "CancelGoalResult", "DescribeRobotJointsResult", "GetLastMessageResult",
           "GetParametersResult", "HelloResult",
           "ListParametersResult", "ListServicesResult", "ListTopicsResult",
           "LookupTransformResult", "ObserveParametersResult", "ParameterOutcome",
           "PublishResult", "Result", "ResultFormatError", "SendGoalResult",
           "SetParametersResult", "SetRobotJointsResult", "SolveIkResult"]

_U32 = (1 << 32) - 1
_COUNT_MAX = (1 << 63) - 1


class ResultFormatError(ProtocolError):
    """A successful reply whose result is not what the op's result type expects (a daemon
    of another schema, or a field renamed on one side); names ``<op>.result.<field>``."""


T = TypeVar("T", bound="Result")
R = TypeVar("R", bound="Result")


class Result:
    """Base of the typed results: each reads its fields from an `Args` in `read`."""

    @classmethod
    def read(cls: type[T], a: Args) -> T:  # noqa: PYI019  (3.9: no Self)
        raise NotImplementedError  # pragma: no cover - every result defines its own

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


def _parameter_values(a: Args, name: str) -> dict[str, ParameterValue]:
    return {key: ParameterValue.from_json_value(raw, f"{a.path(name)}.{key}")
            for key, raw in _object(a, name).items()}


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
class HelloResult(Result):
    """The handshake: the daemon's node, and what this connection may do (``writes``; the
    ``challenge`` a key answers), its heartbeat, the clock of stream stamps, and the
    display rate its streams are paced to."""

    node: str = ""
    writes: bool = True
    challenge: Optional[str] = None
    heartbeat: Optional[float] = None
    clock_ms: Optional[int] = None
    display_hz: Optional[float] = None

    @classmethod
    def read(cls, a: Args) -> HelloResult:
        auth = a.opt_obj("auth")
        writes, challenge = True, None
        if auth is not None:
            writes = auth.opt_bool("writes", True)
            challenge = auth.opt_str("challenge", None, max_len=1024, allow_empty=True)
        return cls(node=cast(str, a.opt_str("node", "", allow_empty=True)), writes=writes,
                   challenge=challenge or None,
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
    """The graph's topics, each an object (``name``, ``types``), as the daemon lists them."""

    topics: tuple[dict[str, Any], ...]

    @classmethod
    def read(cls, a: Args) -> ListTopicsResult:
        return cls(topics=_objects(a, "topics"))


@dataclass(frozen=True)
class ListServicesResult(Result):
    services: tuple[dict[str, Any], ...]

    @classmethod
    def read(cls, a: Args) -> ListServicesResult:
        return cls(services=_objects(a, "services"))


@dataclass(frozen=True)
class PublishResult(Result):
    subscribers: int

    @classmethod
    def read(cls, a: Args) -> PublishResult:
        return cls(subscribers=_count(a, "subscribers"))


@dataclass(frozen=True)
class GetLastMessageResult(Result):
    """The subscriber's last message as text ("" before any) and its message count."""

    text: str
    count: int

    @classmethod
    def read(cls, a: Args) -> GetLastMessageResult:
        return cls(text=cast(str, a.opt_str("text", "", max_len=1 << 30, allow_empty=True)),
                   count=_count(a, "count"))


@dataclass(frozen=True)
class ListParametersResult(Result):
    names: tuple[str, ...]

    @classmethod
    def read(cls, a: Args) -> ListParametersResult:
        return cls(names=a.str_list("names"))


@dataclass(frozen=True)
class GetParametersResult(Result):
    values: dict[str, ParameterValue]

    @classmethod
    def read(cls, a: Args) -> GetParametersResult:
        return cls(values=_parameter_values(a, "values"))


@dataclass(frozen=True)
class ParameterOutcome:
    """One parameter of a `SetParameters`: set, or refused by the node (and why)."""

    ok: bool
    reason: str = ""


@dataclass(frozen=True)
class SetParametersResult(Result):
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
        return cls(results=results)


@dataclass(frozen=True)
class ObserveParametersResult(Result):
    """Whether the node answers now, and the observed parameters' values so far."""

    ready: bool
    values: dict[str, ParameterValue]

    @classmethod
    def read(cls, a: Args) -> ObserveParametersResult:
        return cls(ready=_flag(a, "ready"), values=_parameter_values(a, "values"))


@dataclass(frozen=True)
class LookupTransformResult(Result):
    matrix: Matrix4  # mm, rows

    @classmethod
    def read(cls, a: Args) -> LookupTransformResult:
        return cls(matrix=matrix_from(a.any("matrix"), a.path("matrix"), rigid=False))


@dataclass(frozen=True)
class CallServiceResult(Result):
    response: dict[str, Any]

    @classmethod
    def read(cls, a: Args) -> CallServiceResult:
        return cls(response=_object(a, "response"))


@dataclass(frozen=True)
class DescribeRobotJointsResult(Result):
    """Where the robot's state publisher listens, and its joints as the daemon describes
    them (objects with ``name``, ``type``, limits, ``mimic``, ``actuated``)."""

    joint_states_topic: str
    joints: tuple[dict[str, Any], ...]

    @classmethod
    def read(cls, a: Args) -> DescribeRobotJointsResult:
        return cls(joint_states_topic=a.req_str("joint_states_topic"),
                   joints=_objects(a, "joints"))


@dataclass(frozen=True)
class SetRobotJointsResult(Result):
    """The joint positions published, the added mimic joints included."""

    positions: dict[str, float]

    @classmethod
    def read(cls, a: Args) -> SetRobotJointsResult:
        return cls(positions=_positions(a))


def _positions(a: Args) -> dict[str, float]:
    """A result's ``positions``: joint -> a finite number."""
    path = a.path("positions")
    positions = {}
    for joint, value in _object(a, "positions").items():
        check_str(joint, path, 1 << 10, False, None, "")
        positions[joint] = check_float(value, f"{path}.{joint}", float("-inf"), float("inf"),
                                       False)
    return positions


@dataclass(frozen=True)
class SendGoalResult(Result):
    """The accepted goal's device, where its feedback and result events come."""

    device: str

    @classmethod
    def read(cls, a: Args) -> SendGoalResult:
        return cls(device=_device(a))


@dataclass(frozen=True)
class CancelGoalResult(Result):
    accepted: bool

    @classmethod
    def read(cls, a: Args) -> CancelGoalResult:
        return cls(accepted=_flag(a, "accepted"))


@dataclass(frozen=True)
class AdvertiseActionResult(Result):
    """The device the served action's goals, decisions and cancels come on."""

    device: str

    @classmethod
    def read(cls, a: Args) -> AdvertiseActionResult:
        return cls(device=_device(a))


@dataclass(frozen=True)
class SolveIkResult(Result):
    """A solve_ik answer: ``solved``, the actuated joints' ``positions`` (of the solution,
    or of the best attempt), the residual of that attempt (mm, degrees), and when not
    solved the ``failure`` (``reason``: unreachable, joint_limit or collision; ``text``;
    ``joints`` past their limits; ``link`` and ``obstacle`` in contact)."""

    solved: bool
    positions: dict[str, float]
    residual_mm: float
    residual_deg: float
    iterations: int
    attempts: int
    seed: str  # where the start came from: "given", "joint_states" or "zero"
    failure: Optional[dict[str, Any]] = None
    # Each link's pose at those positions, in the root link's frame (mm): a preview's.
    links: dict[str, Matrix4] = field(default_factory=dict)

    @classmethod
    def read(cls, a: Args) -> SolveIkResult:
        links_path = a.path("links")
        links = {}
        for link, rows in (_object(a, "links") if a.raw("links", False) is not None
                           else {}).items():
            check_str(link, links_path, 1 << 10, False, None, "")
            links[link] = matrix_from(rows, f"{links_path}.{link}")
        failure = a.raw("failure", False)
        return cls(solved=a.opt_bool("solved", False), positions=_positions(a),
                   residual_mm=cast(float, a.opt_float("residual_mm", 0.0, low=0.0,
                                                       high=float("inf"))),
                   residual_deg=cast(float, a.opt_float("residual_deg", 0.0, low=0.0,
                                                        high=180.0)),
                   iterations=a.req_int("iterations", low=0, high=_COUNT_MAX),
                   attempts=a.req_int("attempts", low=0, high=_COUNT_MAX),
                   seed=a.req_str("seed"),
                   failure=dict(failure) if isinstance(failure, dict) else None,
                   links=links)
