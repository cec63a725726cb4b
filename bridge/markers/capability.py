"""The daemon's marker capability: Marker / MarkerArray / Path / PolygonStamped /
PointStamped topics as models in Slicer, placed by tf.

    ROS executor thread        marker worker thread (one per topic)      asyncio loop
    ───────────────────        ────────────────────────────────────      ────────────
    callback: queue the ─────► read the message (convert.events_of),
    message (bounded)          mesh each marker whose digest changed ─► apply: publish
                               (geometry.build_model)  (one call_soon    models, follow
                                                        per message)     frames, expire

Per marker (``ns``, ``id``) one device (`NameKey.marker`, ``mk:<topic>:<ns>:<id>``): a
POLYDATA in mm in the marker's frame (its own pose applied), or a POINT for text, sent as
a persistent message (a client that connects later gets it), with metadata naming its
namespace, id and type (``ros2.ns``, ``ros2.id``, ``ros2.marker_type``), its colour and
its parent TRANSFORM device (``ros2.parent_device``). Per distinct frame one TRANSFORM
(`NameKey.marker_frame`, ``mkf:<fixed>><frame>``) streamed by the tf capability's
change-driven lookups, shared by every marker of every marker topic in that frame (counted;
stopped with the last marker in it). The model moves as tf moves without being re-sent.

Deletion (DELETE, DELETEALL, ``lifetime`` expiry, a marker that can no longer be shown,
removing the subscriber): its device is forgotten by the hub (no late client gets it),
and the topic's own device (`NameKey.marker_topic`, ``mks:<topic>``) streams a STRING whose
metadata lists the live markers' devices (``ros2.markers``, JSON) and the ones just gone
(``ros2.deleted``): the client and the Slicer module remove what is not live. It is sent
when that set changes and when a marker is refused: its text, JSON ``{"markers": n,
"withheld": n, "error": "..."}``, then names the marker, the field, what was expected and
what came.

Why the work is where it is: a MarkerArray of 1000 markers at 10-30 Hz is too much to
convert on the ROS callback or the loop. The callback only queues the message (at most
`MAX_QUEUED`; past that the oldest goes and ``dropped`` counts it); a worker thread per
topic reads and meshes; the loop only publishes. A worker that falls behind reads what
waits in one go and meshes only the newest state of each marker (the end state is the
same as reading the messages one by one; the states in between are skipped), so it
catches up; while the loop is behind it keeps reading into that end state, so the queue
stays short and a DELETE is not lost with an old message (only a worker that cannot even
read as fast as messages come loses the oldest, counted). A marker re-sent unchanged (RViz
publishers re-publish whole arrays) costs its reading and a digest, and no message: its
model is neither rebuilt nor re-sent, nor handed to the loop unless its lifetime must be
renewed.

Decisions, said plainly:
* ``header.frame_id`` empty: the marker is in the fixed frame (as RViz does).
* ``frame_locked`` true: the model follows its frame as tf moves (its parent TRANSFORM is
  the frame's). False (RViz's default, and every Path, polygon and point): the marker is
  placed once, as RViz does, by the fixed<-frame transform at its ``header.stamp``
  (the latest one for stamp 0, or when tf has nothing at the stamp yet), and stays there:
  its model comes in the fixed frame. A re-sent marker is placed again at its new stamp.
  A frame tf does not know yet cannot be placed: such a marker follows its frame (it
  appears when the frame does). The frame policy judges the marker's own frame either way.
* Lifetime counts from when the daemon received the marker, checked on one loop timer per
  daemon set to the next expiry (never by polling per message).
* Frame globs: a marker whose frame the policy denies is withheld (no model, no TRANSFORM;
  said in the STATUS and in list_markers); the fixed frame is judged at creation.
* MESH_RESOURCE reads files only inside the mesh roots (--robot-dir, --package-path), worded
  as for a robot's mesh: a refused file and a missing one get the same answer. An embedded
  ``mesh_file`` (newer ROS 2) is not read. ``http(s)://`` is never fetched.
* DELETEALL removes every marker of the topic, whatever its ns (RViz 2 does so).
"""

from __future__ import annotations

import asyncio
import heapq
import json
import logging
import math
import threading
import time
from collections import deque
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Optional, Union, cast

import numpy as np

from bridge.codecs import CodecError, codec_for
from bridge.codecs.cdr import CdrError
from bridge.core.content_guards import ContentGuard
from bridge.core.dispatch import Created, Handler, made_bridge
from bridge.core.hub import Hub, Replier
from bridge.core.logging_limits import RateLimitedLog
from bridge.core.outbox import SharedFrame
from bridge.core.security import DEFAULT_MAX_MARKER_BYTES, BridgeKey, strip_frame
from bridge.core.threads import OnFailure, start_thread
from bridge.markers.cdr import layout_supported, read_marker, read_marker_array
from bridge.markers.convert import ADD, DELETE, DELETEALL, MarkerEvent, events_of
from bridge.markers.geometry import (MarkerError, MarkerModel, MarkerSpec, build_model,
                                     model_bytes, packed, warm_up)
