"""Ops about a bridge of any kind: keeping it past the client that made it.

A client's bridges end when its last holder leaves (docs/security.md, "Who owns a bridge"):
`KeepBridge` marks one to stay, as the operator's start-up bridges do.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, TypeVar

from protocol.commands.fields import Args
from protocol.commands.op import Example, NameResolver, Op, Resource, bridge_kinds
from protocol.commands.results import Result

__all__ = ["KeepBridge", "KeptBridge"]


@dataclass(frozen=True)
class KeptBridge(Result):
    """The bridge kept: its ``kind``, the fields that name it (``names``, as its remove op
    takes them, sent beside the others), and ``kept``."""

    kind: str
    names: dict[str, str] = field(default_factory=dict)
    kept: bool = True

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        return {"kind": out["kind"], **out.pop("names"), "kept": out["kept"]}

    @classmethod
    def read(cls, a: Args) -> KeptBridge:
        kind = a.choice("kind", _keepable())
        names = {name: str(a.raw(name, True)) for name in bridge_kinds()[kind].bridge.identity}
        return cls(kind=kind, names=names, kept=a.opt_bool("kept", True))

_K = TypeVar("_K", bound="KeepBridge")


def _keepable() -> tuple[str, ...]:
    """The kinds a client may keep: all but those that live with their connection (a
    served service is served by that client: it cannot outlive it)."""
    return tuple(sorted(kind for kind, k in bridge_kinds().items()
                        if not k.bridge.per_connection))


@dataclass(frozen=True)
class KeepBridge(Op, op="keep_bridge", result=KeptBridge, writes=False):
    """Keep the bridge of ``kind`` named by the fields its remove op takes (``topic`` for
    a subscriber, ``parent`` and ``child`` for a tf lookup...) when its clients have left:
    ``{"kind": "subscriber", "topic": "/joint_states"}``. Any client may still remove it.
    It does not write: a connection that may make a subscriber may keep it (a plain
    connector without the daemon's key), and what is kept counts against ``--max-bridges``
    until it is removed."""

    examples = (Example({"kind": "subscriber", "topic": "/a"}),  # judged when it was made
                Example({"kind": "tf_lookup", "parent": "a", "child": "b"}))

    kind: str
    bridge: Op  # the removal that names it: its identity, parsed and resolved as there

    def resources(self) -> tuple[Resource, ...]:
        return ()  # what the bridge touches was judged when it was made

    def with_names(self: _K, resolve: NameResolver) -> _K:
        return replace(self, bridge=self.bridge.with_names(resolve))

    def with_frames(self: _K, resolve: NameResolver) -> _K:
        return replace(self, bridge=self.bridge.with_frames(resolve))

    def to_args(self) -> dict[str, Any]:
        return {**self.bridge.to_args(), "kind": self.kind}

    @classmethod
    def from_args(cls, a: Args) -> KeepBridge:
        kind = a.choice("kind", _keepable())
        return cls(kind=kind, bridge=bridge_kinds()[kind].remove.from_args(a))
