"""tf2 ops: streamed and one-shot lookups, broadcasters, one-off broadcasts."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, cast

from protocol.commands.fields import Args
from protocol.commands.op import Bridge, Example, FrameUse, Op, Resource
from protocol.commands.results import Answered, LookupTransformResult, Result
from protocol.commands.values import Matrix4, Stamp, matrix_from

__all__ = ["BroadcastTransform", "BroadcastTransformResult", "CreateTfBroadcaster",
           "CreateTfLookup", "LookupTransform", "RemoveTfBroadcaster", "RemoveTfLookup",
           "TfBridgeRemoved", "TfBroadcasterBridge", "TfLookupBridge"]


@dataclass(frozen=True)
class TfLookupBridge(Result):
    """A streamed lookup, as `create_tf_lookup` and `list_bridges` describe it: its device,
    ``state`` (pending, streaming or error: then ``error`` says why), the TRANSFORMs sent,
    and its rate cap."""

    kind: str  # "tf_lookup"
    parent: str
    child: str
    device: str
    igtl_type: str
    state: str
    messages: int
    error: Optional[str] = None
    rate_hz: Optional[float] = None


@dataclass(frozen=True)
class TfBroadcasterBridge(Result):
    """A broadcaster, as `create_tf_broadcaster` and `list_bridges` describe it."""

    kind: str  # "tf_broadcaster"
    parent: str
    child: str
    device: str
    igtl_type: str
    static: bool
    topic: str
    messages: int


@dataclass(frozen=True)
class TfBridgeRemoved(Result):
    """A removed lookup or broadcaster: its frames and the device it had."""

    parent: str
    child: str
    device: str


@dataclass(frozen=True)
class BroadcastTransformResult(Result):
    """Where a one-off transform went, its stamp and how many subscribers got it."""

    topic: str
    stamp: Stamp
    subscribers: int


def _stamp(a: Args, name: str) -> Stamp | None:
    sub = a.opt_obj(name)
    return Stamp.from_args(sub) if sub is not None else None


@dataclass(frozen=True)
class CreateTfLookup(Op, op="create_tf_lookup", client_frames=("parent", "child"), writes=False,
                     result=TfLookupBridge,
                     creates=Bridge("tf_lookup", ("parent", "child"), section="tf_lookups")):
    """Stream parent->child as a TRANSFORM (mm) whenever it changes, at most ``rate_hz``."""

    examples = (Example(
        {"parent": "a", "child": "b"},
        {("frame", "child", "b"), ("frame", "parent", "a")}),)

    parent: str
    child: str
    rate_hz: float | None = None

    def resources(self) -> tuple[Resource, ...]:
        return (FrameUse("parent", self.parent), FrameUse("child", self.child))

    @classmethod
    def from_args(cls, a: Args) -> CreateTfLookup:
        return cls(parent=a.frame("parent"), child=a.frame("child"), rate_hz=a.rate_hz())


@dataclass(frozen=True)
class RemoveTfLookup(Op, op="remove_tf_lookup", result=TfBridgeRemoved,
                     client_frames=("parent", "child"), writes=False, removes="tf_lookup"):
    examples = (Example({"parent": "a", "child": "b"}),)

    parent: str
    child: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # judged by who made the bridge

    @classmethod
    def from_args(cls, a: Args) -> RemoveTfLookup:
        return cls(parent=a.frame("parent"), child=a.frame("child"))


@dataclass(frozen=True)
class LookupTransform(Op, Answered[LookupTransformResult], op="lookup_transform",
                      client_frames=("parent", "child"), writes=False):
    """One tf lookup; ``time`` omitted = latest; waits up to ``timeout`` seconds."""

    examples = (Example(
        {"parent": "a", "child": "b"},
        {("frame", "child", "b"), ("frame", "parent", "a")}),)

    parent: str
    child: str
    time: Stamp | None = None
    timeout: float = 0.0

    def resources(self) -> tuple[Resource, ...]:
        return (FrameUse("parent", self.parent), FrameUse("child", self.child))

    @classmethod
    def from_args(cls, a: Args) -> LookupTransform:
        return cls(parent=a.frame("parent"), child=a.frame("child"), time=_stamp(a, "time"),
                   timeout=cast(float, a.opt_float("timeout", 0.0, low=0.0, high=60.0)))


@dataclass(frozen=True)
class CreateTfBroadcaster(Op, op="create_tf_broadcaster", result=TfBroadcasterBridge,
                          client_frames=("parent", "child"), writes=True,
                          creates=Bridge("tf_broadcaster", ("parent", "child"),
                                         section="tf_broadcasters")):
    """Broadcast parent->child; ``static`` uses /tf_static (latched)."""

    examples = (Example(
        {"parent": "a", "child": "b"},
        {("frame", "child", "b"), ("frame", "parent", "a")}),)

    parent: str
    child: str
    static: bool = False

    def resources(self) -> tuple[Resource, ...]:
        return (FrameUse("parent", self.parent), FrameUse("child", self.child))

    @classmethod
    def from_args(cls, a: Args) -> CreateTfBroadcaster:
        return cls(parent=a.frame("parent"), child=a.frame("child"),
                   static=a.opt_bool("static", False))


@dataclass(frozen=True)
class RemoveTfBroadcaster(Op, op="remove_tf_broadcaster", result=TfBridgeRemoved,
                          client_frames=("parent", "child"), writes=False,
                          removes="tf_broadcaster"):
    examples = (Example({"parent": "a", "child": "b"}),)

    parent: str
    child: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # judged by who made the bridge

    @classmethod
    def from_args(cls, a: Args) -> RemoveTfBroadcaster:
        return cls(parent=a.frame("parent"), child=a.frame("child"))


@dataclass(frozen=True)
class BroadcastTransform(Op, op="broadcast_transform", result=BroadcastTransformResult,
                         client_frames=("parent", "child"), writes=True):
    """Broadcast one parent->child transform given as a rigid 4x4 matrix in mm (rows);
    ``stamp`` omitted = the daemon's current time."""

    examples = (Example(
        {"parent": "a", "child": "b",
         "matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
        {("frame", "child", "b"), ("frame", "parent", "a")}),)

    parent: str
    child: str
    matrix: Matrix4
    stamp: Stamp | None = None

    def resources(self) -> tuple[Resource, ...]:
        return (FrameUse("parent", self.parent), FrameUse("child", self.child))

    @classmethod
    def from_args(cls, a: Args) -> BroadcastTransform:
        return cls(parent=a.frame("parent"), child=a.frame("child"),
                   matrix=matrix_from(a.any("matrix"), a.path("matrix")),
                   stamp=_stamp(a, "stamp"))
