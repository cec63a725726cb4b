"""The op as the unit of the command schema: each request class declares, next to its
fields, everything the rest of the daemon derives from it.

    @dataclass(frozen=True)
    class CreateSubscriber(Op, op="create_subscriber", writes=False,
                           creates=Bridge("subscriber", ("topic",), section="subscribers")):
        topic: str
        ...
        def resources(self) -> tuple[Resource, ...]:
            return (TopicUse("topic", self.topic, self.type, writes=False),)

* ``op``: the COMMAND NAME;
* ``writes``: whether it changes the ROS graph or its state (``--read-only`` refuses it);
* ``creates`` / ``removes`` / ``follows``: the bridge it creates (its kind, the fields that
  identify one, its section in the YAML config), removes, or restores state of;
* ``ros_names``: the fields holding ROS names (topics, services, actions, nodes; ``a.b`` for a
  field of a nested value): the dispatcher makes them fully qualified once
  (`Op.with_names`), so the policy, the bridge's identity and the handler all see the
  same name (``cmd`` and ``/cmd`` are one topic);
* ``client_frames``: the fields holding a client's tf frame ids, which the daemon maps to the
  buffer's (``--frame-prefix``) once, in the dispatcher too (`Op.with_frames`);
* ``content``: what a client sees or writes inside its results or its bridge's data, which
  the security policy judges item by item (`CONTENT`): the ``messages`` of its topic, the tf
  ``frames`` or the ``parameters`` they name, the ``files`` they make the daemon read (a
  URDF's meshes). The dispatcher hands its handler a guard built
  for exactly these, so no capability needs to know the policy;
* ``resources()``: what it touches (topics, services, actions, parameters, tf frames, files); the
  security policy judges these, never op names;
* ``result``: the type of its reply's result (`protocol.commands.results.Result`), which its
  handler returns; an op whose result the client reads typed declares it as a second base,
  ``Answered[ItsResult]``, instead;
* ``examples``: one or more valid requests (`Example`) with the resources each must
  declare, from which the tests derive their tables.

Adding an op takes two files: its class here (in the module of its area), with its result
type and examples beside it, and its handler, registered by class in a capability's
``handlers()`` and returning that result type. Nothing else lists ops: the README's op table
is checked against the registry, and the tests draw requests from the class's fields.

A class that leaves out ``op`` or ``writes``, or does not define ``resources`` itself,
fails when its module is imported; so does a second class with the same op. The op lists,
the security decisions, the quotas, the config sections and the client's re-sync state are
all derived from the registry below (`REQUEST_TYPES`, `bridge_kinds`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, Callable, ClassVar, Optional, TypeVar, Union, cast

from protocol.commands.errors import TooLargeError, UnknownOpError, UnsupportedSchemaError
from protocol.commands.errors import WrongTypeError
from protocol.commands.fields import Args
from protocol.commands.results import Result
from protocol.commands.wire import (MAX_OP_NAME_BYTES, SCHEMA_VERSION, dumps, json_type,
                                    jsonable, loads)

__all__ = ["CONTENT", "REQUEST_TYPES", "ActionUse", "Bridge", "BridgeKind", "Example", "FileUse",
           "FrameUse",
           "NameResolver", "Op", "ParameterUse", "Request", "Resource", "ServiceUse", "TopicUse",
           "bridge_kinds", "encode_request", "parse_request"]

# What an op's content may name, judged item by item (`Op.content`).
CONTENT = ("messages", "frames", "parameters", "files")

# (name, field path) -> the fully qualified name; raises a CommandError naming the field.
NameResolver = Callable[[str, str], str]


# ---------------------------------------------------------------------------- resources


@dataclass(frozen=True)
class TopicUse:
    """A ROS topic the op subscribes to (``writes`` False) or publishes on. ``type`` is the
    message type as the request gave it (None when the op does not name one)."""

    field: str
    name: str
    type: Optional[str] = None
    writes: bool = False


@dataclass(frozen=True)
class ServiceUse:
    """A ROS service the op calls (``serves`` False) or offers; ``request`` is the call's
    JSON request (judged for the standard parameter services)."""

    field: str
    name: str
    type: Optional[str] = None
    serves: bool = False
    request: Optional[Mapping[str, Any]] = None


@dataclass(frozen=True)
class ParameterUse:
    """Parameters of a node: ``node`` None is the daemon's own node; ``names`` empty means
    all of the node's parameters (which no name glob can judge beforehand)."""

    field: str
    names: tuple[str, ...]
    node: Optional[str] = None
    node_field: Optional[str] = None
    writes: bool = False


