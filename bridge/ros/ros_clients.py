"""The daemon's cached rclpy clients: service clients for `call_service`, action clients for
`send_goal`.

Each is a ROS entity (an action client is five) with its own discovery traffic, so the
cache holds one per (name, type), at most `capacity`, least recently used first. A client
in use (calls or goals waiting on it) is never dropped; a full cache drops its least
recently used idle client for a new one, and refuses when every client is in use. A client
unused for `idle_s` goes at that moment (a timer armed for the first one due), and the next
use makes a new one. Loop thread only.
"""

from __future__ import annotations

import asyncio
from collections import OrderedDict
from collections.abc import Iterator, Mapping
from typing import Callable, Generic, Optional, Protocol, TypeVar

from protocol.commands import CommandError

__all__ = ["CachedClient", "ClientKey", "RosClientCache"]

# (service or action name, its ROS type)
ClientKey = tuple[str, str]


class CachedClient(Protocol):
    """What the cache reads and writes of an entry (its owner keeps the rest)."""

    in_use: int  # calls or goals waiting on it: it must not go meanwhile
    last_used: float  # loop time


E = TypeVar("E", bound=CachedClient)


class RosClientCache(Mapping[ClientKey, E], Generic[E]):
    """rclpy clients by (name, type), least recently used first.

    ``destroy(entry)`` destroys a dropped client (the cache has already forgotten it);
    ``refusal(name)`` is the error when every client is in use and a new one is asked for.
    """

    def __init__(self, *, capacity: int, idle_s: float, destroy: Callable[[E], None],
                 refusal: Callable[[str], CommandError]) -> None:
        self._entries: OrderedDict[ClientKey, E] = OrderedDict()
        self._capacity = capacity
        self._idle_s = idle_s
        self._destroy = destroy
        self._refusal = refusal
        self._timer: Optional[asyncio.TimerHandle] = None
        self._due = 0.0  # loop time the idle timer fires

    # --- Mapping ---------------------------------------------------------------------------
    def __getitem__(self, key: ClientKey) -> E:
        return self._entries[key]

    def __iter__(self) -> Iterator[ClientKey]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    # --- use -------------------------------------------------------------------------------
    def client(self, key: ClientKey, make: Callable[[], E]) -> E:
        """The client of ``key``, made with ``make()`` if there is none; refused with
        ``refusal(name)`` when the cache is full of clients in use."""
        now = asyncio.get_running_loop().time()
        entry = self._entries.get(key)
        if entry is not None:
            self._entries.move_to_end(key)
            entry.last_used = now
            return entry
        if len(self._entries) >= self._capacity:
            idle = next((k for k, e in self._entries.items() if e.in_use == 0), None)
            if idle is None:
                raise self._refusal(key[0])
            self.drop(idle)
        entry = make()
        entry.last_used = now
        self._entries[key] = entry
        self._schedule()
        return entry

    def take(self, entry: E) -> None:
        """One more call or goal waits on ``entry``."""
        entry.in_use += 1

    def release(self, entry: E) -> None:
        """A call or goal of ``entry`` ended: its idle time counts from now."""
        entry.in_use -= 1
        entry.last_used = asyncio.get_running_loop().time()
        self._schedule()

    def drop(self, key: ClientKey) -> None:
        """Forget and destroy the client of ``key``."""
        self._destroy(self._entries.pop(key))

    def close(self) -> None:
        """Forget every client without destroying it (the node goes with them)."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._entries.clear()

    # --- idle clients ----------------------------------------------------------------------
    def _schedule(self) -> None:
        """Arm the timer for the moment the first idle client has been unused for
        `idle_s` (a client in use is not idle)."""
        idle = [e.last_used for e in self._entries.values() if e.in_use == 0]
        if not idle:
            return
        due = min(idle) + self._idle_s
        if self._timer is not None:
            if self._due <= due:
                return
            self._timer.cancel()
        loop = asyncio.get_running_loop()
        self._timer = loop.call_later(max(0.0, due - loop.time()), self._drop_idle)
        self._due = due

    def _drop_idle(self) -> None:
        self._timer = None
        deadline = asyncio.get_running_loop().time() - self._idle_s
        for key in [k for k, e in self._entries.items()
                    if e.in_use == 0 and e.last_used <= deadline]:
            self.drop(key)
        self._schedule()
