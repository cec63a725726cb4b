"""The daemon's own tf2 buffer: time-stamped transforms per frame, chain lookups, tf2 errors.

Plain Python, no ROS import: the daemon's ROS adapter turns each ``/tf`` or ``/tf_static``
``TFMessage`` into `StampedTransform` values and hands the whole message to
`TfBuffer.set_transforms` in one call. Behaviour follows tf2's ``BufferCore``:

* A static transform (``/tf_static``) has no time and holds at every time; a dynamic one is
  kept per child frame in a time-sorted cache, pruned to ``cache_time_s`` behind that
  frame's newest sample. Data older than that window is ignored (tf2's TF_OLD_DATA).
* ``lookup(target, source, t)`` returns target<-source (it maps points given in ``source``
  into ``target``), composed up to the common ancestor of the two frames. ``t == 0`` means
  the latest common time: the newest time at which every dynamic link of the chain has data
  (static links do not constrain it; a chain of static links only gives stamp 0).
* Between two samples: linear interpolation of the translation, slerp of the rotation. When
  a frame's parent changed between the two samples, the older one is used, as in tf2.
* A frame may be re-parented at any time; the newest sample's parent wins for later times.
* A leading '/' of a frame id is stripped (tf2 strips it on insert; here lookups strip it
  too, so "/base" finds "base").

Deliberate differences from tf2: a slightly denormalised quaternion (within tf2's tolerance,
``| |q|^2 - 1 | < 0.01``) is accepted and normalised before it is stored; a sample with the
same stamp as a stored one replaces it (ROS 1 Noetic's rule) instead of being kept twice.

Thread-safety: one `threading.Lock` guards all state. The ROS thread writes
(`set_transforms`), the asyncio thread reads (`lookup`, `frames`, ...); each public call
holds the lock for its whole duration, so a lookup never sees half of a batch. Uncontended,
the lock costs ~0.1 us per call; the critical sections are tens of microseconds at most.

Speed: 3-vectors and quaternions are plain float tuples (see `bridge.tf.math` for why);
a lookup across a 20-link chain costs tens of microseconds (bench/bench_tf.py).
"""

from __future__ import annotations

import math
import operator
import threading
from bisect import bisect_left, bisect_right
from dataclasses import dataclass
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt

from bridge.tf.errors import (
    ConnectivityError,
    ExtrapolationError,
    InvalidArgumentError,
    RejectedTransformsError,
    TfError,
    TfLookupError,
    display_time,
)
from bridge.tf.math import IDENTITY, Tf7, compose, interpolate, invert
from protocol.conversions import matrix_to_pose, pose_to_matrix

__all__ = ["StampedTransform", "FrameInfo", "TfBuffer"]

_NS_PER_S = 1_000_000_000
_NO_STAMP = 1 << 63  # above any stamp (int64 ns): no dynamic frame seen yet
# tf2's tolerance on |q|^2 (QUATERNION_NORMALIZATION_TOLERANCE in buffer_core.cpp).
_QUATERNION_TOLERANCE = 1e-2


@dataclass(frozen=True, slots=True)
class StampedTransform:
    """One transform parent<-child at ``stamp_ns`` (ROS time in ns; 0 for static data).

    ``translation`` is (x, y, z) in metres, ``rotation`` the quaternion (x, y, z, w). It maps
    points given in ``child`` into ``parent``, like ``geometry_msgs/TransformStamped`` with
    header.frame_id = parent and child_frame_id = child.
    """

    parent: str
    child: str
    stamp_ns: int
    translation: Tuple[float, float, float]
    rotation: Tuple[float, float, float, float]

    def matrix_mm(self) -> npt.NDArray[np.float64]:
        """The 4x4 homogeneous matrix in millimetres (Slicer's convention)."""
        return pose_to_matrix(self.translation, self.rotation)

    @classmethod
    def from_matrix_mm(cls, parent: str, child: str, stamp_ns: int,
                       matrix_mm: npt.ArrayLike) -> StampedTransform:
        """From a 4x4 matrix in mm (validated as a rigid transform by conversions.py)."""
        t, q = matrix_to_pose(matrix_mm)
        return cls(parent, child, stamp_ns, (float(t[0]), float(t[1]), float(t[2])),
                   (float(q[0]), float(q[1]), float(q[2]), float(q[3])))

    def as_tuple(self) -> Tf7:
        """(tx, ty, tz, qx, qy, qz, qw), the form `bridge.tf.math` works on."""
        return self.translation + self.rotation


