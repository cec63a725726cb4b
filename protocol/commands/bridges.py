"""Ops about a bridge of any kind: keeping it past the client that made it.

A client's bridges end when its last holder leaves (docs/security.md, "Who owns a bridge"):
`KeepBridge` marks one to stay, as the operator's start-up bridges do.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, TypeVar

from protocol.commands.fields import Args
from protocol.commands.op import NameResolver, Op, Resource, bridge_kinds

__all__ = ["KeepBridge"]

_K = TypeVar("_K", bound="KeepBridge")


def _keepable() -> tuple[str, ...]:
    """The kinds a client may keep: all but those that live with their connection (a
    served service is served by that client: it cannot outlive it)."""
    return tuple(sorted(kind for kind, k in bridge_kinds().items()
                        if not k.bridge.per_connection))


@dataclass(frozen=True)
class KeepBridge(Op, op="keep_bridge", writes=False):
    """Keep the bridge of ``kind`` named by the fields its remove op takes (``topic`` for
    a subscriber, ``parent`` and ``child`` for a tf lookup...) when its clients have left:
    ``{"kind": "subscriber", "topic": "/joint_states"}``. Any client may still remove it.
    It does not write: a connection that may make a subscriber may keep it (a plain
    connector without the daemon's key), and what is kept counts against ``--max-bridges``
    until it is removed."""

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
