"""Ops about the daemon and the ROS graph as a whole: handshake and listings."""

from __future__ import annotations

from dataclasses import dataclass

from protocol.commands.fields import MAX_NAME, Args
from protocol.commands.op import Op, Resource

__all__ = ["Hello", "ListBridges", "ListServices", "ListTopics"]


@dataclass(frozen=True)
class Hello(Op, op="hello", writes=False):
    """Handshake: the reply says the daemon's schema, version, node name and ops."""

    client: str | None = None

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> Hello:
        return cls(client=a.opt_str("client", max_len=MAX_NAME))


@dataclass(frozen=True)
class ListBridges(Op, op="list_bridges", writes=False):
    """Everything this daemon currently bridges, with device names."""

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ListBridges:
        return cls()


@dataclass(frozen=True)
class ListTopics(Op, op="list_topics", writes=False):
    """The ROS graph's topics and their types."""

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ListTopics:
        return cls()


@dataclass(frozen=True)
class ListServices(Op, op="list_services", writes=False):
    """The ROS graph's services and their types."""

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ListServices:
        return cls()