from bridge.tf.buffer import TfBuffer
from bridge.tf.errors import ExtrapolationError, TfError
from bridge.tf.lookups import LookupKey, LookupStreams
from bridge.tf.math import Quat, Tf7, Vec3, compose, quat_normalize
from protocol.commands import (CommandFailedError, CreateMarkerSubscriber, ErrorCode, ListMarkers,
                               ListMarkersResult, MarkerSubscriberBridge, Op,
                               RemoveMarkerSubscriber, RemovedMarkerSubscriber)
from protocol.conversions import igtl_stamp_or_now
from protocol.messages import Message, StatusCode, String
from protocol.naming import (KEY_COLOR, KEY_DELETED, KEY_FORMAT, KEY_MARKER_TYPE, KEY_MARKERS,
                             KEY_PARENT_DEVICE, UNITS_MM, DeviceNameRegistry, NameKey,
                             NamingError, metadata_for)

if TYPE_CHECKING:  # ROS where the daemon subscribes: `MarkerServing` is ROS-free (a
    # player feeds it a bag's messages)
    from bridge.ros.ros_node import RosNode

__all__ = ["MAX_MARKERS", "MAX_QUEUED", "MarkerBridges", "MarkerServing", "place_unlocked"]

log = logging.getLogger(__name__)

MAX_QUEUED = 64  # messages waiting for a topic's worker; past that the oldest go
MAX_MARKERS = 10_000  # live markers of one topic; more are refused (STATUS)
# A topic's worker meshes at most this share of the time (of one core): a peer's storm
# then costs the daemon its share, and the worker folds what comes meanwhile.
MESH_DUTY = 0.25
_MAX_REFUSALS_KEPT = 16  # whole-message refusals folded while the loop is behind
_MAX_IN_FLIGHT = 4  # batches handed to the loop and not applied yet (worker waits)

MarkerKey = tuple[str, int]  # (ns, id)
MARKER_TYPE = "visualization_msgs/msg/Marker"
MARKER_ARRAY_TYPE = "visualization_msgs/msg/MarkerArray"


def place_unlocked(spec: MarkerSpec, fixed_frame: str, buffer: TfBuffer,
                   resolve: Callable[[str], str],
                   memo: Optional[dict[tuple[str, int], Optional[Tf7]]] = None,
                   ) -> Optional[MarkerSpec]:
    """An unlocked marker placed in ``fixed_frame`` by the fixed<-frame transform at its
    stamp (the latest for stamp 0, or where tf has nothing at the stamp), or None where it
    is not moved: already in the fixed frame, a pose build_model refuses anyway, or a frame
    tf cannot reach yet. ``resolve`` maps frame ids to the buffer's; ``memo`` keeps the
    transforms looked up for one batch (an array's markers share a frame)."""
    frame = spec.frame.lstrip("/")
    if not frame or frame == fixed_frame:
        return None
    # A spec holds 4 orientation values (x, y, z, w) and 3 position values (convert.py).
    orientation = cast(Quat, tuple(float(v) for v in spec.orientation))
    position = cast(Vec3, tuple(float(v) for v in spec.position))
    if not all(math.isfinite(v) for v in orientation + position):
        return None
    stamp_ns = max(spec.stamp[0] * 1_000_000_000 + spec.stamp[1], 0)
    memo = {} if memo is None else memo
    if (frame, stamp_ns) not in memo:
        memo[(frame, stamp_ns)] = _fixed_from(buffer, resolve(fixed_frame), resolve(frame),
                                              stamp_ns)
    where = memo[(frame, stamp_ns)]
    if where is None:
        return None
    quat = quat_normalize(orientation) if any(orientation) else (0.0, 0.0, 0.0, 1.0)
    pose = compose(where, position + quat)
    return replace(spec, frame=fixed_frame, position=np.array(pose[:3]),
                   orientation=np.array(pose[3:]))


def _fixed_from(buffer: TfBuffer, fixed: str, frame: str, stamp_ns: int) -> Optional[Tf7]:
    try:
        try:
            return buffer.lookup(fixed, frame, stamp_ns).as_tuple()
        except ExtrapolationError:  # tf not there yet at the stamp (or gone): the latest
            return buffer.lookup(fixed, frame, 0).as_tuple()
    except TfError:
        return None


class BudgetError(MarkerError):
    """A model the memory budget cannot hold (the clients that show its topic get a
    STATUS RESOURCE_ERROR as well)."""


