"""The tf lookups clients registered, re-evaluated only when something they depend on changed.

The reference (SlicerROS2) runs every registered lookup on every 20 ms tick, changed or not.
Here the daemon calls, after each `TfBuffer.set_transforms` batch::

    for key, result in registry.updates(changed_frames, now_ns):
        send(key, result)            # a StampedTransform, or a TfError to report

and, from a timer, ``registry.due(now_ns)`` (``next_due_ns()`` says when to wake up). Then:

* Only lookups whose chain traverses a changed frame are evaluated. Each lookup's set of
  traversed frames is cached and re-derived when the buffer's ``graph_version`` moves (a new
  frame, a re-parenting, a static/dynamic switch); after such a move every lookup is
  evaluated once, since its chain may be another one.
* Only results that differ from the last one delivered for that key are returned
  (translation within ``translation_tolerance_m`` per axis, rotation within
  ``rotation_tolerance_rad``; errors compare by kind, see `TfError.identity`).
* A lookup with a rate cap delivers at most one result per ``1 / rate_hz``. A result held
  back by the cap is not lost: it comes out of `due` once the interval has passed (unless
  a later result brought the value back to the one delivered).
* A lookup naming a frame the buffer does not know yet is *pending*: nothing is delivered
  until the frame appears (see `pending`). Other errors (no connection, extrapolation, a
  loop) are delivered like values, once per distinct error.
* A newly added lookup is evaluated at the next `updates` or `due` call.

Thread-safety: one lock guards the registry, so `updates` (ROS thread) and `due` / `add` /
`remove` (asyncio thread) may be called concurrently. The buffer has its own lock, taken
only inside the registry's and never the other way round, so the two cannot deadlock.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Dict, Iterable, List, NamedTuple, Optional, Protocol, Set, Tuple, Union

from bridge.tf.buffer import StampedTransform, TfBuffer
from bridge.tf.errors import InvalidArgumentError, TfError, TfLookupError

__all__ = ["LookupKey", "LookupResult", "LookupRegistry"]

LookupResult = Union[StampedTransform, TfError]

_Pair = Tuple[str, str]  # (parent, child): lookups of the same pair share one evaluation


class LookupKey(NamedTuple):
    """One registered lookup: parent<-child (tf2's target<-source), and a ``tag`` the daemon
    chooses to tell apart several registrations of the same pair (one per client, say).

    A named tuple: it is a dict key hashed several times per result on the hot path, and a
    tuple's hash is native where a frozen dataclass's runs in Python."""

    parent: str
    child: str
    tag: str = ""


@dataclass(slots=True)
class _Entry:
    key: LookupKey
    min_interval_ns: int  # 0: no rate cap
    last_sent: Optional[LookupResult] = None
    last_sent_ns: Optional[int] = None
    held: Optional[LookupResult] = None  # the newest result the rate cap kept back


@dataclass(slots=True)
class _PairState:
    entries: Dict[str, _Entry] = field(default_factory=dict)  # tag -> entry
    frames: frozenset[str] = frozenset()  # child frames the chain traverses
    pending: bool = False


class LookupRegistry:
    """Registered lookups on one `TfBuffer`; see the module docstring for the contract."""

    def __init__(self, buffer: TfBuffer, *, translation_tolerance_m: float = 1e-6,
                 rotation_tolerance_rad: float = 1e-6) -> None:
        for name, value in (("translation_tolerance_m", translation_tolerance_m),
                            ("rotation_tolerance_rad", rotation_tolerance_rad)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise InvalidArgumentError(name, "a finite number >= 0", repr(value))
        self._buffer = buffer
        self._tol_m = float(translation_tolerance_m)
        # Same rotation iff |q1 . q2| >= cos(tolerance / 2): one dot product per comparison.
        self._min_dot = math.cos(float(rotation_tolerance_rad) / 2.0)
        self._lock = threading.Lock()
        self._pairs: Dict[_Pair, _PairState] = {}
        self._by_frame: Dict[str, Set[_Pair]] = {}
        self._dirty: Set[_Pair] = set()
        self._held: Dict[LookupKey, _Entry] = {}
        self._chain_version = -1  # forces a derivation at the first call

    # ------------------------------------------------------------------ registration

    def add(self, parent: str, child: str, *, rate_hz: Optional[float] = None,
            tag: str = "") -> LookupKey:
        """Register the lookup parent<-child (again: only its rate cap is updated).

        ``rate_hz`` caps how often a result is delivered (None: every change).
        """
        key = LookupKey(_frame(parent, "parent"), _frame(child, "child"), tag)
        interval = 0
        if rate_hz is not None:
            if isinstance(rate_hz, bool) or not isinstance(rate_hz, (int, float)) or not (
                    math.isfinite(rate_hz) and rate_hz > 0):
                raise InvalidArgumentError("rate_hz", "None or a finite number of Hz > 0",
                                           repr(rate_hz))
            interval = int(round(1e9 / rate_hz))
        pair = (key.parent, key.child)
        with self._lock:
            state = self._pairs.get(pair)
            if state is None:
                state = self._pairs[pair] = _PairState()
                self._chain_version = -1  # derive this pair's chain at the next call
                self._buffer.look_up(frame for ends in self._pairs for frame in ends)
            entry = state.entries.get(tag)
            if entry is None:
                state.entries[tag] = _Entry(key, interval)
                self._dirty.add(pair)
            else:
                entry.min_interval_ns = interval
        return key

    def remove(self, key: LookupKey) -> bool:
        """Forget a lookup; False if it was not registered."""
        pair = (key.parent, key.child)
        with self._lock:
            state = self._pairs.get(pair)
            if state is None or state.entries.pop(key.tag, None) is None:
                return False
            self._held.pop(key, None)
            if not state.entries:
                del self._pairs[pair]
                self._dirty.discard(pair)
                self._buffer.look_up(frame for ends in self._pairs for frame in ends)
                for frame in state.frames:
                    users = self._by_frame.get(frame)
                    if users is not None:
                        users.discard(pair)
                        if not users:
                            del self._by_frame[frame]
            return True

    def keys(self) -> List[LookupKey]:
        with self._lock:
            return [e.key for s in self._pairs.values() for e in s.entries.values()]

    def pending(self) -> List[LookupKey]:
        """Lookups waiting for a frame the buffer does not know yet."""
        with self._lock:
            return [e.key for s in self._pairs.values() if s.pending for e in s.entries.values()]

    def last_sent(self, key: LookupKey) -> Optional[LookupResult]:
        """The last result delivered for ``key`` (None: nothing yet, or not registered)."""
        with self._lock:
            state = self._pairs.get((key.parent, key.child))
            entry = state.entries.get(key.tag) if state is not None else None
            return entry.last_sent if entry is not None else None

    # ------------------------------------------------------------------ evaluation

    def updates(self, changed_frames: Iterable[str],
                now_ns: int) -> List[Tuple[LookupKey, LookupResult]]:
        """Results to deliver after a batch that changed ``changed_frames`` (see the module
        docstring); ``now_ns`` is the daemon's clock, used for the rate caps only."""
        with self._lock:
            todo = self._take_dirty()
            by_frame = self._by_frame
            for frame in changed_frames:
                users = by_frame.get(frame)
                if users:
                    todo |= users
            return self._evaluate(todo, now_ns)

    def due(self, now_ns: int) -> List[Tuple[LookupKey, LookupResult]]:
        """Held-back results whose rate-cap interval has passed, plus first results of newly
        added lookups (call it from the daemon's timer, at `next_due_ns`)."""
        with self._lock:
            out = self._evaluate(self._take_dirty(), now_ns)
            for key, entry in list(self._held.items()):
                assert entry.last_sent_ns is not None and entry.held is not None
                if now_ns - entry.last_sent_ns >= entry.min_interval_ns:
                    out.append((key, self._send(entry, entry.held, now_ns)))
            return out

    def next_due_ns(self) -> Optional[int]:
        """When `due` next has something to deliver (None: nothing is waiting)."""
        with self._lock:
            if self._dirty or self._chain_version != self._buffer.graph_version:
                return 0
            times = [e.last_sent_ns + e.min_interval_ns for e in self._held.values()
                     if e.last_sent_ns is not None]
            return min(times) if times else None

    # ------------------------------------------------------------------ internals (locked)

    def _take_dirty(self) -> Set[_Pair]:
        if self._chain_version != self._buffer.graph_version:
            self._derive_chains()
        todo = self._dirty
        self._dirty = set()
        return todo

    def _derive_chains(self) -> None:
        # Read the version first: a batch landing meanwhile moves it again, so the next call
        # derives once more instead of trusting chains computed from an older graph.
        version = self._buffer.graph_version
        by_frame: Dict[str, Set[_Pair]] = {}
        for pair, state in self._pairs.items():
            try:
                state.frames = self._buffer.chain_frames(pair[0], pair[1])
            except TfError:
                # No chain yet (unknown frame, separate trees, loop): only a change of the
                # graph can fix that, and such a change triggers this derivation again.
                state.frames = frozenset()
            for frame in state.frames:
                by_frame.setdefault(frame, set()).add(pair)
        self._by_frame = by_frame
        self._dirty.update(self._pairs)  # the graph moved: any result may differ now
        self._chain_version = version

    def _evaluate(self, todo: Set[_Pair], now_ns: int) -> List[Tuple[LookupKey, LookupResult]]:
        out: List[Tuple[LookupKey, LookupResult]] = []
        pairs = [pair for pair in sorted(todo) if pair in self._pairs]  # deterministic order
        for pair, result in zip(pairs, self._buffer.lookup_latest_many(pairs)):
            state = self._pairs[pair]
            if isinstance(result, TfLookupError) and result.frame is not None:
                state.pending = True  # a frame does not exist (yet)
                continue
            state.pending = False
            for entry in state.entries.values():
                if self._same(entry.last_sent, result):
                    entry.held = None
                    self._held.pop(entry.key, None)
                elif (entry.min_interval_ns and entry.last_sent_ns is not None
                      and now_ns - entry.last_sent_ns < entry.min_interval_ns):
                    entry.held = result
                    self._held[entry.key] = entry
                else:
                    out.append((entry.key, self._send(entry, result, now_ns)))
        return out

    def _send(self, entry: _Entry, result: LookupResult, now_ns: int) -> LookupResult:
        entry.last_sent = result
        entry.last_sent_ns = now_ns
        entry.held = None
        self._held.pop(entry.key, None)
        return result

    def _same(self, old: Optional[LookupResult], new: LookupResult) -> bool:
        if isinstance(old, StampedTransform) and isinstance(new, StampedTransform):
            tol = self._tol_m
            (ax, ay, az), (bx, by, bz) = old.translation, new.translation
            if abs(ax - bx) > tol or abs(ay - by) > tol or abs(az - bz) > tol:
                return False
            p, q = old.rotation, new.rotation
            dot = p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3]
            return abs(dot) >= self._min_dot
        if isinstance(old, TfError) and isinstance(new, TfError):
            return old.identity() == new.identity()
        return False


def _frame(frame: object, name: str) -> str:
    stripped = frame[1:] if isinstance(frame, str) and frame.startswith("/") else frame
    if not isinstance(stripped, str) or not stripped:
        raise InvalidArgumentError(name, "a non-empty frame id", repr(frame))
    return stripped


class LookupStreams(Protocol):
    """Lookups streamed for another capability (robot links, marker frames): what the tf
    capability offers the others (`TfBridges` is one). They import this, never its handlers."""

    @property
    def buffer(self) -> TfBuffer: ...

    def stream_lookup(self, parent: str, child: str, *, device: str,
                      metadata: dict[str, str], rate_hz: Optional[float] = None,
                      group: Optional[str] = None) -> LookupKey: ...

    def stop_lookup(self, handle: LookupKey) -> None: ...

    def open_pose_group(self, device: str, metadata: dict[str, str]) -> None: ...

    def close_pose_group(self, device: str) -> None: ...
