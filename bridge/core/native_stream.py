"""The native lane of streamed poses, where it was built (bridge/core/_native_stream.pyx),
and the one client-side piece every session uses either way: its `Slot`.

A `Slot` is a client's socket as the writers outside the event loop see it: the session
holds it around every write of its own (it is the session's write lock) and opens it only
while nothing of the client waits anywhere; a writer from another thread writes only to an
open slot. The compiled one is also what the native lanes write through, without the
interpreter. Without the compiled module, `PySlot` does the same in Python and no lane runs.
"""

from __future__ import annotations

import socket
import threading
import weakref
from typing import Any, Optional

from protocol.crc64 import Buffer
from protocol.freshness import CLOCK_MODULUS

__all__ = ["BROKEN", "REFUSED", "SENT", "STASHED", "LaneArrivals", "PySlot", "available",
           "new_fanout", "new_lane", "new_slot"]

# The compiled module's interface this wrapper expects (`_native_stream.INTERFACE`).
NATIVE_INTERFACE = 6

try:
    from bridge.core import _native_stream
except ImportError:  # not built here (no Cython or no C compiler): the Python path only
    _native_stream = None  # type: ignore[assignment]

# What a write did (the compiled module's values where it is built).
SENT, STASHED, REFUSED, BROKEN = 0, 1, 2, 3


def available() -> bool:
    return (_native_stream is not None
            and getattr(_native_stream, "INTERFACE", None) == NATIVE_INTERFACE)


class PySlot:
    """`Slot` in Python (no native lane writes through it)."""

    def __init__(self, owner: Any = None) -> None:
        self.owner = owner
        self._lock = threading.Lock()
        self.fd = -1
        self.header_version = 1
        self.open = False
        self.sent = 0
        self._sock: Optional[socket.socket] = None
        self._stash: Optional[bytes] = None

    def __enter__(self) -> PySlot:
        self._lock.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self._lock.release()

    def connect(self, sock: socket.socket) -> None:
        self._sock = sock
        self.fd = sock.fileno()

    def disconnect(self) -> None:
        self._sock = None
        self.fd = -1
        self.open = False

    @property
    def has_stash(self) -> bool:
        return self._stash is not None

    def take_stash(self) -> Optional[bytes]:
        stash, self._stash = self._stash, None
        return stash

    def send(self, data: bytes | tuple[Buffer, ...]) -> int:
        sock = self._sock
        if sock is None or self._stash is not None:
            self.open = False
            return REFUSED
        parts = [memoryview(part) for part in ((data,) if isinstance(data, bytes) else data)]
        parts = [part if part.c_contiguous else memoryview(part.tobytes()) for part in parts]
        size = sum(part.nbytes for part in parts)
        try:
            sent = sock.sendmsg(parts)
        except (BlockingIOError, InterruptedError):
            sent = 0
        except OSError:
            self.open = False
            return BROKEN
        if sent == size:
            self.sent += 1
            return SENT
        self.open = False
        if sent == 0:
            return REFUSED
        self._stash = b"".join(parts)[sent:]
        self.sent += 1
        return STASHED

    def take_missed(self) -> bool:
        return False


def new_slot(owner: Any) -> Any:
    """A session's slot: the compiled one where the native lane runs. It knows its owner by
    a weak reference (`PoseLane.settle` gives them back), so a closed session is freed at
    once, not by the cyclic collector."""
    ref = weakref.ref(owner) if owner is not None else None
    return _native_stream.Slot(ref) if available() else PySlot(ref)


def new_fanout(*, batch: bool = True) -> Any:
    """A hub's `Fanout`, or None where the native lane is not built. With ``batch`` it
    writes each message to every client in one system call where the system allows
    (`Fanout.batched`); without, one each (`--send-batch off`)."""
    if not available():
        return None
    return _native_stream.Fanout(CLOCK_MODULUS, batch=batch)


# ROS type -> the lane's kind of message.
_KINDS = {"geometry_msgs/msg/Pose": "POSE", "geometry_msgs/msg/PoseStamped": "POSE_STAMPED",
          "geometry_msgs/msg/TransformStamped": "TRANSFORM_STAMPED"}


def new_lane(fanout: Any, ros_type: str, last_max_bytes: int, smoothing: float) -> Any:
    """A `PoseLane` for a stream of ``ros_type`` on ``fanout``, or None (not built here, no
    fan-out, or a type it does not take)."""
    kind = _KINDS.get(ros_type)
    if fanout is None or kind is None or not available():
        return None
    return _native_stream.PoseLane(fanout, getattr(_native_stream, kind), last_max_bytes,
                                   smoothing)


class LaneArrivals:
    """`stream_health.Arrivals` of a stream whose messages a native lane takes too: the
    lane keeps them (the same formula), the Python path notes its own there."""

    def __init__(self, lane: Any, fanout: Any) -> None:
        self._lane = lane
        self._fanout = fanout

    def _read(self) -> tuple[Optional[float], Optional[float], int]:
        with self._fanout:
            last, period, count = self._lane.arrivals()
        return last, period, int(count)

    @property
    def last(self) -> Optional[float]:
        return self._read()[0]

    @property
    def period(self) -> Optional[float]:
        return self._read()[1]

    @property
    def count(self) -> int:
        return self._read()[2]

    def note(self, now: float) -> None:
        with self._fanout:
            self._lane.note(now)