class ModelBudget:
    """Bytes of marker models kept (each once, shared by the clients it goes to), all
    topics together and per topic (half of that), from any thread. A model is charged
    before it is made (`charge`, its size from `model_bytes`), settled at its real size
    once made, and released when it is dropped."""

    def __init__(self, total_limit: int = DEFAULT_MAX_MARKER_BYTES) -> None:
        self.topic_limit = total_limit // 2
        self.total_limit = total_limit
        self.total = 0
        self._lock = threading.Lock()
        self._charges: dict[tuple[str, MarkerKey], int] = {}
        self._topics: dict[str, int] = {}

    def charge(self, topic: str, key: MarkerKey, nbytes: int, *,
               settle: bool = False) -> Optional[MarkerError]:
        """Charge ``nbytes`` for the marker (replacing what it was charged); the refusal,
        charging nothing, if that is over a bound (``settle``: always charged)."""
        with self._lock:
            old = self._charges.get((topic, key), 0)
            on_topic = self._topics.get(topic, 0) - old + nbytes
            total = self.total - old + nbytes
            if not settle and on_topic > self.topic_limit:
                return BudgetError("points", f"a model within the topic's memory budget "
                                   f"({self.topic_limit} bytes of models a topic; "
                                   f"{max(0, self.topic_limit - on_topic + nbytes)} left)",
                                   f"a model of {nbytes} bytes")
            if not settle and total > self.total_limit:
                return BudgetError("points", f"a model within the daemon's memory budget "
                                   f"({self.total_limit} bytes of models, all topics; "
                                   f"{max(0, self.total_limit - total + nbytes)} left)",
                                   f"a model of {nbytes} bytes")
            self._charges[(topic, key)] = nbytes
            self._topics[topic] = on_topic
            self.total = total
            return None

    def release(self, topic: str, key: Optional[MarkerKey] = None) -> None:
        """A marker's model is gone (``key`` None: every model of the topic)."""
        with self._lock:
            keys = ([k for k in self._charges if k[0] == topic] if key is None
                    else [(topic, key)])
            for k in keys:
                nbytes = self._charges.pop(k, 0)
                self.total -= nbytes
                self._topics[topic] = self._topics.get(topic, 0) - nbytes
            if not self._topics.get(topic):
                self._topics.pop(topic, None)

    def of_topic(self, topic: str) -> int:
        with self._lock:
            return self._topics.get(topic, 0)


@dataclass(frozen=True, eq=False)
class _Show:
    key: MarkerKey
    frame: str  # the marker's header frame ("": the fixed frame): the frame policy's
    parent: str  # the frame its model's coordinates are in (the fixed frame once placed)
    digest: bytes
    model: MarkerModel
    lifetime_ns: int
    stamp: tuple[int, int] = (0, 0)


@dataclass(frozen=True)
class _Gone:
    key: Optional[MarkerKey]  # None: every marker (DELETEALL)


@dataclass(frozen=True, eq=False)
class _Refused:
    key: MarkerKey
    error: MarkerError


@dataclass(frozen=True, eq=False)
class _MessageRefused:
    error: MarkerError  # the whole message (a MarkerArray over the bound)


_Update = Union[_Show, _Gone, _Refused, _MessageRefused]


@dataclass
class _Live:
    key: MarkerKey
    name_key: NameKey
    device: str
    frame: str  # its header frame
    parent: str  # the frame of its model's coordinates (the fixed frame once placed)
    kind: str
    body_type: str
    digest: bytes
    points: int
    expires_ns: int = 0  # monotonic; 0: never


@dataclass
class _FrameRef:
    device: str
    name_key: NameKey
    handle: LookupKey
    users: int = 0


@dataclass
class _Folded:
    """Messages read but not handed to the loop yet, as their end state (`_Worker._fold`)."""

    refused: list[_Update] = field(default_factory=list)
    delete_all: bool = False
    last: dict[MarkerKey, MarkerEvent] = field(default_factory=dict)


