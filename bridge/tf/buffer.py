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
(`set_transforms`, `set_transforms_cdr`), the asyncio thread reads (`lookup`, `frames`,
...); each public call holds the lock for its whole duration, so a lookup never sees half of
a batch.

Where the samples live: in a store (see `bridge.tf.store`). This class owns the API, the
validation of incoming transforms (`_check`, the one place that words a refusal) and the
results; the store holds the samples and walks the tree. Two stores give the same results
to the bit: the compiled one (``_compiled_store.pyx``, built by ``make setup`` where a C
compiler is found), used by default, and the pure Python one (``store.py``), the reference
and the fallback. The daemon's `--tf-store python` runs the pure Python one; what each costs
is bench/bench_tf.py's to say.
"""

from __future__ import annotations

import heapq
import math
import operator
import threading
import time
from dataclasses import dataclass
from typing import Callable, Iterable, List, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

from bridge.tf.errors import (
    InvalidArgumentError,
    RejectedTransformsError,
    TfError,
    display_time,
)
from bridge.tf.math import Tf7
from bridge.tf.store import FrameStore
from protocol.commands.fields import MAX_NAME
from protocol.conversions import matrix_to_pose, pose_to_matrix

# The store interface this module expects; the compiled module states the one it was built
# for, so a module left from an older build (a pull without `make setup`) is not used.
STORE_INTERFACE = 6
try:  # built by setup.py where a C compiler is found (optional: see `COMPILED`)
    from bridge.tf import _compiled_store
except ImportError:
    _compiled_store = None  # type: ignore[assignment]
CompiledFrameStore = (_compiled_store.CompiledFrameStore
                      if getattr(_compiled_store, "INTERFACE", None) == STORE_INTERFACE else None)

__all__ = ["COMPILED", "MAX_FRAMES", "MAX_FRAME_ID", "FrameInfo", "StampedTransform",
           "TfBuffer"]

_NS_PER_S = 1_000_000_000
_STAMP_LIMIT = 1 << 63  # tf2's times are int64 ns; so are the compiled store's
# tf2 keeps every frame it has seen for good: a peer sending new names (1 MB each, or
# 100,000 small ones) grew the daemon by hundreds of MB. Frame ids are bounded as every
# ROS name a client sends is (MAX_NAME characters), and so is the number of frames.
MAX_FRAME_ID = MAX_NAME
MAX_FRAMES = 10_000
# Past MAX_FRAMES, room kept for the frames clients look up and the chains that lead to
# them: a peer's flood of other frames, once it has filled the buffer, must not keep a
# robot that starts later out of every lookup.
LOOKED_UP_RESERVE = MAX_FRAMES // 10
# A full buffer makes room for a new frame by forgetting the frames received least recently
# (by the daemon's clock, never by their stamps), at least a tenth of the bound at a time:
# forgetting rebuilds the store, so a flood of new names must not rebuild it per frame.
FORGET_SHARE = 10
# Refusals of one TFMessage's CDR worded one by one; the others are counted.
_WORDED_REFUSALS = 8
# Whether the compiled store was built here: a buffer's default.
COMPILED = CompiledFrameStore is not None
# tf2's tolerance on |q|^2 (QUATERNION_NORMALIZATION_TOLERANCE in buffer_core.cpp).
_QUATERNION_TOLERANCE = 1e-2


class StampedTransform(NamedTuple):
    """One transform parent<-child at ``stamp_ns`` (ROS time in ns; 0 for static data).

    ``translation`` is (x, y, z) in metres, ``rotation`` the quaternion (x, y, z, w). It maps
    points given in ``child`` into ``parent``, like ``geometry_msgs/TransformStamped`` with
    header.frame_id = parent and child_frame_id = child.

    A named tuple, not a frozen dataclass: a 7-link robot at 1 kHz makes 7,000 of them a
    second, and a frozen dataclass costs four times as much to build.
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


def _strip(frame: str) -> str:
    return frame[1:] if frame.startswith("/") else frame


