"""Ops about the daemon and the ROS graph as a whole: handshake, credential, listings."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from protocol.auth import NONCE
from protocol.commands.fields import MAX_NAME, Args
from protocol.commands.op import Example, Op, Resource
from protocol.commands.results import (Answered, AuthenticateResult, HelloResult,
                                       ListServicesResult, ListTopicsResult, Result,
                                       read_field)

_PROOF = re.compile(r"[0-9a-f]{64}\Z")
DISPLAY_HZ = 60.0  # what a display shows: the message stream's pace, and 3D Slicer's
DISPLAY_HZ_MIN, DISPLAY_HZ_MAX = 1.0, 1000.0  # a display's frame rate, as a client asks it

__all__ = ["DISPLAY_HZ", "DISPLAY_HZ_MAX", "DISPLAY_HZ_MIN", "Authenticate", "Hello",
           "ListBridges", "ListBridgesResult", "ListServices", "ListTopics"]


@dataclass(frozen=True)
class ListBridgesResult(Result):
    """Every bridge (each an object naming its ``kind``), the hub's devices and clients,
    and each capability's other state under its own key (``state``: those keys, sent
    beside the others)."""

    large = True

    bridges: tuple[dict[str, Any], ...]
    devices: tuple[str, ...]
    clients: tuple[dict[str, Any], ...]
    hub_dropped: int
    state: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        state = out.pop("state")
        return {**out, **state}

    @classmethod
    def read(cls, a: Args) -> ListBridgesResult:
        known = ("bridges", "devices", "clients", "hub_dropped")
        return cls(bridges=read_field(a, "bridges", tuple[dict[str, Any], ...]),
                   devices=read_field(a, "devices", tuple[str, ...]),
                   clients=read_field(a, "clients", tuple[dict[str, Any], ...]),
                   hub_dropped=read_field(a, "hub_dropped", int),
                   state={k: a.raw(k, True) for k in a.keys() if k not in known})


@dataclass(frozen=True)
class Hello(Op, Answered[HelloResult], op="hello", writes=False):
    """Handshake: the reply says the daemon's schema, version, node name and ops, whether
    this connection may write and, when the daemon has a key, the challenge to answer with
    `Authenticate`. ``heartbeat``: send this connection a STATUS every that many seconds
    (protocol/liveness.py), so that it notices a dead link. ``stamps``: this client drops
    stream values that come late by their freshness stamps (protocol/freshness.py); a
    client that shows whatever arrives (3D Slicer's connector) leaves it false, and the
    daemon cuts its dead link before a backlog could age past the bound. ``display_hz``:
    this client shows streams on a display (3D Slicer): send it each stream's newest value
    that many times a second at most, not every value (a value waits at most a frame)."""

    examples = (Example({}),)

    client: str | None = None
    heartbeat: float | None = None
    stamps: bool = False
    display_hz: float | None = None

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> Hello:
        return cls(client=a.opt_str("client", max_len=MAX_NAME),
                   heartbeat=a.opt_float("heartbeat", None, low=0.1, high=60.0),
                   stamps=a.opt_bool("stamps", False),
                   display_hz=a.opt_float("display_hz", None, low=DISPLAY_HZ_MIN,
                                          high=DISPLAY_HZ_MAX))


@dataclass(frozen=True)
class Authenticate(Op, Answered[AuthenticateResult], op="authenticate", writes=False):
    """Present the daemon's key (protocol/auth.py): a fresh ``nonce`` of this client's (32
    to 128 hex digits) and ``proof``, the HMAC of the challenge `hello` gave with it. Once
    accepted, this connection may write (ops that write, data sent to publishers)."""

    examples = (Example(
        {"nonce": "00000000000000000000000000000000",
         "proof": "1111111111111111111111111111111111111111111111111111111111111111"}),)

    nonce: str
    proof: str

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> Authenticate:
        return cls(nonce=a.req_str("nonce", pattern=NONCE, desc="32 to 128 hex digits"),
                   proof=a.req_str("proof", pattern=_PROOF, desc="64 hex digits"))


@dataclass(frozen=True)
class ListBridges(Op, op="list_bridges", writes=False, content=("frames",),
                  result=ListBridgesResult):
    """Everything this daemon currently bridges, with device names."""

    examples = (Example({}),)

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ListBridges:
        return cls()


@dataclass(frozen=True)
class ListTopics(Op, Answered[ListTopicsResult], op="list_topics", writes=False):
    """The ROS graph's topics and their types."""

    examples = (Example({}),)

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ListTopics:
        return cls()


@dataclass(frozen=True)
class ListServices(Op, Answered[ListServicesResult], op="list_services", writes=False):
    """The ROS graph's services and their types."""

    examples = (Example({}),)

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ListServices:
        return cls()
