"""What the service and action capabilities share about entities a client serves (a ROS
service or action advertised by a client): who may advertise and unadvertise, and how a
client's answer to the daemon's COMMAND is read."""

from __future__ import annotations

from typing import Any, Iterable, Mapping, Optional, Protocol, TypeVar

from bridge.core.hub import Replier
from protocol.commands import CommandFailedError, ErrorCode, Reply, loads

__all__ = ["Advertised", "advertised_by", "already_served", "client_answer",
           "connected_client"]


def connected_client(client: Optional[Replier], field: str, why: str) -> Replier:
    """The client a request came from; NOT_SUPPORTED for a start-up command (no client
    to ``why``: answer the calls, get the feedback...)."""
    if client is None:
        raise CommandFailedError(field, f"a request from a connected client (it {why})",
                                 "a start-up command", code=ErrorCode.NOT_SUPPORTED)
    return client


def already_served(kind: str, name: str, ros_type: str, client: Replier,
                   owner: Optional[Replier], owner_type: str,
                   graph: Iterable[tuple[str, list[str]]]) -> bool:
    """Whether `client` already serves the ``kind`` (service, action) `name` as `ros_type`
    (advertising again is idempotent); ALREADY_EXISTS if another client (`owner`, serving
    it as `owner_type`) or a ROS node in `graph` ((name, types) pairs) serves it."""
    if owner is not None:
        if owner is client and owner_type == ros_type:
            return True
        raise CommandFailedError(kind, f"a {kind} no other client advertises (or the same "
                                 "type again)", f"{name} ({owner_type})",
                                 code=ErrorCode.ALREADY_EXISTS)
    for found, types in graph:
        if found == name:
            raise CommandFailedError(kind, f"a {kind} no ROS node serves yet",
                                     f"{name} ({', '.join(types)})",
                                     code=ErrorCode.ALREADY_EXISTS)
    return False


class Advertised(Protocol):
    """A ROS service or action a client serves: who advertised it."""

    @property
    def owner(self) -> Replier: ...


A = TypeVar("A", bound=Advertised)


def advertised_by(served: Mapping[str, A], kind: str, name: str,
                  client: Optional[Replier]) -> A:
    """The ``kind`` (service, action) `name` of `served` that `client` advertises (the
    operator's config: whoever does); NOT_FOUND naming the field ``kind`` otherwise. The one
    rule of who may unadvertise."""
    entry = served.get(name)
    if entry is None or (client is not None and entry.owner is not client):
        raise CommandFailedError(kind, f"{'an' if kind[0] in 'aeiou' else 'a'} {kind} this "
                                 "client advertises", name,
                                 code=ErrorCode.NOT_FOUND)
    return entry


def client_answer(text: str) -> dict[str, Any]:
    """The payload of a client's RTS_COMMAND answer to a COMMAND the daemon sent: an
    ordinary `Reply` (its result) or the bare object, judged by its JSON (3D Slicer's Status
    metadata is junk). A refusal (``ok: false``) raises `CommandFailedError`."""
    data = loads(text)
    if "ok" in data:  # a Reply envelope
        reply = Reply.from_json(text)
        if not reply.ok:
            assert reply.error is not None
            raise CommandFailedError("ok", "true", f"false ({reply.error.message})")
        data = reply.result
    return data
