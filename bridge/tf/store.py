"""The samples behind `TfBuffer`, and the walks that answer lookups: the pure Python store.

`TfBuffer` (buffer.py) owns the API: argument checks, validation of incoming transforms,
the lock, `StampedTransform` results, YAML. It keeps its samples in a store, this one or the
compiled one (``bridge/tf/_compiled_store.pyx``, same interface, same results to the bit;
tests/bridge/test_tf_store_equivalence.py holds them together). This module is the
reference and the fallback wherever the compiled store was not built.

Every frame id given to a store is already stripped of its leading '/' and non-empty, and
every value is checked (finite, unit quaternion): see `TfBuffer`.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from typing import Dict, List, Optional, Sequence, Tuple, Union

from bridge.tf.errors import ConnectivityError, ExtrapolationError, TfError, TfLookupError
from bridge.tf.math import IDENTITY, Tf7, compose, interpolate, invert

__all__ = ["FrameStore", "FrameRow", "LatestResult", "NO_STAMP", "Receipt", "Result"]

NO_STAMP = 1 << 63  # above any stamp (int64 ns): no dynamic frame seen yet

# (frame, parent, static, newest stamp, oldest live stamp, live samples): `TfBuffer.frame_info`.
FrameRow = Tuple[str, str, bool, int, int, int]
# target<-source as (time used, translation, rotation): `StampedTransform`'s last fields.
Result = Tuple[int, Tuple[float, float, float], Tuple[float, float, float, float]]
# (child frame, newest parent, static, receive tick): what `TfBuffer` judges room by.
Receipt = Tuple[str, str, bool, int]
# One result of `FrameStore.latest_many`, or the error it raised.
LatestResult = Union[Result, TfError]


class _FrameCache:
    """The samples of one child frame, oldest first, in three parallel lists.

    Parallel lists (not a list of records) so `bisect` runs on the plain int stamps. A
    static frame holds exactly one sample with stamp 0. ``received``: the store's
    ``receive_tick`` when a transform of this frame last came (stored or not).
    """

    __slots__ = ("static", "window_ns", "received", "stamps", "parents", "values")

    def __init__(self, static: bool, window_ns: int) -> None:
        self.static = static
        self.window_ns = window_ns
        self.received = 0
        self.stamps: List[int] = []
        self.parents: List[str] = []
        self.values: List[Tf7] = []

    def first(self) -> int:
        """The index of the oldest live sample: the lists may still hold a few older ones
        (`FrameStore.insert` drops them in chunks), which count for nothing."""
        stamps = self.stamps
        oldest = stamps[-1] - self.window_ns
        return 0 if stamps[0] >= oldest else bisect_left(stamps, oldest)


# One link of a chain at a given time: the frame's cache, the older sample's index and the
# interpolation ratio towards the next sample (0.0: the sample itself).
_Slot = Tuple[_FrameCache, int, float]
# top<-frame at time t, keyed (top, frame, t): what one batch of lookups has composed.
_Memo = Dict[Tuple[str, str, int], Tf7]


def _locate(cache: _FrameCache, t: int) -> Tuple[str, int, float]:
    """(parent, index, ratio) of ``cache`` at time ``t`` (0: newest), or ExtrapolationError."""
    if cache.static:
        return cache.parents[0], 0, 0.0
    stamps = cache.stamps
    n = len(stamps)
    last = stamps[-1]
    if t == last or t == 0:
        return cache.parents[-1], n - 1, 0.0
    if n == 1:
        raise ExtrapolationError("single", t, last)
    if t > last:
        raise ExtrapolationError("future", t, last)
    first = cache.first()
    if t < stamps[first]:
        raise ExtrapolationError("past", t, stamps[first])
    if n - first == 1:
        raise ExtrapolationError("single", t, last)
    i = bisect_right(stamps, t) - 1  # stamps[i] <= t < stamps[i + 1]
    parents = cache.parents
    s0 = stamps[i]
    if s0 == t or parents[i] != parents[i + 1]:
        return parents[i], i, 0.0
    return parents[i], i, (t - s0) / (stamps[i + 1] - s0)


def _value(slot: _Slot) -> Tf7:
    cache, i, ratio = slot
    if ratio == 0.0:
        return cache.values[i]
    return interpolate(cache.values[i], cache.values[i + 1], ratio)


def _up(slots: Sequence[_Slot]) -> Tf7:
    """top<-bottom for the links of one side, listed bottom-up; composed top-down, as
    `FrameStore._up_at` does, so both give the same bits."""
    if not slots:
        return IDENTITY
    acc = _value(slots[-1])  # starting from a link saves one product with identity
    for k in range(len(slots) - 2, -1, -1):
        acc = compose(acc, _value(slots[k]))
    return acc


def _combine(source_slots: Sequence[_Slot], target_slots: Sequence[_Slot]) -> Tf7:
    """target<-source from the links source->common and target->common."""
    a = _up(source_slots)  # common<-source
    if not target_slots:
        return a
    return compose(invert(_up(target_slots)), a)  # target<-common after common<-source


class FrameStore:
    """Each child frame's samples within ``window_ns`` of its newest, and tf2's walks.

    ``receive_tick``: when the transforms inserted next came, as `TfBuffer` reads its
    monotonic clock (ns) for each batch; each child frame keeps the tick of its last one
    (`receipts`). Stamps are the sender's word and may lie; this is the daemon's own.
    """

    def __init__(self, window_ns: int) -> None:
        self._window_ns = window_ns
        self._frames: dict[str, _FrameCache] = {}  # child frame -> its samples
        self._known: dict[str, None] = {}  # every frame id seen, children and parents
        self.graph_version = 0
        self.receive_tick = 0

    @property
    def frame_count(self) -> int:
        """Frame ids known, children and parents alike."""
        return len(self._known)

    # ------------------------------------------------------------------ writing

    def insert(self, parent: str, child: str, stamp: int, value: Tf7, static: bool) -> bool:
        """Store one checked sample; False if it changed nothing (a repeat, or too old)."""
        known = self._known
        if child not in known or parent not in known:
            known[child] = None
            known[parent] = None
            self.graph_version += 1
        cache = self._frames.get(child)
        if cache is None or cache.static != static:
            # tf2 also replaces the whole cache when a frame switches static <-> dynamic.
            cache = self._frames[child] = _FrameCache(static, self._window_ns)
            self.graph_version += 1
        cache.received = self.receive_tick  # a repeat or too old still says it is alive
        stamps, parents, values = cache.stamps, cache.parents, cache.values
        if static:
            if parents and parents[0] == parent and values[0] == value:
                return False  # /tf_static is latched: repeats are common and change nothing
            if parents and parents[0] != parent:
                self.graph_version += 1
            cache.stamps, cache.parents, cache.values = [0], [parent], [value]
            return True
        if not stamps or stamp > stamps[-1]:  # the usual case: a newer sample
            if parents and parents[-1] != parent:
                self.graph_version += 1
            stamps.append(stamp)
            parents.append(parent)
            values.append(value)
            # Samples older than the window are dropped a quarter window at a time: one at a
            # time moves the whole list on every insert (10,000 per link at 1 kHz).
            if stamps[0] < stamp - self._window_ns - (self._window_ns >> 2):
                k = bisect_left(stamps, stamp - self._window_ns)
                del stamps[:k], parents[:k], values[:k]
            return True
        if stamp < stamps[-1] - self._window_ns:
            return False  # older than the window: tf2 ignores it too (TF_OLD_DATA)
        i = bisect_left(stamps, stamp)  # out of order: keep the list sorted
        if stamps[i] == stamp:
            if parents[i] == parent and values[i] == value:
                return False
            if i == len(stamps) - 1 and parents[i] != parent:
                self.graph_version += 1
            parents[i] = parent
            values[i] = value
            return True
        stamps.insert(i, stamp)
        parents.insert(i, parent)
        values.insert(i, value)
        return True

    def clear(self) -> None:
        self._frames.clear()
        self._known.clear()
        self.graph_version += 1

    # ------------------------------------------------------------------ reading

    def known(self) -> List[str]:
        """Every frame id seen, children and parents alike, in no particular order."""
        return list(self._known)

    def has_frame(self, frame: str) -> bool:
        return frame in self._known

    def frame_rows(self) -> List[FrameRow]:
        """One `FrameRow` per child frame, sorted by frame id."""
        out = []
        for name in sorted(self._frames):
            c = self._frames[name]
            first = c.first()
            out.append((name, c.parents[-1], c.static, c.stamps[-1], c.stamps[first],
                        len(c.stamps) - first))
        return out

    def receipts(self) -> List[Receipt]:
        """One `Receipt` per child frame, in no particular order."""
        return [(name, c.parents[-1], c.static, c.received) for name, c in self._frames.items()]

    def samples_of(self, frame: str) -> List[Tuple[int, str, Tf7]]:
        """The live samples of a child frame, oldest first: (stamp, parent, value)."""
        c = self._frames[frame]
        first = c.first()
        return list(zip(c.stamps[first:], c.parents[first:], c.values[first:]))

    def lookup(self, target: str, source: str, t: int) -> Result:
        """target<-source at ``t`` (0: the latest common time), or a TfError."""
        t, value = self._lookup(target, source, t, None)
        return t, value[:3], value[3:]

    def latest_many(self, pairs: Sequence[Tuple[str, str]]) -> List[LatestResult]:
        """`lookup(target, source, 0)` for each pair, a result or the error it raised; links
        shared by several chains are composed once."""
        memo: _Memo = {}
        out: List[LatestResult] = []
        for target, source in pairs:
            try:
                t, value = self._lookup(target, source, 0, memo)
            except TfError as error:
                out.append(error)
                continue
            out.append((t, value[:3], value[3:]))
        return out

    def chain_frames(self, target: str, source: str) -> frozenset[str]:
        """The child frames whose links a latest-time lookup target<-source traverses."""
        if target == source:
            return frozenset()
        self._require(target, "lookupTransform argument target_frame")
        self._require(source, "lookupTransform argument source_frame")
        _, src, tgt = self._latest_chain(target, source)
        return frozenset(src).union(tgt)

    # ------------------------------------------------------------------ internals

    def _lookup(self, target: str, source: str, t: int,
                memo: Optional[_Memo]) -> Tuple[int, Tf7]:
        if target == source:  # tf2 answers identity even for unknown frames
            cache = self._frames.get(target)
            if t == 0 and cache is not None and not cache.static:
                t = cache.stamps[-1]
            return t, IDENTITY
        self._require(target, "lookupTransform argument target_frame")
        self._require(source, "lookupTransform argument source_frame")
        if t != 0:
            return t, self._walk(target, source, t)
        t, src, tgt = self._latest_chain(target, source)
        # The chain was found with each frame's newest parent. Sample it at t; if a frame's
        # parent at t is another one (a re-parenting inside the window), walk again at t.
        top = self._frames[src[-1]].parents[-1] if src else source  # the common ancestor
        try:
            a = self._up_at(src, t, top, memo)  # top<-source
            if a is None:
                return t, self._walk(target, source, t)
            if not tgt:
                return t, a
            b = self._up_at(tgt, t, top, memo)  # top<-target
            if b is None:
                return t, self._walk(target, source, t)
        except ExtrapolationError as exc:
            raise exc.with_frames(source, target) from None
        return t, compose(invert(b), a)

    def _require(self, frame: str, argument: str) -> None:
        if frame not in self._known:
            raise TfLookupError.unknown_frame(frame, argument)

    def _loop_error(self) -> TfLookupError:
        listing = "".join(f"Frame {name} exists with parent {cache.parents[-1]}.\n"
                          for name, cache in sorted(self._frames.items()))
        return TfLookupError("The tf tree is invalid because it contains a loop.\n" + listing)

    def _up_at(self, chain: List[str], t: int, top: str,
               memo: Optional[_Memo]) -> Optional[Tf7]:
        """top<-chain[0] at t for the frames of `_latest_chain` (listed bottom-up), or None if
        a frame had another parent at t. ``memo`` holds top<-frame at t for frames already
        composed in this batch: the walk up stops at the first one found."""
        frames = self._frames
        below: List[Tuple[str, _Slot]] = []
        acc: Optional[Tf7] = None
        for frame in chain:
            if memo is not None:
                acc = memo.get((top, frame, t))
                if acc is not None:
                    break
            cache = frames[frame]
            parent, i, ratio = _locate(cache, t)
            if parent != cache.parents[-1]:
                return None
            below.append((frame, (cache, i, ratio)))
        for frame, slot in reversed(below):
            value = _value(slot)
            acc = value if acc is None else compose(acc, value)
            if memo is not None:
                memo[(top, frame, t)] = acc
        return IDENTITY if acc is None else acc

    def _latest_chain(self, target: str, source: str) -> Tuple[int, List[str], List[str]]:
        """Walk by each frame's newest parent: (latest common time, source-side frames,
        target-side frames), the frame lists naming the links below the common ancestor."""
        frames = self._frames
        seen: dict[str, Tuple[int, int]] = {}  # frame -> (min stamp below it, links below)
        src: List[str] = []
        low = NO_STAMP
        frame = source
        while True:
            if frame in seen:
                raise self._loop_error()
            seen[frame] = (low, len(src))
            if frame == target:  # target is an ancestor of source
                return (0 if low == NO_STAMP else low), src, []
            cache = frames.get(frame)
            if cache is None:  # a root
                break
            if not cache.static and cache.stamps[-1] < low:
                low = cache.stamps[-1]
            src.append(frame)
            frame = cache.parents[-1]
        tgt: List[str] = []
        low = NO_STAMP
        frame = target
        limit = len(frames)
        while frame not in seen:
            cache = frames.get(frame)
            if cache is None:
                raise ConnectivityError(target, source)
            if not cache.static and cache.stamps[-1] < low:
                low = cache.stamps[-1]
            tgt.append(frame)
            if len(tgt) > limit:
                raise self._loop_error()
            frame = cache.parents[-1]
        src_low, below = seen[frame]
        low = min(low, src_low)
        return (0 if low == NO_STAMP else low), src[:below], tgt

    def _walk(self, target: str, source: str, t: int) -> Tf7:
        """target<-source at time t, following each frame's parent *at t* (tf2's walk)."""
        frames = self._frames
        seen: dict[str, int] = {}  # frame on the source side -> links below it
        src: List[_Slot] = []
        src_error: Optional[ExtrapolationError] = None
        frame = source
        while True:
            if frame in seen:
                raise self._loop_error()
            seen[frame] = len(src)
            if frame == target:
                break
            cache = frames.get(frame)
            if cache is None:
                break
            try:
                parent, i, ratio = _locate(cache, t)
            except ExtrapolationError as exc:
                # Not fatal yet: the target side may meet the chain below this link.
                src_error = exc
                break
            src.append((cache, i, ratio))
            frame = parent
        tgt: List[_Slot] = []
        frame = target
        limit = len(frames)
        while frame not in seen:
            cache = frames.get(frame)
            if cache is None:
                if src_error is not None:
                    raise src_error.with_frames(source, target)
                raise ConnectivityError(target, source)
            try:
                parent, i, ratio = _locate(cache, t)
            except ExtrapolationError as exc:
                raise exc.with_frames(source, target) from None
            tgt.append((cache, i, ratio))
            if len(tgt) > limit:
                raise self._loop_error()
            frame = parent
        return _combine(src[: seen[frame]], tgt)