@dataclass(frozen=True, slots=True)
class FrameInfo:
    """What `TfBuffer.frame_info` reports about one child frame (tf2's allFramesAsYAML)."""

    frame: str
    parent: str
    static: bool
    most_recent_ns: int  # 0 for a static frame
    oldest_ns: int
    samples: int

    @property
    def buffer_length_s(self) -> float:
        return (self.most_recent_ns - self.oldest_ns) / _NS_PER_S

    @property
    def rate_hz(self) -> float:
        # tf2's figure: samples over the time they span (at least 100 us).
        return self.samples / max(self.buffer_length_s, 1e-4)


class _FrameCache:
    """The samples of one child frame, oldest first, in three parallel lists.

    Parallel lists (not a list of records) so `bisect` runs on the plain int stamps. A
    static frame holds exactly one sample with stamp 0.
    """

    __slots__ = ("static", "window_ns", "stamps", "parents", "values")

    def __init__(self, static: bool, window_ns: int) -> None:
        self.static = static
        self.window_ns = window_ns
        self.stamps: List[int] = []
        self.parents: List[str] = []
        self.values: List[Tf7] = []

    def first(self) -> int:
        """The index of the oldest live sample: the lists may still hold a few older ones
        (`TfBuffer._insert` drops them in chunks), which count for nothing."""
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
    `TfBuffer._up_at` does, so both give the same bits."""
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


def _strip(frame: str) -> str:
    return frame[1:] if frame.startswith("/") else frame


class TfBuffer:
    """tf2's buffer for the daemon: `set_transforms` from ROS, `lookup` for clients.

    ``cache_time_s`` is how far behind each frame's newest sample older samples are kept
    (tf2's default is 10 s). Thread-safe: see the module docstring.
    """

    def __init__(self, cache_time_s: float = 10.0) -> None:
        if not (isinstance(cache_time_s, (int, float)) and math.isfinite(cache_time_s)
                and cache_time_s > 0):
            raise InvalidArgumentError("cache_time_s", "a finite number of seconds > 0",
                                       repr(cache_time_s))
        self._cache_ns = int(cache_time_s * _NS_PER_S)
        self._lock = threading.Lock()
        self._frames: dict[str, _FrameCache] = {}  # child frame -> its samples
        self._known: dict[str, None] = {}  # every frame id seen, children and parents
        self._graph_version = 0

    # ------------------------------------------------------------------ writing

    @property
    def cache_time_s(self) -> float:
        return self._cache_ns / _NS_PER_S

    @property
    def graph_version(self) -> int:
        """Bumped whenever the tree's shape may change: a new frame, a frame's newest parent
        changes, a frame switches between static and dynamic. `LookupRegistry` re-derives
        which frames each lookup traverses when it moves."""
        return self._graph_version

    def set_transforms(self, transforms: Iterable[StampedTransform], *, static: bool) -> set[str]:
        """Store one batch (a whole TFMessage); return the child frames whose data changed.

        Each transform is judged alone, as in tf2: invalid ones (empty frame id, parent equal
        to child, negative stamp, NaN or infinity, a quaternion whose squared norm is not
        within 0.01 of 1) are never stored; after the valid ones are stored,
        `RejectedTransformsError` (INVALID_ARGUMENT) is raised carrying ``changed`` and one
        error per refused transform. ``static=True`` ignores the stamps.
        """
        changed: set[str] = set()
        rejected: list[InvalidArgumentError] = []
        with self._lock:
            for index, tr in enumerate(transforms):
                try:
                    parent, child, stamp, value = _check(tr, index, static)
                except InvalidArgumentError as exc:
                    rejected.append(exc)
                    continue
                if self._insert(parent, child, stamp, value, static):
                    changed.add(child)
        if rejected:
            raise RejectedTransformsError(rejected, changed)
        return changed

    def clear(self) -> None:
        """Forget every frame (for example after a ROS time jump backwards)."""
        with self._lock:
            self._frames.clear()
            self._known.clear()
            self._graph_version += 1

    def _insert(self, parent: str, child: str, stamp: int, value: Tf7, static: bool) -> bool:
        known = self._known
        if child not in known or parent not in known:
            known[child] = None
            known[parent] = None
            self._graph_version += 1
        cache = self._frames.get(child)
        if cache is None or cache.static != static:
            # tf2 also replaces the whole cache when a frame switches static <-> dynamic.
            cache = self._frames[child] = _FrameCache(static, self._cache_ns)
            self._graph_version += 1
        stamps, parents, values = cache.stamps, cache.parents, cache.values
        if static:
            if parents and parents[0] == parent and values[0] == value:
                return False  # /tf_static is latched: repeats are common and change nothing
            if parents and parents[0] != parent:
                self._graph_version += 1
            cache.stamps, cache.parents, cache.values = [0], [parent], [value]
            return True
        if not stamps or stamp > stamps[-1]:  # the usual case: a newer sample
            if parents and parents[-1] != parent:
                self._graph_version += 1
            stamps.append(stamp)
            parents.append(parent)
            values.append(value)
            # Samples older than the window are dropped a quarter window at a time: one at a
            # time moves the whole list on every insert (10,000 per link at 1 kHz).
            if stamps[0] < stamp - self._cache_ns - (self._cache_ns >> 2):
                k = bisect_left(stamps, stamp - self._cache_ns)
                del stamps[:k], parents[:k], values[:k]
            return True
        if stamp < stamps[-1] - self._cache_ns:
            return False  # older than the window: tf2 ignores it too (TF_OLD_DATA)
        i = bisect_left(stamps, stamp)  # out of order: keep the list sorted
        if stamps[i] == stamp:
            if parents[i] == parent and values[i] == value:
                return False
            if i == len(stamps) - 1 and parents[i] != parent:
                self._graph_version += 1
            parents[i] = parent
            values[i] = value
            return True
        stamps.insert(i, stamp)
        parents.insert(i, parent)
        values.insert(i, value)
        return True

    # ------------------------------------------------------------------ reading

    def lookup(self, target_frame: str, source_frame: str, time_ns: int = 0) -> StampedTransform:
        """target<-source at ``time_ns`` (0: the latest common time), tf2's lookupTransform.

        The result's parent is ``target_frame``, its child ``source_frame``, its stamp the
        time used. Raises `TfLookupError` (unknown frame, loop), `ConnectivityError`,
        `ExtrapolationError` or `InvalidArgumentError`, worded as tf2 words them.
        """
        t = _time_arg(time_ns)
        with self._lock:
            return self._lookup_one(target_frame, source_frame, t, None)

    def lookup_latest_many(self, pairs: Sequence[Tuple[str, str]],
                           ) -> List[StampedTransform | TfError]:
        """`lookup(target, source)` at the latest common time for each (target, source), as
        a result or the error it raised, under one lock: chains that share links (a robot's
        links seen from its base) compose each shared link once, not once per lookup."""
        memo: _Memo = {}
        out: List[StampedTransform | TfError] = []
        with self._lock:
            for target, source in pairs:
                try:
                    out.append(self._lookup_one(target, source, 0, memo))
                except TfError as error:
                    out.append(error)
        return out

    def _lookup_one(self, target_frame: str, source_frame: str, t: int,
                    memo: Optional[_Memo]) -> StampedTransform:
        target = _frame_arg(target_frame, "target_frame")
        source = _frame_arg(source_frame, "source_frame")
        if target == source:  # tf2 answers identity even for unknown frames
            cache = self._frames.get(target)
            if t == 0 and cache is not None and not cache.static:
                t = cache.stamps[-1]
            return StampedTransform(target, source, t, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
        self._require(target, "lookupTransform argument target_frame")
        self._require(source, "lookupTransform argument source_frame")
        t, value = self._lookup_locked(target, source, t, memo)
        return StampedTransform(target, source, t, value[:3], value[3:])

    def can_transform(self, target_frame: str, source_frame: str, time_ns: int = 0) -> bool:
        """Whether `lookup` with the same arguments would succeed."""
        try:
            self.lookup(target_frame, source_frame, time_ns)
        except TfError:
            return False
        return True

    def chain_frames(self, target_frame: str, source_frame: str) -> frozenset[str]:
        """The child frames whose links a latest-time lookup target<-source traverses.

        New data for any other frame cannot change that lookup's result (until
        `graph_version` moves). Raises like `lookup` if there is no chain.
        """
        target = _frame_arg(target_frame, "target_frame")
        source = _frame_arg(source_frame, "source_frame")
        if target == source:
            return frozenset()
        with self._lock:
            self._require(target, "lookupTransform argument target_frame")
            self._require(source, "lookupTransform argument source_frame")
            _, src, tgt = self._latest_chain(target, source)
        return frozenset(src).union(tgt)

    def frames(self) -> list[str]:
        """Every frame id known, children and parents alike (tf2's getAllFrameNames), sorted."""
        with self._lock:
            return sorted(self._known)

    def has_frame(self, frame: str) -> bool:
        with self._lock:
            return _strip(frame) in self._known

    def frame_info(self) -> list[FrameInfo]:
        """One `FrameInfo` per child frame, sorted by frame id."""
        with self._lock:
            out = []
            for name in sorted(self._frames):
                c = self._frames[name]
                first = c.first()
                out.append(FrameInfo(name, c.parents[-1], c.static, c.stamps[-1],
                                     c.stamps[first], len(c.stamps) - first))
            return out

    def all_frames_as_yaml(self, current_time_ns: int = 0) -> str:
        """A YAML description of every child frame, like tf2's ``allFramesAsYAML``.

        Per frame: parent, rate, most_recent_transform, oldest_transform, buffer_length (and
        transform_delay if ``current_time_ns`` is given); static frames show times of 0.
        An empty buffer gives ``[]``.
        """
        infos = self.frame_info()
        if not infos:
            return "[]\n"
        lines = []
        for info in infos:
            lines.append(f"{_yaml_key(info.frame)}:")
            lines.append(f"  parent: {_yaml_str(info.parent)}")
            lines.append(f"  static: {'true' if info.static else 'false'}")
            lines.append(f"  rate: {info.rate_hz:.3f}")
            lines.append(f"  most_recent_transform: {display_time(info.most_recent_ns)}")
            lines.append(f"  oldest_transform: {display_time(info.oldest_ns)}")
            if current_time_ns:
                delay = (current_time_ns - info.most_recent_ns) / _NS_PER_S
                lines.append(f"  transform_delay: {delay:.3f}")
            lines.append(f"  buffer_length: {info.buffer_length_s:.3f}")
        return "\n".join(lines) + "\n"

    # ------------------------------------------------------------------ internals (locked)

    def _require(self, frame: str, argument: str) -> None:
        if frame not in self._known:
            raise TfLookupError.unknown_frame(frame, argument)

    def _loop_error(self) -> TfLookupError:
        listing = "".join(f"Frame {name} exists with parent {cache.parents[-1]}.\n"
                          for name, cache in sorted(self._frames.items()))
        return TfLookupError("The tf tree is invalid because it contains a loop.\n" + listing)

    def _lookup_locked(self, target: str, source: str, t: int,
                       memo: Optional[_Memo] = None) -> Tuple[int, Tf7]:
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
        low = _NO_STAMP
        frame = source
        while True:
            if frame in seen:
                raise self._loop_error()
            seen[frame] = (low, len(src))
            if frame == target:  # target is an ancestor of source
                return (0 if low == _NO_STAMP else low), src, []
            cache = frames.get(frame)
            if cache is None:  # a root
                break
            if not cache.static and cache.stamps[-1] < low:
                low = cache.stamps[-1]
            src.append(frame)
            frame = cache.parents[-1]
        tgt: List[str] = []
        low = _NO_STAMP
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
        return (0 if low == _NO_STAMP else low), src[:below], tgt

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


# ---------------------------------------------------------------------- validation


def _frame_arg(frame: object, argument: str) -> str:
    if not isinstance(frame, str):
        raise InvalidArgumentError(argument, "a frame id (str)", type(frame).__name__)
    stripped = _strip(frame)
    if not stripped:
        raise InvalidArgumentError(argument, "a non-empty frame id", repr(frame))
    return stripped


def _time_arg(time_ns: object) -> int:
    if type(time_ns) is not int:
        try:
            if isinstance(time_ns, bool):
                raise TypeError
            time_ns = operator.index(time_ns)  # type: ignore[arg-type]  # numpy integers
        except TypeError:
            raise InvalidArgumentError("time_ns", "an integer number of nanoseconds",
                                       type(time_ns).__name__) from None
    if time_ns < 0:
        raise InvalidArgumentError("time_ns", "a time >= 0 (0: the latest common time)",
                                   str(time_ns))
    return time_ns


def _check(tr: StampedTransform, index: int, static: bool) -> Tuple[str, str, int, Tf7]:
    """Validate one incoming transform; return (parent, child, stamp, value) to store."""
    where = f"transforms[{index}]"
    parent, child = tr.parent, tr.child
    if not isinstance(parent, str) or not isinstance(child, str):
        raise InvalidArgumentError(f"{where} frame ids", "strings",
                                   f"{type(parent).__name__}, {type(child).__name__}")
    parent, child = _strip(parent), _strip(child)
    if not child:
        raise InvalidArgumentError(f"{where}.child", "a non-empty frame id", repr(tr.child))
    if not parent:
        raise InvalidArgumentError(f"{where}.parent", "a non-empty frame id",
                                   f"{tr.parent!r} (child '{child}')")
    if parent == child:
        raise InvalidArgumentError(f"{where}", "a parent frame different from the child",
                                   f"both '{child}'")
    stamp = 0
    if not static:
        stamp = tr.stamp_ns
        if type(stamp) is not int:
            try:
                if isinstance(stamp, bool):
                    raise TypeError
                stamp = operator.index(stamp)
            except TypeError:
                raise InvalidArgumentError(f"{where}.stamp_ns", "an integer (ns)",
                                           type(stamp).__name__) from None
        if stamp < 0:
            raise InvalidArgumentError(f"{where}.stamp_ns", "a time >= 0", str(stamp))
    try:
        tx, ty, tz = tr.translation
        qx, qy, qz, qw = tr.rotation
        tx, ty, tz = float(tx), float(ty), float(tz)
        qx, qy, qz, qw = float(qx), float(qy), float(qz), float(qw)
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"{where} ('{child}')",
                                   "translation of 3 numbers and rotation of 4 numbers",
                                   str(exc)) from None
    total = tx + ty + tz + qx + qy + qz + qw
    # One subtraction tests all seven: NaN or +-inf make it NaN. Only if it fires, look closer
    # (huge finite values can overflow the sum).
    if total - total != 0.0 and not all(
            math.isfinite(v) for v in (tx, ty, tz, qx, qy, qz, qw)):
        raise InvalidArgumentError(
            f"{where} ('{child}')", "finite numbers",
            f"translation ({tx}, {ty}, {tz}) rotation ({qx}, {qy}, {qz}, {qw})")
    norm2 = qx * qx + qy * qy + qz * qz + qw * qw
    if not abs(norm2 - 1.0) < _QUATERNION_TOLERANCE:
        raise InvalidArgumentError(
            f"{where}.rotation ('{child}')", "a unit quaternion (|q|^2 within 0.01 of 1)",
            f"({qx}, {qy}, {qz}, {qw}), |q|^2 = {norm2:.6g}")
    if norm2 != 1.0:
        n = math.sqrt(norm2)
        qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    return parent, child, stamp, (tx, ty, tz, qx, qy, qz, qw)


# ---------------------------------------------------------------------- YAML helpers


def _yaml_key(text: str) -> str:
    # Frame ids are usually plain words; quote anything YAML could read as something else.
    if text and all(c.isalnum() or c in "_/.-" for c in text) and text[0] not in "-.":
        return text
    return _yaml_str(text)


def _yaml_str(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"
