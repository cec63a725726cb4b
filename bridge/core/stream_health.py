"""Tells clients when a stream goes stale and when it comes back.

A robot that freezes in 3D Slicer must not look live: when a subscribed topic's publisher
is gone from the ROS graph, or no message came within the stream's expected period, every
client that gets its device receives a STATUS on that device (code NOT_READY, name
``stale``, the reason in its text); a client that connects later gets it too. The next
message brings the stream back: a STATUS OK named ``live``.

Only a stream that has been live can go stale (a subscriber made before its publisher
starts is waiting, not stale). Its expected period is learned from its own arrivals, so a
1 kHz pose stream is stale after a few milliseconds of silence and a 1 Hz one after a few
seconds; a publisher gone from the graph is stale at once, whatever its rate.

Threads: `Arrivals.note` runs in the ROS callback (a clock read and a few float
operations); the judging runs on the loop, `CHECK_INTERVAL_S` apart.
"""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass
from typing import Callable, Optional, Protocol

from bridge.core.hub import Hub
from bridge.core.outbox import Frame
from protocol.liveness import condition_status
from protocol.messages import Message

__all__ = ["Arrivals", "ArrivalsView", "CHECK_INTERVAL_S", "StreamHealth", "stale_reason"]

log = logging.getLogger(__name__)

CHECK_INTERVAL_S = 0.1
GRAPH_INTERVAL_S = 0.5  # publisher counts are asked of the graph this often
# Silence longer than this many expected periods is stale, and never less than the floor
# (scheduling jitter on a busy machine is not an outage).
STALE_PERIODS = 5.0
SILENCE_FLOOR_S = 0.3
SMOOTHING = 0.1  # weight of a new interval in the expected period


class ArrivalsView(Protocol):
    """What the health check reads of a stream's arrivals (`Arrivals`, or a native lane's:
    native_stream.LaneArrivals)."""

    @property
    def last(self) -> Optional[float]: ...
    @property
    def period(self) -> Optional[float]: ...
    @property
    def count(self) -> int: ...
    def note(self, now: float) -> None: ...


class Arrivals:
    """When a stream's messages come, and how far apart they usually are."""

    __slots__ = ("last", "period", "count")

    def __init__(self) -> None:
        self.last: Optional[float] = None
        self.period: Optional[float] = None
        self.count = 0

    def note(self, now: float) -> None:
        last = self.last
        if last is not None:
            gap = now - last
            period = self.period
            self.period = gap if period is None else period + SMOOTHING * (gap - period)
        self.last = now
        self.count += 1


def stale_reason(arrivals: ArrivalsView, now: float, publishers: Optional[int],
                 topic: str) -> Optional[str]:
    """Why a stream that has been live is stale now, or None (live, or never live)."""
    if arrivals.last is None:
        return None
    silence = now - arrivals.last
    if publishers == 0 and silence > CHECK_INTERVAL_S:  # the graph may lag the last message
        return f"no publisher of {topic} in the ROS graph"
    if arrivals.period is None or arrivals.count < 3:
        return None  # no expected period yet: one message may be all there is
    allowed = max(STALE_PERIODS * arrivals.period, SILENCE_FLOOR_S)
    if silence > allowed:
        return (f"no message on {topic} for {silence:.1f} s (expected one every "
                f"{arrivals.period * 1000:.0f} ms)")
    return None


@dataclass
class _Watched:
    topic: str
    arrivals: ArrivalsView
    publishers: Callable[[], int]
    stale: Optional[str] = None
    count: Optional[int] = None
    counted_at: float = float("-inf")


class StreamHealth:
    """Watches streamed devices (loop thread) and sets their condition on the hub."""

    def __init__(self, hub: Hub, loop: asyncio.AbstractEventLoop) -> None:
        self._hub = hub
        self._loop = loop
        self._watched: dict[str, _Watched] = {}
        self._timer: Optional[asyncio.TimerHandle] = None

    def watch(self, device: str, topic: str, arrivals: ArrivalsView,
              publishers: Callable[[], int]) -> None:
        """Judge `device`, streamed from `topic`; `publishers()` counts its publishers."""
        self._watched[device] = _Watched(topic, arrivals, publishers)
        if self._timer is None:
            self._timer = self._loop.call_later(CHECK_INTERVAL_S, self._check)

    def unwatch(self, device: str) -> None:
        """Stop judging `device` (its bridge is gone: `Hub.forget` drops its condition)."""
        self._watched.pop(device, None)

    def stale(self, device: str) -> Optional[str]:
        watched = self._watched.get(device)
        return None if watched is None else watched.stale

    def _check(self) -> None:
        self._timer = None
        now = time.monotonic()
        for device, watched in tuple(self._watched.items()):
            if watched.arrivals.last is None:
                continue
            if now - watched.counted_at >= GRAPH_INTERVAL_S:
                try:
                    watched.count = watched.publishers()
                except Exception:  # noqa: BLE001 - a graph query at shutdown: judge by time
                    watched.count = None
                watched.counted_at = now
            reason = stale_reason(watched.arrivals, now, watched.count, watched.topic)
            if (reason is None) != (watched.stale is None):
                self._set(device, watched, reason)
        if self._watched:
            self._timer = self._loop.call_later(CHECK_INTERVAL_S, self._check)

    def _set(self, device: str, watched: _Watched, reason: Optional[str]) -> None:
        watched.stale = reason
        if reason is None:
            log.info("%s is live again (device %r)", watched.topic, device)
        else:
            log.warning("%s is stale: %s (device %r)", watched.topic, reason, device)
        frame = Frame(Message(device_name=device, body=condition_status(reason, watched.topic)))
        self._hub.set_condition(device, frame if reason is not None else None, frame)

    def close(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._watched.clear()