class _Worker:
    """One topic's reader: a bounded queue of messages, one thread that meshes them."""

    def __init__(self, sub: _Subscription, mesh_roots: Optional[tuple[Path, ...]],
                 package_paths: Mapping[str, Path], *, budget: Optional[ModelBudget] = None,
                 gate: Optional[threading.Lock] = None) -> None:
        self._sub = sub
        self._mesh_roots = mesh_roots
        self._package_paths = dict(package_paths)
        self._budget = budget or ModelBudget()
        self._gate = gate or threading.Lock()  # the daemon's: one topic meshes at a time
        self._queue: deque[Any] = deque()
        self._cond = threading.Condition()
        self._in_flight = 0  # batches handed to the loop, not applied yet (under _cond)
        self._stopped = False
        # (ns, id) -> (digest, model) of what was last meshed: an unchanged marker is
        # handed on without meshing; the loop may have expired it and needs the model.
        self._models: dict[MarkerKey, tuple[bytes, MarkerModel]] = {}
        self._lock = threading.Lock()
        self.dropped = 0
        self.meshed = 0
        # A bug that escapes the worker's own handling is logged, and the worker starts
        # again (what it had folded is lost; the next markers make it anew).
        self._thread = start_thread(f"markers {sub.topic}", self._run, OnFailure.RESTART)

    def put(self, msg: Any) -> None:  # ROS executor thread
        with self._cond:
            if self._stopped:
                return
            if len(self._queue) >= MAX_QUEUED:
                self._queue.popleft()
                self.dropped += 1
            self._queue.append(msg)
            self._cond.notify()

    def applied(self) -> None:  # loop thread: a batch is done
        with self._cond:
            self._in_flight -= 1
            self._cond.notify()

    def forget(self, key: MarkerKey) -> None:  # loop thread: dropped there
        with self._lock:
            self._models.pop(key, None)
            self._budget.release(self._sub.topic, key)

    def remember(self, key: MarkerKey, digest: bytes, model: MarkerModel) -> None:
        with self._lock:
            self._models[key] = (digest, model)
            self._budget.charge(self._sub.topic, key, model.nbytes, settle=True)

    def _forget_all(self) -> None:
        with self._lock:
            self._models.clear()
            self._budget.release(self._sub.topic)

    def stop(self) -> None:
        with self._cond:
            self._stopped = True
            self._queue.clear()
            self._cond.notify()
        self._forget_all()

    def _run(self) -> None:
        # While the loop is behind (`_MAX_IN_FLIGHT` batches not applied), the worker keeps
        # reading what arrives into one folded end state (`_fold`), so the queue of raw
        # messages stays short and no DELETE is dropped with an old message; the folded
        # state is meshed and handed over once the loop takes batches again.
        folded: Optional[_Folded] = None
        try:
            warm_up()  # the mesh libraries load now, not with a storm's first marker
        except Exception:  # noqa: BLE001 - the markers that need them will say why
            log.exception("markers on %s: the mesh primitives could not be made",
                          self._sub.topic)
        while True:
            with self._cond:
                while not self._stopped and not self._queue and not (
                        folded is not None and self._in_flight < _MAX_IN_FLIGHT):
                    self._cond.wait()
                if self._stopped:
                    return
                messages = list(self._queue)
                self._queue.clear()
                can_hand_over = self._in_flight < _MAX_IN_FLIGHT
            spent = 0.0
            try:
                if messages:
                    folded = self._fold(messages, folded)
                if folded is None or not can_hand_over:
                    continue
                with self._gate:
                    began = time.thread_time()
                    updates = self._updates(folded)
                    spent = time.thread_time() - began
                folded = None
            except Exception:  # noqa: BLE001 - a bug on one message must not end the topic
                log.exception("markers on %s: a message could not be read", self._sub.topic)
                folded = None
                continue
            if updates:  # else nothing changed (an array re-sent as it was): no wake-up
                with self._cond:
                    if self._stopped:
                        return
                    self._in_flight += 1
                self._sub.hand_over(updates)
            # Its share of the time (MESH_DUTY): what comes meanwhile is folded after.
            rest = spent * (1.0 / MESH_DUTY - 1.0)
            if rest > 0.001:
                with self._cond:
                    self._cond.wait_for(lambda: self._stopped, timeout=rest)

    def _events(self, msg: Any) -> list[MarkerEvent]:
        sub = self._sub
        if isinstance(msg, bytes):  # a raw Marker / MarkerArray subscription
            try:
                return (read_marker_array(msg) if sub.ros_type == MARKER_ARRAY_TYPE
                        else read_marker(msg))
            except CdrError:  # another encoding: the ordinary way
                from rclpy.serialization import deserialize_message

                msg = deserialize_message(msg, sub.message_class)
        return events_of(sub.ros_type, msg)

    def _fold(self, messages: list[Any], into: Optional[_Folded] = None) -> _Folded:
        """The messages' events folded into their end state, in order, after ``into``
        (what was folded before): messages refused whole, whether a DELETEALL came, the last
        event of each marker after the last DELETEALL. Applying that end state leaves the
        loop where applying every message in turn would; only the states in between are
        skipped."""
        folded = into if into is not None else _Folded()
        for msg in messages:
            try:
                events = self._events(msg)
            except MarkerError as error:
                folded.refused.append(_MessageRefused(error))
                del folded.refused[:-_MAX_REFUSALS_KEPT]  # the newest say enough
                continue
            for event in events:
                if event.action == DELETEALL:
                    folded.delete_all = True
                    folded.last.clear()
                    continue
                key = (event.ns, event.id)
                folded.last.pop(key, None)  # keep the order of the latest events
                folded.last[key] = event
        return folded

    def _updates(self, folded: _Folded) -> list[_Update]:
        out, delete_all, events = list(folded.refused), folded.delete_all, folded.last
        placements: dict[tuple[str, int], Optional[Tf7]] = {}  # (frame, stamp) -> fixed<-frame
        if delete_all:
            self._forget_all()
            out.append(_Gone(None))
        for key, event in events.items():
            if event.action == DELETE:
                self.forget(key)
                out.append(_Gone(key))
                continue
            assert event.action == ADD
            if event.error is not None or event.spec is None:
                self.forget(key)
                out.append(_Refused(key, event.error or MarkerError("marker", "a marker",
                                                                    "nothing")))
                continue
            spec = event.spec
            frame = spec.frame.lstrip("/")
            placed = (None if spec.frame_locked or not frame
                      else self._sub.owner.placed(self._sub, spec, placements))
            if placed is not None:
                spec = placed
            digest = spec.digest()
            with self._lock:
                known = self._models.get(key)
            if known is not None and known[0] == digest:
                if not spec.lifetime_ns:
                    # Unchanged and never expiring: the loop has it live (whatever drops it
                    # there forgets it here, so a re-send after that goes through).
                    continue
                model = known[1]  # unchanged: only its lifetime is renewed
            else:
                # Judged before anything is made: a model the budget cannot hold is refused.
                refusal = self._budget.charge(self._sub.topic, key, model_bytes(spec))
                try:
                    if refusal is not None:
                        raise refusal
                    model = packed(build_model(spec, mesh_roots=self._mesh_roots,
                                               package_paths=dict(self._package_paths)))
                except MarkerError as error:
                    self.forget(key)
                    out.append(_Refused(key, error))
                    continue
                self.meshed += 1
                self.remember(key, digest, model)
            out.append(_Show(key, frame, spec.frame.lstrip("/"), digest, model,
                             spec.lifetime_ns, spec.stamp))
        return out