@dataclass(frozen=True)
class FrameUse:
    """A tf frame the op reveals or writes the pose of. ``client_frame``: a client's frame
    id (``--frame-prefix`` applies) rather than one as tf holds it."""

    field: str
    frame: str
    client_frame: bool = True


@dataclass(frozen=True)
class FileUse:
    """A file on the daemon's machine the op makes it read, or write (``writes``)."""

    field: str
    path: str
    writes: bool = False


@dataclass(frozen=True)
class ActionUse:
    """A ROS action the op sends goals to or cancels (``writes``), lists or watches, or
    offers (``serves``). Its hidden services and topics (``<action>/_action/...``) are
    judged by the same rules when a topic or service op names them."""

    field: str
    name: str
    type: Optional[str] = None
    writes: bool = False
    serves: bool = False


Resource = Union[TopicUse, ServiceUse, ParameterUse, FrameUse, FileUse, ActionUse]


# ---------------------------------------------------------------------------- bridges


@dataclass(frozen=True)
class Bridge:
    """What a creating op makes: one bridge of ``kind`` per value of its ``identity``
    fields. ``section``: its list in the YAML config (None: not a start-up bridge);
    ``per_connection``: it lives only as long as the client that made it (so a client does
    not restore it from saved state)."""

    kind: str
    identity: tuple[str, ...]
    section: Optional[str] = None
    per_connection: bool = False


@dataclass(frozen=True)
class BridgeKind:
    """A bridge kind with its create and remove ops, and the ops that restore its state."""

    bridge: Bridge
    create: type[Op]
    remove: type[Op]
    follow_ups: tuple[type[Op], ...] = ()


# ---------------------------------------------------------------------------- examples


@dataclass(frozen=True)
class Example:
    """One valid request of an op, beside its declaration: its JSON ``args``, and the
    resources it must declare, each ``(kind, field, judged name)`` (kind: topic, service,
    action, parameter (name ``node.names``, ``OWN`` for the daemon's node), frame or
    file). tests/protocol derives its tables from these: every op parses its examples,
    declares exactly those resources, and round-trips requests drawn from its fields."""

    args: Mapping[str, Any]
    declares: frozenset[tuple[str, str, str]] = frozenset()

    def __init__(self, args: Mapping[str, Any],
                 declares: Iterable[tuple[str, str, str]] = ()) -> None:
        object.__setattr__(self, "args", args)
        object.__setattr__(self, "declares", frozenset(declares))


# ---------------------------------------------------------------------------- requests

REQUEST_TYPES: dict[str, type[Op]] = {}

R = TypeVar("R", bound="Op")