class TfBuffer:
    """tf2's buffer for the daemon: `set_transforms` from ROS, `lookup` for clients.

    ``cache_time_s`` is how far behind each frame's newest sample older samples are kept
    (tf2's default is 10 s). ``compiled``: True to require the compiled store, False for
    the pure Python one, None (the default) for the compiled one where it was built (see
    `COMPILED`). ``max_frames`` and ``max_frame_id`` bound what it keeps (a transform
    naming a frame id longer than ``max_frame_id`` characters, or a new frame past
    ``max_frames``, is refused like an invalid one); ``looked_up_reserve`` more frames are
    kept for the frames `look_up` names and the chains leading to them. A full buffer
    forgets frames to make room (`_forget_least_received`). ``clock``: the daemon's
    monotonic clock in ns, read once per batch to judge which frames were received least
    recently. Thread-safe: see the module docstring.
    """

    def __init__(self, cache_time_s: float = 10.0, *, compiled: Optional[bool] = None,
                 max_frames: int = MAX_FRAMES, max_frame_id: int = MAX_FRAME_ID,
                 looked_up_reserve: int = LOOKED_UP_RESERVE,
                 clock: Callable[[], int] = time.monotonic_ns) -> None:
        if not (isinstance(cache_time_s, (int, float)) and math.isfinite(cache_time_s)
                and cache_time_s > 0):
            raise InvalidArgumentError("cache_time_s", "a finite number of seconds > 0",
                                       repr(cache_time_s))
        self._cache_ns = int(cache_time_s * _NS_PER_S)
        self._lock = threading.Lock()
        self._max_frames = max_frames
        self._max_frame_id = max_frame_id
        self._reserve = looked_up_reserve
        self._looked_up: frozenset[str] = frozenset()  # frames named by clients' lookups
        self._chains: Tuple[int, frozenset[str]] = (-1, frozenset())  # (graph_version, frames)
        self._clock = clock
        self._tick = 0  # the receive tick of the last batch (see `_next_tick`)
        self._forget_tick = -1  # the tick of the last batch that forgot (or tried to)
        self._forgotten = 0
        self._store: _Store = _make_store(self._cache_ns, compiled, max_frames, max_frame_id)

    # ------------------------------------------------------------------ writing

    @property
    def cache_time_s(self) -> float:
        return self._cache_ns / _NS_PER_S

    @property
    def compiled(self) -> bool:
        """Whether this buffer runs on the compiled store (`COMPILED`)."""
        return not isinstance(self._store, FrameStore)

    @property
    def graph_version(self) -> int:
        """Bumped whenever the tree's shape may change: a new frame, a frame's newest parent
        changes, a frame switches between static and dynamic. `LookupRegistry` re-derives
        which frames each lookup traverses when it moves."""
        return self._store.graph_version

    @property
    def forgotten(self) -> int:
        """Frames forgotten so far to make room for new ones (the capability logs it)."""
        return self._forgotten

    def _next_tick(self) -> int:
        """Under the lock: the receive tick of a new batch, the clock's ns, made to grow
        strictly so that a batch is told from the one before."""
        self._tick = max(self._clock(), self._tick + 1)
        return self._tick

    def set_transforms(self, transforms: Iterable[StampedTransform], *, static: bool) -> set[str]:
        """Store one batch (a whole TFMessage); return the child frames whose data changed.

        Each transform is judged alone, as in tf2: invalid ones (empty frame id, parent equal
        to child, negative stamp, NaN or infinity, a quaternion whose squared norm is not
        within 0.01 of 1) are never stored; after the valid ones are stored,
        `RejectedTransformsError` (INVALID_ARGUMENT) is raised carrying ``changed`` and one
        error per refused transform. ``static=True`` ignores the stamps.
        """
        changed: set[str] = set()
        rejected: list[tuple[int, InvalidArgumentError]] = []
        checked: list[tuple[int, _Checked]] = []
        for index, tr in enumerate(transforms):
            try:
                checked.append((index, _check(tr, index, static, self._max_frame_id)))
            except InvalidArgumentError as exc:
                rejected.append((index, exc))
        with self._lock:
            rejected += self._store_checked(checked, static, changed, self._next_tick())
        if rejected:
            raise RejectedTransformsError([exc for _, exc in sorted(rejected, key=_first)],
                                          changed)
        return changed

    def set_transforms_cdr(self, data: Union[bytes, memoryview], *, static: bool
                           ) -> Optional[set[str]]:
        """`set_transforms` of a serialized ``tf2_msgs/TFMessage`` (a raw subscription's
        bytes), with the same results and errors, read and stored in one call by the
        compiled store. None (nothing stored) when this buffer does not read those bytes:
        on the pure Python store, or bytes that are not little-endian plain CDR. The caller
        then reads the message itself and calls `set_transforms`.

        A transform the compiled store refuses is judged again by `_check`, the one place
        that words the reasons.
        """
        store = self._store
        if isinstance(store, FrameStore):  # the pure Python store reads no CDR
            return None
        with self._lock:
            tick = store.receive_tick = self._next_tick()
            stored = store.insert_cdr(data, static)
        if stored is None:
            return None
        changed, refused = stored
        if not refused:
            return changed
        # A peer's flood (a thousand new frames past the bound in each message) is worded
        # a few at a time: judging each refusal again in Python cost 20 ms a message. Past
        # those few, transforms toward a looked-up frame are judged again, and those naming
        # a new frame while frames can still be forgotten to make room for it.
        worded, rest = refused[:_WORDED_REFUSALS], refused[_WORDED_REFUSALS:]
        checked, rejected = self._judge(worded, static)
        unworded = len(rest)
        with self._lock:
            ends = self._toward_looked_up() if self._looked_up and rest else frozenset()
        checked += self._judge([row for row in rest if _strip(row[1][3]) in ends], static)[0]
        with self._lock:
            room_refused = self._store_checked(checked, static, changed, tick)
            store = self._store
            # Each names a new frame: no more of them fit than the room left once this
            # batch has forgotten what it may.
            room = (len(rest) if self._forget_tick != tick
                    else self._max_frames - store.frame_count)
            late = [(index, raw) for index, raw in rest if _strip(raw[3]) not in ends and (
                not store.has_frame(_strip(raw[2])) or not store.has_frame(_strip(raw[3])))
            ][:room] if rest and room > 0 else []
        if late:
            more = self._judge(late, static)[0]
            with self._lock:
                room_refused += self._store_checked(more, static, changed, tick)
            checked += more
        last_worded = worded[-1][0]
        rejected += [(index, exc) for index, exc in room_refused if index <= last_worded]
        unworded -= sum(1 for index, _ in checked if index > last_worded)
        unworded += sum(1 for index, _ in room_refused if index > last_worded)
        if unworded and not rejected:  # the worded few were stored after all
            rejected.append((0, InvalidArgumentError("transforms", "transforms the buffer keeps",
                                                     f"{unworded} refused")))
            unworded -= 1
        if rejected:
            raise RejectedTransformsError([exc for _, exc in sorted(rejected, key=_first)],
                                          changed, unworded)
        return changed

    def _judge(self, refused: list[tuple[int, _RawTransform]], static: bool
               ) -> tuple[list[tuple[int, _Checked]], list[tuple[int, InvalidArgumentError]]]:
        """Transforms the compiled store refused, judged again by `_check`: the valid ones
        and the reasons of the others."""
        checked: list[tuple[int, _Checked]] = []
        rejected: list[tuple[int, InvalidArgumentError]] = []
        for index, raw in refused:
            try:
                checked.append((index, _check(_from_raw(raw), index, static,
                                              self._max_frame_id)))
            except InvalidArgumentError as exc:
                rejected.append((index, exc))
        return checked, rejected

    def _store_checked(self, rows: list[tuple[int, _Checked]], static: bool,
                       changed: set[str], tick: int) -> list[tuple[int, InvalidArgumentError]]:
        """Under the lock: store each checked transform of the batch received at ``tick``
        there is room for; the refusals. Refused ones whose child leads to a looked-up frame
        are tried again while the tree grows: a chain sent root first gets into the reserve
        from its looked-up end."""
        refused: dict[int, tuple[_Checked, InvalidArgumentError]] = {}
        self._store.receive_tick = tick
        # Twice: first what there is room for, in order, as the compiled store's insert_cdr
        # stores a message; then the refused ones, in order, forgetting frames to make room.
        # So both ways in store the same frames.
        for forget in (False, True):
            pending = rows if not forget else sorted(
                (index, row) for index, (row, _) in refused.items())
            while pending:
                version = self._store.graph_version
                for index, (parent, child, stamp, value) in pending:
                    try:
                        self._check_room(parent, child, index, tick, rows, forget)
                    except InvalidArgumentError as exc:
                        refused[index] = ((parent, child, stamp, value), exc)
                        continue
                    refused.pop(index, None)
                    # The store itself: `_check_room` may have made a new one.
                    if self._store.insert(parent, child, stamp, value, static):
                        changed.add(child)
                if not (refused and self._looked_up and self._store.graph_version != version):
                    break
                ends = self._toward_looked_up()
                pending = [(index, row) for index, (row, _) in sorted(refused.items())
                           if row[1] in ends]
            if not refused:
                break
        return [(index, exc) for index, (_, exc) in sorted(refused.items())]

    def look_up(self, frames: Iterable[str]) -> None:
        """The frames clients look up (`LookupRegistry` says): they, and the frames that
        lead to them, may use the reserve past ``max_frames``."""
        wanted = frozenset(_strip(frame) for frame in frames)
        with self._lock:
            self._looked_up = wanted
            self._chains = (-1, frozenset())

    def _toward_looked_up(self) -> frozenset[str]:
        """Under the lock: the looked-up frames and every frame above them (their parents,
        their parents' parents...) as the store knows them now; kept per graph version."""
        version, frames = self._chains
        if version == self._store.graph_version:
            return frames
        parent_of = {row[0]: row[1] for row in self._store.frame_rows()}
        found = set(self._looked_up)
        todo = list(found)
        while todo:
            parent = parent_of.get(todo.pop())
            if parent is not None and parent not in found:
                found.add(parent)
                todo.append(parent)
        self._chains = (self._store.graph_version, frozenset(found))
        return self._chains[1]

    def _check_room(self, parent: str, child: str, index: int, tick: int,
                    batch: list[tuple[int, _Checked]], forget: bool) -> None:
        """Under the lock: InvalidArgumentError if storing parent<-child would make the
        buffer know more than ``max_frames`` frames. With ``forget``: once frames received
        least recently are forgotten, and a child that leads to a looked-up frame may then
        use the reserve past that. ``tick`` and ``batch``: the batch being stored (its frames
        stay)."""
        store = self._store
        if store.frame_count + 2 <= self._max_frames:
            return  # the usual case: no lookups
        new = (not store.has_frame(parent)) + (not store.has_frame(child))
        if (forget and new and store.frame_count + new > self._max_frames
                and self._forget_least_received(new, tick, batch)):
            store = self._store
            new = (not store.has_frame(parent)) + (not store.has_frame(child))
        if new and store.frame_count + new > self._max_frames:
            if (forget and store.frame_count + new <= self._max_frames + self._reserve
                    and self._looked_up and child in self._toward_looked_up()):
                return
            raise InvalidArgumentError(
                f"transforms[{index}]", f"frames the buffer knows, or room for new ones (at "
                f"most {self._max_frames} frames are kept)", f"{new} new frame(s): "
                f"'{_shown(parent)}' -> '{_shown(child)}'")

    def _forget_least_received(self, new: int, tick: int,
                               batch: list[tuple[int, _Checked]]) -> bool:
        """Under the lock, with the buffer full: forget dynamic frames, those received least
        recently first, so that ``new`` frames find room; whether any went.

        Judged by the daemon's receive ticks, never by stamps: a peer's frames stamped in
        the future (or now) once must not keep a new frame out, for good or for a cache
        time. Forgotten: every frame silent for longer than the cache time, and at least
        ``new`` and a tenth of the bound (`FORGET_SHARE`), those received least recently
        first; once per batch at most, so that a message of new names costs one rebuild
        of the store, not one per tenth of the bound (its new frames past that are
        refused). A frame goes only after the frames below it (a parent of a kept frame stays
        known, so forgetting it would free no room). Never forgotten: static frames (latched,
        never sent again), the frames clients look up and their chains, and the frames of
        the batch being stored. Unlike tf2, which keeps every frame for good, a full buffer
        lets these go: the store is made again from the frames kept (only ever when full).
        """
        if self._forget_tick == tick:
            return False
        self._forget_tick = tick
        receipts = self._store.receipts()
        keep = {row[1] for _, row in batch}
        if self._looked_up:
            keep |= self._toward_looked_up()
        below: dict[str, int] = {}  # frame -> child frames naming it as newest parent
        for _, parent, _, _ in receipts:
            below[parent] = below.get(parent, 0) + 1
        # Frames that may go, by receive tick; a frame joins once nothing is left below it.
        can_go = {frame: (received, frame, parent) for frame, parent, static, received
                  in receipts if not static and received < tick and frame not in keep}
        heap = [entry for frame, entry in can_go.items() if frame not in below]
        heapq.heapify(heap)
        silent_before = tick - self._cache_ns
        least = max(new, self._max_frames // FORGET_SHARE)
        gone: set[str] = set()
        while heap:
            received, frame, parent = heap[0]
            if len(gone) >= least and received >= silent_before:
                break
            heapq.heappop(heap)
            gone.add(frame)
            below[parent] -= 1
            if not below[parent] and parent in can_go:
                heapq.heappush(heap, can_go[parent])
        if not gone:
            return False
        old = self._store
        store = _make_store(self._cache_ns, not isinstance(old, FrameStore),
                            self._max_frames, self._max_frame_id)
        for frame, _, static, received in receipts:
            if frame not in gone:
                store.receive_tick = received
                for stamp, parent, value in old.samples_of(frame):
                    store.insert(parent, frame, stamp, value, static)
        store.receive_tick = tick
        store.graph_version = old.graph_version + 1  # every lookup's chain is derived again
        self._store = store
        self._forgotten += len(gone)
        return True

    def clear(self) -> None:
        """Forget every frame (for example after a ROS time jump backwards)."""
        with self._lock:
            self._store.clear()

    # ------------------------------------------------------------------ reading

    def lookup(self, target_frame: str, source_frame: str, time_ns: int = 0) -> StampedTransform:
        """target<-source at ``time_ns`` (0: the latest common time), tf2's lookupTransform.

        The result's parent is ``target_frame``, its child ``source_frame``, its stamp the
        time used. Raises `TfLookupError` (unknown frame, loop), `ConnectivityError`,
        `ExtrapolationError` or `InvalidArgumentError`, worded as tf2 words them.
        """
        t = _time_arg(time_ns)
        target = _frame_arg(target_frame, "target_frame")
        source = _frame_arg(source_frame, "source_frame")
        with self._lock:
            t, translation, rotation = self._store.lookup(target, source, t)
        return StampedTransform(target, source, t, translation, rotation)

    def lookup_latest_many(self, pairs: Sequence[Tuple[str, str]],
                           ) -> List[StampedTransform | TfError]:
        """`lookup(target, source)` at the latest common time for each (target, source), as
        a result or the error it raised, under one lock: chains that share links (a robot's
        links seen from its base) compose each shared link once, not once per lookup."""
        try:
            checked = [(_frame_arg(target, "target_frame"), _frame_arg(source, "source_frame"))
                       for target, source in pairs]
        except InvalidArgumentError:  # rare: each pair alone, an invalid one as its error
            return [self._latest_or_error(target, source) for target, source in pairs]
        with self._lock:
            results = self._store.latest_many(checked)
        return [result if isinstance(result, TfError)
                else StampedTransform(target, source, *result)
                for (target, source), result in zip(checked, results)]

    def _latest_or_error(self, target: str, source: str) -> StampedTransform | TfError:
        try:
            return self.lookup(target, source)
        except TfError as error:
            return error

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
        with self._lock:
            return self._store.chain_frames(target, source)

    def frames(self) -> list[str]:
        """Every frame id known, children and parents alike (tf2's getAllFrameNames), sorted."""
        with self._lock:
            return sorted(self._store.known())

    def has_frame(self, frame: str) -> bool:
        with self._lock:
            return self._store.has_frame(_strip(frame))

    def frame_info(self) -> list[FrameInfo]:
        """One `FrameInfo` per child frame, sorted by frame id."""
        with self._lock:
            rows = self._store.frame_rows()
        return [FrameInfo(*row) for row in rows]

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


# ---------------------------------------------------------------------- stores

_Store = Union[FrameStore, "_compiled_store.CompiledFrameStore"]


def _make_store(window_ns: int, compiled: Optional[bool], max_frames: int,
                max_frame_id: int) -> _Store:
    if compiled is None:
        compiled = COMPILED
    if not compiled:
        return FrameStore(window_ns)  # TfBuffer checks the bounds before each insert
    if CompiledFrameStore is None:
        raise InvalidArgumentError("compiled", "False or None: the compiled store was not built",
                                   "True")
    # It refuses what is out of bounds in insert_cdr; TfBuffer words the refusal.
    return CompiledFrameStore(window_ns, max_frames, max_frame_id)


_RawTransform = Tuple[int, int, str, str, float, float, float, float, float, float, float]
_Checked = Tuple[str, str, int, Tf7]  # parent, child, stamp, value: what `_check` passed


def _first(row: Tuple[int, object]) -> int:
    return row[0]


def _from_raw(raw: _RawTransform) -> StampedTransform:
    """A transform as read from CDR (sec, nanosec, frame, child, tx..qw)."""
    sec, nanosec, frame, child, tx, ty, tz, x, y, z, w = raw
    return StampedTransform(frame, child, sec * _NS_PER_S + nanosec, (tx, ty, tz), (x, y, z, w))


# ---------------------------------------------------------------------- validation


def _frame_arg(frame: object, argument: str) -> str:
    if type(frame) is str and frame and frame[0] != "/":
        return frame  # the usual case, on every lookup of every batch
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
    if not 0 <= time_ns < _STAMP_LIMIT:
        raise InvalidArgumentError("time_ns", "a time >= 0 and < 2**63 ns (0: the latest "
                                   "common time)", str(time_ns))
    return time_ns


def _shown(frame: str) -> str:
    """A frame id as an error shows it: a long one cut (it may be a megabyte)."""
    return frame if len(frame) <= 64 else f"{frame[:60]}...({len(frame)} characters)"


def _check(tr: StampedTransform, index: int, static: bool,
           max_frame_id: int = MAX_FRAME_ID) -> Tuple[str, str, int, Tf7]:
    """Validate one incoming transform; return (parent, child, stamp, value) to store."""
    where = f"transforms[{index}]"
    parent, child = tr.parent, tr.child
    if not isinstance(parent, str) or not isinstance(child, str):
        raise InvalidArgumentError(f"{where} frame ids", "strings",
                                   f"{type(parent).__name__}, {type(child).__name__}")
    parent, child = _strip(parent), _strip(child)
    if len(parent) > max_frame_id or len(child) > max_frame_id:
        name, frame = ("parent", parent) if len(parent) > max_frame_id else ("child", child)
        raise InvalidArgumentError(f"{where}.{name}", f"a frame id of at most "
                                   f"{max_frame_id} characters", _shown(frame))
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
        if not 0 <= stamp < _STAMP_LIMIT:
            raise InvalidArgumentError(f"{where}.stamp_ns", "a time >= 0 and < 2**63 ns",
                                       str(stamp))
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