@dataclass(eq=False)
class _Subscription:
    topic: str
    ros_type: str
    request: CreateMarkerSubscriber
    fixed_frame: str
    topic_key: NameKey
    device: str
    owner: MarkerServing
    guard: ContentGuard  # which marker frames a client may see (from its create request)
    markers: dict[MarkerKey, _Live] = field(default_factory=dict)
    withheld: dict[MarkerKey, str] = field(default_factory=dict)
    errors: dict[MarkerKey, str] = field(default_factory=dict)
    message_class: Any = None
    raw: bool = False  # taken as CDR bytes (bridge.markers.cdr), not rclpy messages
    worker: Optional[_Worker] = None
    subscription: Any = None
    received: int = 0
    closed: bool = False
    last_error: str = ""
    # Its bridge: its devices go to whom that goes (`Hub.bridge_device`).
    bridge: Optional[BridgeKey] = None
    last_budget_status: float = 0.0  # monotonic: one STATUS a second at most

    def on_message(self, msg: Any) -> None:  # ROS executor thread: hand off only
        self.received += 1
        worker = self.worker
        if worker is not None:
            worker.put(msg)

    def hand_over(self, updates: list[_Update]) -> None:  # worker thread
        self.owner.hub_call(self.owner.apply, self, updates)


class MarkerServing:
    """Marker subscribers: models per marker, a TRANSFORM per frame, lifetimes. Where the
    messages come from is a subclass's (`_open_source`, `_close_source`): the daemon's
    `MarkerBridges` subscribes to ROS, the player (bridge/playback) feeds a bag's."""

    def __init__(self, hub: Hub, names: DeviceNameRegistry, *, tf: LookupStreams,
                 package_paths: Optional[Mapping[str, Path]] = None,
                 max_model_bytes: int = DEFAULT_MAX_MARKER_BYTES) -> None:
        self._hub = hub
        self._names = names
        self._tf = tf
        self._package_paths = {k: Path(v) for k, v in (package_paths or {}).items()}
        self.subscriptions: dict[str, _Subscription] = {}
        self._frames: dict[tuple[str, str], _FrameRef] = {}
        self._expiry: list[tuple[int, int, str, MarkerKey]] = []  # (due, seq, topic, key)
        self._seq = 0
        self._timer: Optional[asyncio.TimerHandle] = None
        self._timer_due = 0
        self._refusals = RateLimitedLog(log)
        self.budget = ModelBudget(max_model_bytes)
        self._meshing = threading.Lock()  # one topic's worker meshes at a time

    # ------------------------------------------------------------------ sources

    def _check_source(self, topic: str, ros_type: str, type_name: str) -> tuple[Any, bool]:
        """Refuse a topic the source cannot give as ``ros_type`` (``type_name`` as the
        request spelt it); (the message class, or None, and whether messages come as CDR
        bytes for bridge.markers.cdr)."""
        raise NotImplementedError

    def _open_source(self, sub: _Subscription) -> None:
        """Start feeding ``sub.on_message``."""
        raise NotImplementedError

    def _close_source(self, sub: _Subscription) -> None:
        pass

    def hub_call(self, callback: Any, *args: Any) -> None:
        self._hub.call_soon(callback, *args)

    def placed(self, sub: _Subscription, spec: MarkerSpec,
               memo: dict[tuple[str, int], Optional[Tf7]]) -> Optional[MarkerSpec]:
        """`place_unlocked` in this daemon's tf buffer (worker thread: it is thread-safe).
        A marker's frame ids are ROS's, as tf holds them: ``--frame-prefix`` (for frame
        ids a client writes) does not apply, so the frame the policy judges, the one a
        marker is placed by and the one its TRANSFORM follows are one name."""
        return place_unlocked(spec, sub.fixed_frame, self._tf.buffer, strip_frame, memo)

    # ------------------------------------------------------------------ ops

    def create(self, request: CreateMarkerSubscriber, client: Optional[Replier],
               guard: ContentGuard) -> Created[MarkerSubscriberBridge]:
        topic = request.topic
        ros_type = request.ros_type
        existing = self.subscriptions.get(topic)
        if existing is not None:
            if existing.request == request:  # a reconnecting client re-creates what it had
                return Created(self._describe(existing), existed=True)
            raise CommandFailedError("topic", "a topic without a marker subscriber "
                                     "(remove_marker_subscriber first, or repeat the same "
                                     "request)", topic, code=ErrorCode.ALREADY_EXISTS)
        message_class, raw = self._check_source(topic, ros_type, request.type)
        topic_key = NameKey.marker_topic(topic)
        device = self._names.register(topic_key)
        sub = _Subscription(topic, ros_type, request, request.fixed_frame.lstrip("/"),
                            topic_key, device, self, guard, message_class=message_class,
                            bridge=made_bridge(request))
        self._limit(sub, device)
        sub.raw = raw
        sub.worker = _Worker(sub, guard.readable_roots(), self._package_paths, budget=self.budget,
                             gate=self._meshing)
        try:
            self._open_source(sub)
        except BaseException:
            sub.worker.stop()
            self._hub.forget(device)
            self._names.release(topic_key)
            raise
        self.subscriptions[topic] = sub
        self._index(sub, [])
        log.info("markers from %s (%s) in fixed frame %s: status device %r", topic, ros_type,
                 sub.fixed_frame, device)
        return Created(self._describe(sub), existed=False)

    # ------------------------------------------------------------------ audiences

    def _limit(self, sub: _Subscription, device: str) -> None:
        """``device`` is one of ``sub``'s: it goes to whom ``sub``'s bridge goes."""
        if sub.bridge is not None:
            self._hub.bridge_device(sub.bridge, device)

    def _find(self, topic: str) -> _Subscription:
        sub = self.subscriptions.get(topic)
        if sub is None:
            raise CommandFailedError("topic", "a topic with a marker subscriber", topic,
                                     code=ErrorCode.NOT_FOUND)
        return sub

    def remove(self, request: RemoveMarkerSubscriber) -> RemovedMarkerSubscriber:
        sub = self._find(request.topic)
        topic = sub.topic
        devices = [live.device for live in sub.markers.values()] + [sub.device]
        self._close(sub)
        return RemovedMarkerSubscriber(topic, tuple(devices))

    def list_markers(self, request: ListMarkers) -> ListMarkersResult:
        sub = self._find(request.topic)
        now = time.monotonic_ns()
        return ListMarkersResult(
            sub.topic, sub.device,
            markers=tuple({"ns": live.key[0], "id": live.key[1], "device": live.device,
                           "type": live.kind, "frame": live.frame, "points": live.points,
                           "placed": live.parent != live.frame,
                           "frame_device": self._frames[(sub.fixed_frame, live.parent)].device,
                           "expires_in": (round((live.expires_ns - now) / 1e9, 3)
                                          if live.expires_ns else None)}
                          for live in sub.markers.values()),
            withheld=tuple({"ns": k[0], "id": k[1], "reason": why}
                           for k, why in sub.withheld.items()),
            errors=tuple({"ns": k[0], "id": k[1], "error": why}
                         for k, why in sub.errors.items()))

    # ------------------------------------------------------------------ loop thread

    def apply(self, sub: _Subscription, updates: list[_Update]) -> None:
        """One message's updates (loop thread), then the index if the live set changed."""
        try:
            if sub.closed:
                return
            added: list[str] = []
            gone: list[str] = []
            with self._hub.batch():
                for update in updates:
                    if isinstance(update, _Show):
                        self._show(sub, update, added, gone)
                    elif isinstance(update, _Gone):
                        if update.key is None:  # DELETEALL
                            for key in list(sub.markers):
                                self._drop(sub, key, gone)
                            sub.withheld.clear()
                            sub.errors.clear()
                        else:
                            sub.withheld.pop(update.key, None)
                            sub.errors.pop(update.key, None)
                            self._drop(sub, update.key, gone)
                    elif isinstance(update, _MessageRefused):
                        sub.last_error = f"message refused: {update.error}"
                        self._refusals.warning(f"{sub.topic} message", None,
                                               "markers on %s: %s", sub.topic, sub.last_error)
                        self._index(sub, gone, error=sub.last_error)
                        gone.clear()
                    else:
                        self._refuse(sub, update, gone)
                if added or gone:
                    self._index(sub, gone)
        finally:
            worker = sub.worker
            if worker is not None:
                worker.applied()

    def _show(self, sub: _Subscription, update: _Show, added: list[str],
              gone: list[str]) -> None:
        key = update.key
        frame = update.frame or sub.fixed_frame
        parent = update.parent or sub.fixed_frame
        reason = sub.guard.frame_refusal(frame)
        if reason is not None:
            if sub.withheld.get(key) != reason:
                sub.withheld[key] = reason
                self._refusals.warning(f"{sub.topic} {frame}", None, "markers on %s: %s",
                                       sub.topic, reason)
            self._drop(sub, key, gone)
            return
        sub.withheld.pop(key, None)
        sub.errors.pop(key, None)
        live = sub.markers.get(key)
        expires = time.monotonic_ns() + update.lifetime_ns if update.lifetime_ns else 0
        model = update.model
        body_type = model.type_name
        if live is not None and live.digest == update.digest:
            live.expires_ns = expires  # unchanged: renew the lifetime, send nothing
            self._schedule(sub, live)
            return
        if live is not None and (live.parent != parent or live.body_type != body_type):
            self._drop(sub, key, gone)  # a new parent or node class: a new device
            if sub.worker is not None:
                sub.worker.remember(key, update.digest, model)
            live = None
        if live is None:
            if len(sub.markers) >= MAX_MARKERS:
                self._refuse(sub, _Refused(key, MarkerError(
                    "id", f"at most {MAX_MARKERS} live markers on a topic",
                    f"marker {len(sub.markers) + 1}")), gone)
                return
            try:  # a namespace or frame no device name or tf lookup can hold (NUL)
                name_key = NameKey.marker(sub.topic, key[0], key[1])
                self._use_frame(sub, parent)
            except (NamingError, TfError) as error:
                self._refuse(sub, _Refused(key, MarkerError(
                    "ns/frame", "a namespace and frame id usable as names (no NUL)",
                    f"{key[0]!r} in frame {frame!r} ({error})")), gone)
                return
            device = self._names.register(name_key)
            self._limit(sub, device)
            live = _Live(key, name_key, device, frame, parent, model.kind, body_type,
                         update.digest, model.point_count)
            sub.markers[key] = live
            added.append(device)
            if device in gone:
                gone.remove(device)
        live.frame, live.digest, live.kind, live.points = (frame, update.digest, model.kind,
                                                           model.point_count)
        live.expires_ns = expires
        metadata = metadata_for(live.name_key, frame=parent, units=UNITS_MM)
        metadata[KEY_MARKER_TYPE] = model.kind
        metadata[KEY_PARENT_DEVICE] = self._frames[(sub.fixed_frame, parent)].device
        metadata[KEY_COLOR] = " ".join(f"{c:.6g}" for c in model.rgba)
        metadata.update(model.metadata)
        # Stamped with the marker's header stamp, as topic bridges stamp their messages.
        stamp = igtl_stamp_or_now(*update.stamp)
        # A stream: a client that is behind gets only the newest model of each marker,
        # and the model's content is shared by every client, not copied per client.
        self._hub.stream_frame(live.device, SharedFrame(Message(
            device_name=live.device, body=model.body, timestamp=stamp, metadata=metadata),
            content_crc=model.content_crc))
        self._schedule(sub, live)

    def _refuse(self, sub: _Subscription, update: _Refused, gone: list[str]) -> None:
        key = update.key
        text = f"marker ns {key[0]!r} id {key[1]}: {update.error}"
        self._drop(sub, key, gone)
        if isinstance(update.error, BudgetError):
            self._tell_budget(sub, text)
        if sub.errors.get(key) == text:
            return
        sub.errors[key] = text
        sub.last_error = text
        self._refusals.warning(f"{sub.topic} {key}", None, "markers on %s: %s", sub.topic,
                               text)
        self._index(sub, gone, error=text)
        gone.clear()  # the index just sent said so

    def _tell_budget(self, sub: _Subscription, text: str) -> None:
        """A STATUS RESOURCE_ERROR on the topic's device to the clients that show it, at
        most one a second (the topic's STRING names every refusal)."""
        now = time.monotonic()
        if now - sub.last_budget_status < 1.0:
            return
        sub.last_budget_status = now
        for client in tuple(cast(Replier, c) for c in self._hub.audience(sub.device)):
            client.send_status(sub.device, StatusCode.RESOURCE_ERROR, text[:4000])

    def _drop(self, sub: _Subscription, key: MarkerKey, gone: list[str]) -> None:
        if sub.worker is not None:
            sub.worker.forget(key)  # a later identical marker is then shown again
        live = sub.markers.pop(key, None)
        if live is None:
            return
        self._hub.forget(live.device)
        self._names.release(live.name_key)
        self._release_frame(sub.fixed_frame, live.parent)
        gone.append(live.device)

    def _index(self, sub: _Subscription, gone: list[str], error: str = "") -> None:
        """The topic's STRING: which marker devices are live, which just went (metadata,
        which holds any length; a STRING body holds 64 KiB), and a JSON summary with the
        last error. A STRING, not a STATUS: 3D Slicer makes a text node of it, whose
        changes the Slicer module hands to the client (it makes no node of a STATUS)."""
        metadata = metadata_for(sub.topic_key, ros_type=sub.ros_type, frame=sub.fixed_frame)
        metadata[KEY_FORMAT] = "json"
        metadata[KEY_MARKERS] = json.dumps([live.device for live in sub.markers.values()])
        metadata[KEY_DELETED] = json.dumps(sorted(set(gone)))
        # Every index names the last refusal of a marker still refused: a later index
        # (and so a client that connects later) must not lose it.
        error = error or next(reversed(sub.errors.values()), "")
        summary = {"markers": len(sub.markers), "withheld": len(sub.withheld),
                   "error": error[:4000]}
        self._hub.stream(Message(device_name=sub.device, body=String(json.dumps(summary)),
                                 metadata=metadata))

    # ------------------------------------------------------------------ frames

    def _use_frame(self, sub: _Subscription, frame: str) -> None:
        """A marker of ``sub`` is in ``frame``: its TRANSFORM (shared by every marker of
        every topic in it) goes to the audiences of those topics' bridges (to everyone
        once one of them goes to everyone)."""
        fixed = sub.fixed_frame
        ref = self._frames.get((fixed, frame))
        if ref is None:
            name_key = NameKey.marker_frame(fixed, frame)
            device = self._names.register(name_key)
            self._limit(sub, device)
            metadata = metadata_for(name_key, frame=fixed, units=UNITS_MM)
            handle = self._tf.stream_lookup(fixed, frame, device=device, metadata=metadata)
            ref = self._frames[(fixed, frame)] = _FrameRef(device, name_key, handle)
        else:
            self._limit(sub, ref.device)
        ref.users += 1

    def _release_frame(self, fixed: str, frame: str) -> None:
        ref = self._frames.get((fixed, frame))
        if ref is None:
            return
        ref.users -= 1
        if ref.users <= 0:
            del self._frames[(fixed, frame)]
            self._tf.stop_lookup(ref.handle)
            self._hub.forget(ref.device)
            self._names.release(ref.name_key)

    # ------------------------------------------------------------------ lifetimes

    def _schedule(self, sub: _Subscription, live: _Live) -> None:
        if not live.expires_ns:
            return
        self._seq += 1
        heapq.heappush(self._expiry, (live.expires_ns, self._seq, sub.topic, live.key))
        self._arm()

    def _arm(self) -> None:
        if not self._expiry:
            return
        due = self._expiry[0][0]
        if self._timer is not None:
            if self._timer_due <= due:
                return
            self._timer.cancel()
        loop = asyncio.get_running_loop()
        self._timer = loop.call_later(max(0, due - time.monotonic_ns()) / 1e9, self._expire)
        self._timer_due = due

    def _expire(self) -> None:
        self._timer = None
        now = time.monotonic_ns()
        gone_by_topic: dict[str, list[str]] = {}
        while self._expiry and self._expiry[0][0] <= now:
            due, _, topic, key = heapq.heappop(self._expiry)
            sub = self.subscriptions.get(topic)
            if sub is None:
                continue
            live = sub.markers.get(key)
            if live is None or live.expires_ns != due:
                continue  # renewed or deleted since: a stale entry
            self._drop(sub, key, gone_by_topic.setdefault(topic, []))
        for topic, gone in gone_by_topic.items():
            sub = self.subscriptions.get(topic)
            if sub is not None and gone:
                self._index(sub, gone)
        if len(self._expiry) > 4 * max(16, sum(len(s.markers) for s in
                                               self.subscriptions.values())):
            # Renewals leave stale entries behind: rebuild from the live markers.
            self._expiry = [(live.expires_ns, i, s.topic, live.key)
                            for i, (s, live) in enumerate(
                                (s, live) for s in self.subscriptions.values()
                                for live in s.markers.values()) if live.expires_ns]
            heapq.heapify(self._expiry)
        self._arm()

    # ------------------------------------------------------------------ capability

    def _close(self, sub: _Subscription) -> None:
        sub.closed = True
        if self.subscriptions.get(sub.topic) is sub:
            del self.subscriptions[sub.topic]
        if sub.worker is not None:
            sub.worker.stop()
        self._close_source(sub)
        gone: list[str] = []
        for key in list(sub.markers):
            self._drop(sub, key, gone)
        self._hub.forget(sub.device)
        self._names.release(sub.topic_key)

    def handlers(self) -> dict[type[Op], Handler]:
        return {
            CreateMarkerSubscriber: self.create,
            RemoveMarkerSubscriber: lambda request, _: self.remove(request),
            ListMarkers: lambda request, _: self.list_markers(request),
        }

    def _describe(self, sub: _Subscription) -> MarkerSubscriberBridge:
        worker = sub.worker
        return MarkerSubscriberBridge(
            "marker_subscriber", sub.topic, sub.ros_type, sub.fixed_frame, sub.device,
            sub.request.qos.to_dict(), sub.received, len(sub.markers), len(sub.withheld),
            len(sub.errors), sub.raw, worker.dropped if worker is not None else 0,
            worker.meshed if worker is not None else 0, self.budget.of_topic(sub.topic))

    def recorded_topics(self) -> dict[str, Optional[str]]:
        """What a recording takes from here (any thread): every marker topic."""
        return {topic: sub.request.ros_type for topic, sub in tuple(self.subscriptions.items())}

    def describe(self) -> list[dict[str, Any]]:
        return [self._describe(sub).to_dict() for sub in self.subscriptions.values()]

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        for sub in list(self.subscriptions.values()):
            self._close(sub)


