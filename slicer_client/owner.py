"""What a resource needs from the client that owns it, as a `typing.Protocol`: resources
(resources.py) depend on this, not on `Client` (client.py), so the modules import in one
direction only (client -> resources -> owner)."""

from __future__ import annotations

from typing import (Any, Callable, Dict, Hashable, List, Mapping, Optional, Protocol, Tuple,
                    TypeVar, overload)

import numpy as np

from protocol import commands as c
from protocol.messages import Message

__all__ = ["ResourceOwner"]

_R = TypeVar("_R", bound=c.Result)


class ResourceOwner(Protocol):
    """The client side of a resource: commands, data, event delivery, bookkeeping."""

    errors: List[str]

    @property
    def address(self) -> str: ...

    def command(self, op: str, arguments: Optional[Mapping[str, Any]] = None, *,
                timeout: float = 10.0) -> Dict[str, Any]: ...

    @overload
    def request(self, request: c.Answered[_R], *, timeout: float = 10.0) -> _R: ...
    @overload
    def request(self, request: c.Op, *, timeout: float = 10.0) -> Dict[str, Any]: ...

    def send(self, message: Message) -> None: ...

    def lookup_transform(self, parent: str, child: str, *, timeout: float = 0.5,
                         stamp: Optional[Tuple[int, int]] = None) -> np.ndarray: ...

    def emit(self, callback: Callable[..., None], *args: Any) -> None:
        """Deliver a callback where the client delivers events (thread or queue)."""
        ...

    def emit_newest(self, key: Hashable, callback: Callable[..., None], *args: Any) -> None:
        """`emit`, or, while the one queued under `key` has not run, give it these args."""
        ...

    def remove_resource(self, resource: Any) -> None:
        """Remove `resource` daemon-side and forget it."""
        ...

    def keep_resource(self, resource: Any) -> None:
        """Have the daemon keep `resource` past this client (`keep_bridge`)."""
        ...

    def spec_changed(self, resource: Any) -> None:
        """A resource's follow-up commands changed (kept for re-sync and saving)."""
        ...