@dataclass(frozen=True)
class Op:
    """Base of every request: its declarations (see the module) and the shared encoding
    (fields become JSON keys; None fields are left out)."""

    op: ClassVar[str] = ""
    writes: ClassVar[bool] = False
    creates: ClassVar[Optional[Bridge]] = None
    removes: ClassVar[Optional[str]] = None
    follows: ClassVar[Optional[str]] = None
    # Sent by the daemon to a client, never the other way (service_request).
    to_client: ClassVar[bool] = False
    ros_names: ClassVar[tuple[str, ...]] = ()
    client_frames: ClassVar[tuple[str, ...]] = ()
    content: ClassVar[tuple[str, ...]] = ()
    # The type of its result; None for an op the daemon sends to a client.
    result: ClassVar[Optional[type[Result]]] = None
    # Its valid requests, for the tests (`Example`); every op gives at least one.
    examples: ClassVar[tuple[Example, ...]] = ()

    def __init_subclass__(cls, *, op: str = "", writes: Optional[bool] = None,
                          creates: Optional[Bridge] = None, removes: Optional[str] = None,
                          follows: Optional[str] = None, to_client: bool = False,
                          ros_names: tuple[str, ...] = (),
                          client_frames: tuple[str, ...] = (),
                          content: tuple[str, ...] = (), result: Optional[type[Result]] = None,
                          **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)  # `Answered` sets ``result_type`` here
        name = cls.__name__
        if not op:
            raise TypeError(f"{name}: an op declares its name (op=...)")
        if writes is None:
            raise TypeError(f"{name} ({op}): an op declares whether it writes (writes=...)")
        if "resources" not in cls.__dict__:
            raise TypeError(f"{name} ({op}): an op declares what it touches (resources())")
        if op in REQUEST_TYPES:
            raise TypeError(f"{name}: op {op!r} is declared twice (also "
                            f"{REQUEST_TYPES[op].__name__})")
        if sum(x is not None for x in (creates, removes, follows)) > 1:
            raise TypeError(f"{name} ({op}): creates, removes and follows exclude each other")
        annotations = cls.__dict__.get("__annotations__", {})
        if creates is not None:
            missing = [f for f in creates.identity if f not in annotations]
            if missing:
                raise TypeError(f"{name} ({op}): identity field {missing[0]!r} is not a field")
        unknown = [n for n in (*ros_names, *client_frames)
                   if n.partition(".")[0] not in annotations]
        if unknown:
            raise TypeError(f"{name} ({op}): name field {unknown[0]!r} is not a field")
        odd = [kind for kind in content if kind not in CONTENT]
        if odd:
            raise TypeError(f"{name} ({op}): content {odd[0]!r} is not one of "
                            f"{', '.join(CONTENT)}")
        cls.op, cls.writes, cls.to_client, cls.ros_names = op, writes, to_client, ros_names
        cls.client_frames, cls.content = client_frames, content
        cls.creates, cls.removes, cls.follows = creates, removes, follows
        answered = cls.__dict__.get("result_type")
        if result is not None and answered is not None:
            raise TypeError(f"{name} ({op}): its result is declared twice (result= and "
                            f"Answered[...])")
        cls.result = result or answered
        REQUEST_TYPES[op] = cls

    def resources(self) -> tuple[Resource, ...]:
        """What this request touches, for the security policy."""
        raise NotImplementedError  # pragma: no cover - every op defines its own

    def with_names(self: R, resolve: NameResolver) -> R:
        """This request with each of its `ros_names` made fully qualified by `resolve` (an
        empty or absent optional name is left as it is)."""
        changes: dict[str, Any] = {}
        for path in type(self).ros_names:
            head, _, inner = path.partition(".")
            value = changes.get(head, getattr(self, head))
            if inner:
                name = getattr(value, inner, None)
                if name:
                    changes[head] = replace(value, **{inner: resolve(name, path)})
            elif value:
                changes[head] = resolve(value, path)
        return replace(self, **changes) if changes else self

    def with_frames(self: R, resolve: NameResolver) -> R:
        """This request with each of its `client_frames` mapped by `resolve(frame, field)`
        to the frame id the tf buffer holds."""
        changes = {field: resolve(getattr(self, field), field)
                   for field in type(self).client_frames}
        return replace(self, **changes) if changes else self

    def to_args(self) -> dict[str, Any]:
        out: dict[str, Any] = {"schema": SCHEMA_VERSION}
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None or f.default is not None:  # omit unset optionals only
                out[f.name] = jsonable(value)
        return out

    def to_json(self) -> str:
        """The COMMAND text for this request (the op goes in the COMMAND NAME)."""
        return dumps(self.to_args())

    @classmethod
    def from_args(cls, a: Args) -> Op:
        raise NotImplementedError  # pragma: no cover

    @classmethod
    def from_json(cls: type[R], text: str | bytes) -> R:  # noqa: PYI019  (3.9: no Self)
        """Parse and validate this op's COMMAND text."""
        return cast(R, parse_request(cls.op, text))


# Any parsed request (each op's class is an `Op`; no hand-kept union to update).
Request = Op


def bridge_kinds() -> dict[str, BridgeKind]:
    """Every bridge kind with its create, remove and follow-up ops, from the declarations.
    Raises TypeError if a kind lacks its pair or a remove op lacks an identity field."""
    creators = {cls.creates.kind: cls for cls in REQUEST_TYPES.values()
                if cls.creates is not None}
    removers = {cls.removes: cls for cls in REQUEST_TYPES.values() if cls.removes is not None}
    if set(creators) != set(removers):
        odd = sorted(set(creators) ^ set(removers))
        raise TypeError(f"bridge kind {odd[0]!r} has no create/remove pair")
    kinds: dict[str, BridgeKind] = {}
    for kind, create in creators.items():
        bridge = cast(Bridge, create.creates)
        remove = removers[kind]
        names = {f.name for f in fields(remove)}
        missing = [f for f in bridge.identity if f not in names]
        if missing:
            raise TypeError(f"{remove.op}: lacks identity field {missing[0]!r} of {kind}")
        follow = tuple(cls for cls in REQUEST_TYPES.values() if cls.follows == kind)
        kinds[kind] = BridgeKind(bridge, create, remove, follow)
    return kinds


def _check_schema(data: Mapping[str, Any]) -> None:
    if "schema" not in data:
        return
    value = data["schema"]
    if isinstance(value, bool) or not isinstance(value, int):
        raise WrongTypeError("schema", "an integer", json_type(value))
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
    args = Args(data)
    args.allow("schema")
    request = cls.from_args(args)
    args.finish()
    return request


def encode_request(request: Request) -> tuple[str, str]:
    """A request -> (COMMAND NAME, COMMAND text)."""
    return request.op, request.to_json()