class MarkerBridges(MarkerServing):
    """The daemon's marker subscribers: each a ROS subscription (markers taken raw where
    the installed Marker is the layout bridge.markers.cdr reads)."""

    def __init__(self, ros: RosNode, hub: Hub, names: DeviceNameRegistry, *, tf: LookupStreams,
                 package_paths: Optional[Mapping[str, Path]] = None,
                 max_model_bytes: int = DEFAULT_MAX_MARKER_BYTES) -> None:
        super().__init__(hub, names, tf=tf, package_paths=package_paths,
                         max_model_bytes=max_model_bytes)
        self._ros = ros

    def _check_source(self, topic: str, ros_type: str, type_name: str) -> tuple[Any, bool]:
        from bridge.ros.graph_types import refuse_other_type

        refuse_other_type(self._ros, topic, ros_type, "type")
        try:
            message_class = codec_for(ros_type).message_class
        except CodecError as error:
            raise CommandFailedError("type", "a message type installed in the daemon's "
                                     "environment", f"{type_name!r} ({error})",
                                     code=ErrorCode.UNKNOWN_ROS_TYPE) from None
        # Markers are read from their bytes when the installed Marker is the one the CDR
        # reader knows (a 1000-marker array: a few ms instead of ~100 through rclpy).
        raw = ros_type in (MARKER_TYPE, MARKER_ARRAY_TYPE) and layout_supported(
            codec_for(MARKER_TYPE).message_class.get_fields_and_field_types())
        return message_class, raw

    def _open_source(self, sub: _Subscription) -> None:
        from bridge.ros.qos import qos_profile

        sub.subscription = self._ros.stream_node.create_subscription(
            sub.message_class, sub.topic, sub.on_message, qos_profile(sub.request.qos),
            raw=sub.raw)

    def _close_source(self, sub: _Subscription) -> None:
        if sub.subscription is not None:
            self._ros.destroy(sub.subscription)
            sub.subscription = None

