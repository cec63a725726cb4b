"""The daemon's tf2 capability: the buffer fed from /tf and /tf_static, lookups streamed to
clients when they change, one-shot lookups, and broadcasters publishing clients' transforms.

    ROS streams thread (EventsExecutor)            asyncio loop thread
    ───────────────────────────────────            ───────────────────
    /tf, /tf_static ─► read the TFMessage raw                create/remove lookups
                       buffer.set_transforms(batch)          timer: registry.due (rate
                       registry.updates(changed frames)         caps, new lookups)
                       hub.post_frames: one write per        wake one-shot lookups
                       client for the whole update           that wait (when any do)

Why this shape (and not the reference's): SlicerROS2 runs every lookup on a 50 Hz timer
whether anything moved or not, so a client sees a change up to 20 ms late and idle lookups
cost CPU forever. Here a lookup is evaluated only when a frame of its chain changed
(`LookupRegistry`), and sent only when its result differs from the last one sent; a lookup
with ``rate_hz`` gets at most that many messages a second, the newest value winning.

Threads: a /tf batch is evaluated and written where it arrives, as the pose hot path is
(`Hub.post_frames`): a 7-link robot at 1 kHz would otherwise cost a loop wake-up and a GIL
hand-off per message. The loop is woken only when it has something to do: a rate-capped
result to release earlier than its timer, or a one-shot lookup waiting for data. One
delivery lock orders evaluation and writing between the two threads, so a newer result is
never overtaken by an older one, and a removed lookup's device never comes back.

Frames: a client's frame ids are used as given unless ``frame_prefix`` is set (the
``tf_prefix`` idea of ROS 1, for a daemon started with ``--namespace`` next to a namespaced
robot): then a relative frame ``base`` means ``<prefix>base`` and ``/base`` means ``base``.
The topics stay ``/tf`` and ``/tf_static`` whatever the node's namespace, as with tf2_ros;
pass relative ``tf_topic`` / ``tf_static_topic`` names to use namespaced ones instead.

Pose groups: lookups another capability streams together (a robot's links) go as one TDATA
per update, every placed element in each message (`open_pose_group`, `stream_lookup(group=)`),
not a TRANSFORM each: one message for the receiver's main thread instead of one per link.

Units: the buffer holds metres; clients get 4x4 matrices in mm, and the TRANSFORM messages a
client sends to a broadcaster are in mm. Every conversion goes through `protocol.conversions`.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Awaitable, Callable, Optional, Union

import numpy as np
import numpy.typing as npt

from bridge.codecs.cdr import CdrError, read_tf_message
from bridge.codecs.fast import pack_transform, transform_body

from bridge.core.content_guards import TF_MESSAGE_TYPE, ContentGuard
from bridge.core.dispatch import Created, Handler, made_bridge
from bridge.core.hub import Hub, Replier
from bridge.core.logging_limits import RateLimitedLog
from bridge.core.outbox import Frame, TemplateFrame
from bridge.tf.buffer import MAX_FRAMES, StampedTransform, TfBuffer
from bridge.tf.errors import (
    ConnectivityError,
    ExtrapolationError,
    RejectedTransformsError,
    TfError,
    TfLookupError,
)
from bridge.tf.lookups import LookupKey, LookupRegistry, LookupResult
from protocol.commands import (
    BroadcastTransform,
    BroadcastTransformResult,
    CommandFailedError,
    CreateTfBroadcaster,
    DISPLAY_HZ,
    DISPLAY_HZ_MIN,
    CreateTfLookup,
    ErrorCode,
    LookupTransform,
    LookupTransformResult,
    Op,
    OutOfRangeError,
    RemoveTfBroadcaster,
    RemoveTfLookup,
    Stamp,
    TfBridgeRemoved,
    TfBroadcasterBridge,
    TfLookupBridge,
    matrix_rows,
)
from protocol.conversions import (
    ConversionError,
    igtl_stamp_or_now,
    igtl12_to_matrix,
    igtl_timestamp_now,
    pose_to_igtl12,
    validate_matrix,
)
from protocol.framing import StreamTemplate
from protocol.messages import (Message, Status, StatusCode, TrackingData, TrackingElement,
                               Transform)
from protocol.naming import UNITS_MM, DeviceNameRegistry, NameKey, metadata_for

if TYPE_CHECKING:  # ROS is imported where the daemon subscribes and publishes: `TfLookups`
    # serves a bag without it (bridge/playback)
    from bridge.ros.ros_node import RosNode

__all__ = ["TfBridges", "TfLookups", "status_for_error", "tf_cdr_to_transforms",
           "tf_message_to_transforms"]

log = logging.getLogger(__name__)

_NS_PER_S = 1_000_000_000
# When a pose group's message that named new elements goes again (`TfLookups._send_again`).
_SEND_AGAIN_AFTER_S = (2.0 / DISPLAY_HZ, 1.5 / DISPLAY_HZ_MIN)



# ---------------------------------------------------------------------------- conversions


def tf_message_to_transforms(msg: Any) -> list[StampedTransform]:
    """A tf2_msgs/TFMessage -> `StampedTransform`s (metres, as ROS sends them).

    No validation here: `TfBuffer.set_transforms` judges each transform and says why it
    refused one, and it must see the whole batch at once.
    """
    out = []
    for t in msg.transforms:
        stamp = t.header.stamp
        tr = t.transform.translation
        q = t.transform.rotation
        out.append(StampedTransform(t.header.frame_id, t.child_frame_id,
                                    stamp.sec * _NS_PER_S + stamp.nanosec,
                                    (tr.x, tr.y, tr.z), (q.x, q.y, q.z, q.w)))
    return out


def tf_cdr_to_transforms(data: bytes, decode: Optional[Callable[[bytes], Any]] = None,
                         ) -> list[StampedTransform]:
    """A serialized TFMessage -> `StampedTransform`s, read without rclpy messages (the same
    values as `tf_message_to_transforms` of the deserialized message). Bytes of a CDR
    encoding the reader does not take are deserialized the ordinary way: by ``decode``
    (a bag's decoder, from its schema) or else by rclpy."""
    try:
        raw = read_tf_message(data)
    except CdrError:  # another CDR encoding: the ordinary way
        if decode is not None:
            return tf_message_to_transforms(decode(data))
        from rclpy.serialization import deserialize_message
        from tf2_msgs.msg import TFMessage

        return tf_message_to_transforms(deserialize_message(data, TFMessage))
    return [StampedTransform(frame, child, sec * _NS_PER_S + nanosec, (tx, ty, tz),
                             (x, y, z, w))
            for sec, nanosec, frame, child, tx, ty, tz, x, y, z, w in raw]


def _transform_stamped(st: StampedTransform) -> Any:
    from geometry_msgs.msg import TransformStamped

    msg = TransformStamped()
    sec, nanosec = divmod(st.stamp_ns, _NS_PER_S)
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = nanosec
    msg.header.frame_id = st.parent
    msg.child_frame_id = st.child
    tr = msg.transform.translation
    tr.x, tr.y, tr.z = st.translation
    q = msg.transform.rotation
    q.x, q.y, q.z, q.w = st.rotation
    return msg



def _stamp_ns(stamp: Optional[Stamp]) -> int:
    return 0 if stamp is None else stamp.sec * _NS_PER_S + stamp.nanosec


def _igtl_timestamp(stamp_ns: int) -> int:
    # A chain of static links has stamp 0 (valid at every time); OpenIGTLink's 0 means
    # "unset", so such a result carries the time the daemon computed it instead.
    if stamp_ns <= 0:
        return igtl_timestamp_now()
    global _last_stamp
    last = _last_stamp  # one read: another thread may replace it meanwhile
    if stamp_ns == last[0]:  # the lookups of one /tf message share their stamp
        return last[1]
    timestamp = igtl_stamp_or_now(*divmod(stamp_ns, _NS_PER_S))
    _last_stamp = (stamp_ns, timestamp)
    return timestamp


_last_stamp = (-1, 0)  # (stamp_ns, its IGTL time stamp): this pure function's last answer


# OpenIGTLink STATUS for a lookup that fails: the code says what a client can expect
# (NOT_READY: data may still come; NOT_FOUND: the frames are not connected), SUB_CODE is the
# tf2_msgs/TF2Error value, ERROR_NAME its name, the text tf2's own wording.
_STATUS_OF_ERROR: dict[type[TfError], StatusCode] = {
    ExtrapolationError: StatusCode.NOT_READY,
    ConnectivityError: StatusCode.NOT_FOUND,
    TfLookupError: StatusCode.CONFIG_ERROR,  # a loop in the tree (unknown frames are pending)
}


def status_for_error(error: TfError) -> Status:
    """The STATUS body that tells clients why a streamed lookup has no value now."""
    code = _STATUS_OF_ERROR.get(type(error), StatusCode.UNKNOWN_ERROR)
    name = error.code.name
    if len(name) > 19:  # ERROR_NAME holds 19 bytes (see protocol.messages.Status)
        name = name.removesuffix("_ERROR")[:19]
    return Status(code=code, subcode=int(error.code), error_name=name, text=error.message)


def _field_of(error: TfError, time_ns: int) -> str:
    """The request field a tf2 error is about, for error replies."""
    if isinstance(error, TfLookupError) and error.frame is not None:
        return "parent" if "target_frame" in error.message else "child"
    if isinstance(error, ExtrapolationError) and time_ns != 0:
        return "time"
    return "child"


# ---------------------------------------------------------------------------- bridges


@dataclass
class _Lookup:
    key: LookupKey  # the registry's key: the resolved frames
    device: str
    metadata: dict[str, str]
    requested: tuple[str, str]  # the frames as the client named them
    rate_hz: Optional[float]
    group: Optional[str] = None  # the pose group it is an element of (device), if any
    messages: int = 0
    # The constant part of its TRANSFORMs: a result costs two struct packs and a CRC, not
    # a Message and a full encode (a 7-link robot at 1 kHz is 7,000 of them a second).
    template: Optional[StreamTemplate] = None

    def __post_init__(self) -> None:
        self.template = StreamTemplate("TRANSFORM", self.device, self.metadata)

    def frame_of(self, result: StampedTransform) -> Optional[TemplateFrame]:
        """The result as a frame, or None if a number is not finite as float32 once in mm
        (the checked path says why)."""
        values = pose_to_igtl12(*result.translation, *result.rotation)
        if values is None or self.template is None:
            return None
        return TemplateFrame(self.template, pack_transform(values),
                             _igtl_timestamp(result.stamp_ns), values, transform_body)


@dataclass
class _PoseGroup:
    """Lookups sent together as one TDATA on `device`: each lookup an element named by its
    own device, every element placed now in each message (one that tf cannot place is left
    out, as the spec says of a tool out of view), so the newest message is the whole state.
    A robot's links: 3D Slicer's connector updates all its link nodes from one message."""

    device: str
    metadata: dict[str, str]
    # element -> (matrix in mm, stamp ns)
    poses: dict[str, tuple[npt.NDArray[np.float64], int]] = field(default_factory=dict)
    sent: frozenset[str] = frozenset()  # the element names of the last message

    def names_new_elements(self) -> bool:
        """Does the message now name an element the last one did not (then noted as sent)?"""
        names = frozenset(self.poses)
        new, self.sent = not names <= self.sent, names
        return new

    def message(self) -> Message:
        stamps = [stamp for _, stamp in self.poses.values()]
        return Message(device_name=self.device, body=TrackingData(
            [TrackingElement(name, matrix) for name, (matrix, _) in self.poses.items()]),
            timestamp=_igtl_timestamp(max(stamps)) if stamps else igtl_timestamp_now(),
            metadata=self.metadata)


@dataclass
class _Broadcaster:
    parent: str
    child: str
    static: bool
    device: str
    topic: str
    messages: int = 0


class TfLookups:
    """Lookups of the tf buffer, streamed (``create_tf_lookup``, and `stream_lookup` for
    robots) and one-shot (``lookup_transform``): what serves tf to clients, whoever fills
    the buffer (`store_transforms`, from any thread). Without ROS: the daemon's `TfBridges`
    feeds it from /tf, the player (bridge/playback) from a bag.

    Keyword options: ``frame_prefix`` (see the module docstring), ``cache_time_s`` (how much
    history the buffer keeps per frame, tf2's default 10 s), ``tf_topic`` and
    ``tf_static_topic`` (resolved: the names its state and warnings give).
    """

    def __init__(self, hub: Hub, names: DeviceNameRegistry, *,
                 frame_prefix: str = "", cache_time_s: float = 10.0,
                 tf_topic: str = "/tf", tf_static_topic: str = "/tf_static",
                 compiled_store: Optional[bool] = None) -> None:
        """``compiled_store``: `TfBuffer`'s ``compiled`` (None: the compiled one where built)."""
        self._hub = hub
        self._names = names
        self._prefix = frame_prefix.lstrip("/")
        self.buffer = TfBuffer(cache_time_s, compiled=compiled_store)
        self.registry = LookupRegistry(self.buffer)
        self.lookups: dict[tuple[str, str], _Lookup] = {}
        self._by_key: dict[LookupKey, _Lookup] = {}
        self._groups: dict[str, _PoseGroup] = {}
        self._tf_topic = tf_topic
        self._tf_static_topic = tf_static_topic
        # Evaluation + writing of lookups, from either thread (see the module docstring).
        self._deliver_lock = threading.Lock()
        # Streams thread -> loop: at most one call scheduled at a time.
        self._lock = threading.Lock()
        self._loop_call_scheduled = False
        self._refusals = RateLimitedLog(log)
        self._forgotten = 0  # the buffer's `forgotten` count as last logged
        # Loop-thread state.
        self._timer: Optional[asyncio.TimerHandle] = None
        self._timer_due_ns: Optional[int] = None
        self._changed_event: Optional[asyncio.Event] = None
        self._closed = False
        self.received = {"tf": 0, "tf_static": 0}
        self.updates = 0  # tf batches that changed a frame some lookup follows or waits for

    def store_transforms(self, transforms: list[StampedTransform], *, static: bool) -> None:
        """Store one batch (metres) and deliver the lookups it changed (any thread)."""
        self._store(transforms, static=static)

    def reset(self, static: list[StampedTransform], moving: list[StampedTransform]) -> None:
        """Forget every frame and hold these instead (a player's seek: its time jumps), in
        one step: no lookup is evaluated on a buffer half filled."""
        changed: set[str] = set()
        with self._deliver_lock:
            self.buffer.clear()
            for batch, is_static in ((static, True), (moving, False)):
                try:
                    changed |= self.buffer.set_transforms(batch, static=is_static)
                except RejectedTransformsError as error:
                    self._warn_rejected(error, is_static)
                    changed |= error.changed
        self._deliver(changed)

    # ------------------------------------------------------------------ ROS thread

    def _store_cdr(self, data: Union[bytes, memoryview], *, static: bool) -> None:
        """Store one serialized TFMessage (rclpy's bytes, or the raw reader's view, valid
        during the call): read and stored in one call by the compiled store, else read here
        and stored as `StampedTransform`s."""
        try:
            changed = self.buffer.set_transforms_cdr(data, static=static)
        except RejectedTransformsError as error:
            self._warn_rejected(error, static)
            changed = error.changed
        if changed is None:
            self._store(tf_cdr_to_transforms(bytes(data)), static=static)
        else:
            self._deliver(changed)

    def _store(self, transforms: list[StampedTransform], *, static: bool) -> None:
        """Store one batch and deliver the lookups it changed (any thread)."""
        try:
            changed = self.buffer.set_transforms(transforms, static=static)
        except RejectedTransformsError as error:
            self._warn_rejected(error, static)
            changed = error.changed
        self._deliver(changed)

    def _deliver(self, changed: set[str]) -> None:
        forgotten = self.buffer.forgotten
        if forgotten != self._forgotten:
            self._refusals.warning(
                "tf-forgotten", None, "the tf buffer was full (%d frames): forgot %d frame(s), "
                "those received least recently, to make room for new ones",
                MAX_FRAMES, forgotten - self._forgotten, count=forgotten - self._forgotten)
            self._forgotten = forgotten
        if not changed:
            return
        with self._deliver_lock:
            if self._closed:
                return
            self._post(self.registry.updates(changed, time.monotonic_ns()))
            due = self.registry.next_due_ns()
        armed = self._timer_due_ns
        if self._changed_event is not None or (due is not None and (armed is None
                                                                    or due < armed)):
            self._call_loop()

    def _warn_rejected(self, error: RejectedTransformsError, static: bool) -> None:
        topic = self._tf_static_topic if static else self._tf_topic
        self._refusals.warning(topic, None, "refused %d transform(s) from %s: %s",
                               error.count, topic, error, count=error.count)

    def _call_loop(self) -> None:
        with self._lock:
            if self._loop_call_scheduled:
                return
            self._loop_call_scheduled = True
        self._hub.call_soon(self._on_change)

    # ------------------------------------------------------------------ loop thread

    def _on_change(self) -> None:
        with self._lock:
            self._loop_call_scheduled = False
        if self._closed:
            return
        event, self._changed_event = self._changed_event, None
        if event is not None:
            event.set()  # one-shot lookups that wait for data try again
        self._arm()

    def _on_timer(self) -> None:
        self._timer = None
        self._timer_due_ns = None
        if self._closed:
            return
        with self._deliver_lock:
            if self._closed:
                return
            self._post(self.registry.due(time.monotonic_ns()))
        self._arm()

    def _arm(self) -> None:
        """Wake up when the registry has something due (a rate cap ran out, a new lookup)."""
        due = self.registry.next_due_ns()
        if due is None:
            return
        if self._timer is not None:
            if self._timer_due_ns is not None and self._timer_due_ns <= due:
                return  # an earlier wake-up is already set; it re-arms after running
            self._timer.cancel()
        delay = max(0, due - time.monotonic_ns()) / _NS_PER_S
        loop = asyncio.get_running_loop()
        self._timer = loop.call_later(delay, self._on_timer)
        self._timer_due_ns = due

    # ------------------------------------------------------------------ delivery (locked)

    def _post(self, results: list[tuple[LookupKey, LookupResult]]) -> None:
        """Results -> frames -> every client, one write each (under the delivery lock)."""
        frames = self._frames_of(results)
        if frames:
            self.updates += 1
            self._hub.post_frames(frames)

    def _frames_of(self, results: list[tuple[LookupKey, LookupResult]],
                   ) -> list[tuple[str, Frame]]:
        frames: list[tuple[str, Frame]] = []
        moved: dict[str, _PoseGroup] = {}
        for key, result in results:
            lookup = self._by_key.get(key)
            if lookup is None:
                continue
            lookup.messages += 1
            group = self._groups.get(lookup.group) if lookup.group is not None else None
            if group is not None:
                self._place(group, lookup, result)
                moved[group.device] = group
                continue
            if isinstance(result, StampedTransform):
                frame = lookup.frame_of(result)
                if frame is not None:
                    frames.append((lookup.device, frame))
                    continue
                try:
                    body: Union[Transform, Status] = Transform(matrix=result.matrix_mm())
                except ConversionError as error:  # finite links can compose beyond float32
                    self._refusals.warning(lookup.device, None, "lookup %s <- %s (device %r)"
                                           " not sent: %s", *lookup.requested, lookup.device,
                                           error)
                    continue
                timestamp = _igtl_timestamp(result.stamp_ns)
            else:
                body = status_for_error(result)
                timestamp = igtl_timestamp_now()
            frames.append((lookup.device, Frame(Message(
                device_name=lookup.device, body=body, timestamp=timestamp,
                metadata=lookup.metadata))))
        for device, group in moved.items():
            frames.append((device, Frame(group.message())))
            if group.names_new_elements():
                self._hub.call_soon(self._send_again, device)
        return frames

    def _send_again(self, device: str) -> None:
        """3D Slicer's connector makes the node of an element new to a bundle it has at the
        identity, not at the element's pose (vtkMRMLIGTLConnectorNode.cxx, SlicerOpenIGTLink
        d090ca4: its new-element branch passes a fresh matrix); the next message places it.
        A robot at rest sends none, so a group's message that named new elements goes again:
        two display frames later, and once more after the slowest display's frame (a paced
        client takes only the newest message of a frame)."""
        loop = asyncio.get_running_loop()
        for delay in _SEND_AGAIN_AFTER_S:
            loop.call_later(delay, self._post_group, device)

    def _post_group(self, device: str) -> None:
        with self._deliver_lock:
            group = self._groups.get(device)
            if group is not None and not self._closed:
                self._hub.post_frames([(device, Frame(group.message()))])

    def _place(self, group: _PoseGroup, lookup: _Lookup, result: LookupResult) -> None:
        """A group element's new result: its pose, or out of the group while tf cannot
        place it (or its pose is beyond float32 in mm: said, as for a lookup's TRANSFORM)."""
        values = None
        if isinstance(result, StampedTransform):
            values = pose_to_igtl12(*result.translation, *result.rotation)
            if values is not None:
                group.poses[lookup.device] = (igtl12_to_matrix(values), result.stamp_ns)
                return
            self._refusals.warning(lookup.device, None, "lookup %s <- %s (element %r of %r) "
                                   "not sent: not finite as float32 in mm",
                                   *lookup.requested, lookup.device, group.device)
        group.poses.pop(lookup.device, None)

    # ------------------------------------------------------------------ frames

    def resolve_frame(self, frame: str) -> str:
        """A client's frame id -> the buffer's (``frame_prefix`` applied, see the module)."""
        if frame.startswith("/"):
            return frame.lstrip("/")
        return self._prefix + frame

    @property
    def topics(self) -> tuple[str, str]:
        """The tf and tf_static topics the buffer reads (fully qualified)."""
        return self._tf_topic, self._tf_static_topic

    def recorded_topics(self) -> dict[str, Optional[str]]:
        """What a recording takes from tf: the topics the buffer reads."""
        return {topic: TF_MESSAGE_TYPE for topic in self.topics}

    def resolve_client_frame(self, frame: str, field: str) -> str:
        """A request's frame id (`Op.client_frames`) -> the buffer's; the dispatcher maps
        each request's frames once with it. An id that maps to nothing is refused."""
        resolved = self.resolve_frame(frame)
        if not resolved:
            raise OutOfRangeError(field, "a non-empty frame id", repr(frame))
        return resolved

    # ------------------------------------------------------------------ lookups

    def stream_lookup(self, parent: str, child: str, *, device: str,
                      metadata: dict[str, str], rate_hz: Optional[float] = None,
                      group: Optional[str] = None) -> LookupKey:
        """Stream parent <- child on ``device`` with ``metadata`` for another capability
        (robots): the same change-driven evaluation and delivery as `create_lookup`, but
        the caller owns the device name (and forgets it). Frames are taken as given (no
        ``frame_prefix``). With ``group`` (an `open_pose_group` device) it is an element
        of that group's TDATA, named ``device``, instead of a TRANSFORM of its own.
        Returns the handle for `stop_lookup`."""
        tag = f"device:{device}"  # one registration per device, beside clients' lookups
        with self._deliver_lock:  # the streams thread must not evaluate it unregistered
            key = self.registry.add(parent, child, rate_hz=rate_hz, tag=tag)
            self._by_key[key] = _Lookup(key, device, dict(metadata), (parent, child), rate_hz,
                                        group)
        self._arm()
        return key

    def stop_lookup(self, handle: LookupKey) -> None:
        """Stop a `stream_lookup` (its device is the caller's to forget)."""
        with self._deliver_lock:  # after this, nothing more is written to its device
            lookup = self._by_key.pop(handle, None)
            if lookup is not None:
                self.registry.remove(handle)
                group = self._groups.get(lookup.group) if lookup.group is not None else None
                if group is not None:
                    group.poses.pop(lookup.device, None)

    def open_pose_group(self, device: str, metadata: dict[str, str]) -> None:
        """Lookups streamed with ``group=device`` go as one TDATA on ``device`` (the
        caller's device name, to forget with `close_pose_group`). Opening it again
        changes its metadata."""
        with self._deliver_lock:
            group = self._groups.setdefault(device, _PoseGroup(device, dict(metadata)))
            group.metadata = dict(metadata)

    def close_pose_group(self, device: str) -> None:
        with self._deliver_lock:
            self._groups.pop(device, None)

    def create_lookup(self, request: CreateTfLookup) -> Created[TfLookupBridge]:
        pair = (request.parent, request.child)  # mapped by the dispatcher
        existing = self.lookups.get(pair)
        if existing is not None:
            # Idempotent (a reconnecting client re-creates what it had); the cap may change.
            self.registry.add(pair[0], pair[1], rate_hz=request.rate_hz)
            existing.rate_hz = request.rate_hz
            self._arm()
            return Created(self._describe_lookup(existing), existed=True)
        name_key = NameKey.tf_lookup(*pair)
        device = self._names.register(name_key)
        self._hub.bridge_device(made_bridge(request), device)
        with self._deliver_lock:  # the streams thread must not evaluate it unregistered
            key = self.registry.add(pair[0], pair[1], rate_hz=request.rate_hz)
            lookup = _Lookup(key, device, metadata_for(name_key, frame=pair[0],
                                                       units=UNITS_MM),
                             (request.parent, request.child), request.rate_hz)
            self.lookups[pair] = lookup
            self._by_key[key] = lookup
        self._arm()  # the first result comes from registry.due, on the next loop turn
        log.info("tf lookup %s -> %s streams as device %r", pair[0], pair[1], device)
        return Created(self._describe_lookup(lookup), existed=False)

    def remove_lookup(self, request: RemoveTfLookup) -> TfBridgeRemoved:
        pair = (request.parent, request.child)  # mapped by the dispatcher
        lookup = self.lookups.pop(pair, None)
        if lookup is None:
            raise CommandFailedError("child", "a lookup created by create_tf_lookup",
                                     f"{pair[0]} -> {pair[1]}", code=ErrorCode.NOT_FOUND)
        with self._deliver_lock:  # after this, nothing more is written to its device
            del self._by_key[lookup.key]
            self.registry.remove(lookup.key)
        self._hub.forget(lookup.device)
        self._names.release(NameKey.tf_lookup(*pair))
        return TfBridgeRemoved(pair[0], pair[1], lookup.device)

    def lookup_transform(self, request: LookupTransform,
                         ) -> Union[LookupTransformResult, Awaitable[LookupTransformResult]]:
        """One lookup; with ``timeout`` it waits (without blocking the loop) for tf data."""
        pair = (request.parent, request.child)  # mapped by the dispatcher
        time_ns = _stamp_ns(request.time)
        try:
            return self._lookup_once(pair, time_ns)
        except TfError as error:
            if request.timeout <= 0:
                raise _unavailable(pair, time_ns, error) from None
        return self._lookup_waiting(pair, time_ns, request.timeout)

    def _lookup_once(self, pair: tuple[str, str], time_ns: int) -> LookupTransformResult:
        result = self.buffer.lookup(pair[0], pair[1], time_ns)
        try:
            matrix: npt.NDArray[np.float64] = result.matrix_mm()
        except ConversionError as error:  # JSON and TRANSFORM would both hold infinity
            raise CommandFailedError(
                "child", f"a transform {pair[0]} <- {pair[1]} whose numbers fit float32 in mm",
                f"{error}", code=ErrorCode.NOT_SUPPORTED) from None
        return LookupTransformResult(pair[0], pair[1], matrix_rows(matrix),
                                     tuple(result.translation), tuple(result.rotation),
                                     Stamp.from_ns(result.stamp_ns))

    async def _lookup_waiting(self, pair: tuple[str, str], time_ns: int,
                              timeout: float) -> LookupTransformResult:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while True:
            # Take the event before trying: data landing after the try still wakes us.
            if self._changed_event is None:
                self._changed_event = asyncio.Event()
            event = self._changed_event
            try:
                return self._lookup_once(pair, time_ns)
            except TfError as error:
                remaining = deadline - loop.time()
                if remaining <= 0:
                    raise _unavailable(pair, time_ns, error, waited=timeout) from None
            try:
                await asyncio.wait_for(event.wait(), remaining)
            except asyncio.TimeoutError:
                pass

    # ------------------------------------------------------------------ capability

    def handlers(self) -> dict[type[Op], Handler]:
        return {
            CreateTfLookup: lambda request, _: self.create_lookup(request),
            RemoveTfLookup: lambda request, _: self.remove_lookup(request),
            LookupTransform: lambda request, _: self.lookup_transform(request),
        }

    def describe(self) -> list[dict[str, Any]]:
        return [self._describe_lookup(lookup).to_dict() for lookup in self.lookups.values()]

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        """The shared tf buffer (not a bridge: every lookup reads it), naming only the
        frames ``guard`` lets a client see."""
        return {"tf_buffer": {
            "topics": list(self.topics), "frame_prefix": self._prefix,
            "frames": guard.visible_frames(self.buffer.frames()),
            "received": dict(self.received), "cache_time_s": self.buffer.cache_time_s}}

    def _describe_lookup(self, lookup: _Lookup) -> TfLookupBridge:
        last = self.registry.last_sent(lookup.key)
        if isinstance(last, StampedTransform):
            state = "streaming"
        elif isinstance(last, TfError):
            state = "error"
        else:
            state = "pending"  # no result yet: a frame is unknown, or not evaluated yet
        return TfLookupBridge("tf_lookup", lookup.key.parent, lookup.key.child, lookup.device,
                              Transform.TYPE, state, lookup.messages,
                              error=last.message if isinstance(last, TfError) else None,
                              rate_hz=lookup.rate_hz or None)

    def close(self) -> None:
        with self._deliver_lock:  # a delivery under way ends before the devices are forgotten
            self._closed = True
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        for lookup in self.lookups.values():
            self._hub.forget(lookup.device)
        self.lookups.clear()
        self._by_key.clear()


class TfBridges(TfLookups):
    """The tf capability of the daemon: `TfLookups` fed from /tf and /tf_static, and
    broadcasters publishing clients' transforms.

    Keyword options: as `TfLookups`; ``tf_topic`` and ``tf_static_topic`` may be relative
    (resolved in the node's namespace).
    """

    def __init__(self, ros: RosNode, hub: Hub, names: DeviceNameRegistry, *,
                 frame_prefix: str = "", cache_time_s: float = 10.0,
                 tf_topic: str = "/tf", tf_static_topic: str = "/tf_static",
                 compiled_store: Optional[bool] = None) -> None:
        from tf2_msgs.msg import TFMessage

        from bridge.ros.qos import TF_QOS, TF_STATIC_SUBSCRIBER_QOS
        from bridge.ros.raw_reader import RawTopic

        super().__init__(hub, names, frame_prefix=frame_prefix, cache_time_s=cache_time_s,
                         tf_topic=ros.resolve_topic(tf_topic),
                         tf_static_topic=ros.resolve_topic(tf_static_topic),
                         compiled_store=compiled_store)
        self._ros = ros
        self.broadcasters: dict[tuple[str, str], _Broadcaster] = {}
        self._by_device: dict[str, _Broadcaster] = {}
        # Publishers are made on first use, so a daemon that never broadcasts does not show
        # up as a /tf publisher in the ROS graph.
        self._tf_publisher: Any = None
        self._static_publisher: Any = None
        self._static_transforms: dict[str, Any] = {}  # child -> TransformStamped (latched)
        # The EventsExecutor's node, taken raw: /tf may come at kHz rates, and rclpy builds
        # six Python objects per transform (most of the daemon's CPU in a 1 kHz robot).
        # Where the compiled rcl reader is built, /tf is taken without the interpreter's
        # lock (rclpy held it about 20 ms for a peer's 10 MB TFMessage, stalling every
        # client's stream): bridge/ros/raw_reader.py.
        self._reader = ros.raw_reader([
            RawTopic(self._tf_topic, TFMessage, TF_QOS, self._on_tf),
            RawTopic(self._tf_static_topic, TFMessage, TF_STATIC_SUBSCRIBER_QOS,
                     self._on_tf_static)], name="tf-reader")
        node = ros.stream_node
        self._subscriptions = [] if self._reader is not None else [
            node.create_subscription(TFMessage, self._tf_topic, self._on_tf, TF_QOS, raw=True),
            node.create_subscription(TFMessage, self._tf_static_topic, self._on_tf_static,
                                     TF_STATIC_SUBSCRIBER_QOS, raw=True),
        ]

    def store_in_use(self) -> str:
        """Which store the buffer runs on, and how /tf is taken, for the start-up log."""
        taken = ("; /tf taken without the interpreter's lock (rcl reader)" if self._reader
                 is not None else "; /tf taken through rclpy (the rcl reader is not built here)")
        if self.buffer.compiled:
            return "compiled store" + taken
        return ("pure Python store (the compiled one is not built here, is from an older "
                "build, or --tf-store python)" + taken)


    # ------------------------------------------------------------------ ROS thread

    def _on_tf(self, data: Union[bytes, memoryview]) -> None:
        self.received["tf"] += 1
        self._store_cdr(data, static=False)

    def _on_tf_static(self, data: Union[bytes, memoryview]) -> None:
        self.received["tf_static"] += 1
        self._store_cdr(data, static=True)

    # ------------------------------------------------------------------ broadcasters

    def create_broadcaster(self, request: CreateTfBroadcaster,
                           ) -> Created[TfBroadcasterBridge]:
        pair = (request.parent, request.child)  # mapped by the dispatcher
        if pair[0] == pair[1]:
            raise OutOfRangeError("child", "a frame other than the parent", repr(request.child))
        existing = self.broadcasters.get(pair)
        if existing is not None:
            if existing.static != request.static:
                raise CommandFailedError(
                    "static", f"{str(existing.static).lower()} (the broadcaster {pair[0]} -> "
                    f"{pair[1]} has it; remove it first)", str(request.static).lower(),
                    code=ErrorCode.ALREADY_EXISTS)
            return Created(self._describe_broadcaster(existing), existed=True)
        name_key = NameKey.tf_broadcaster(*pair)
        device = self._names.register(name_key)
        broadcaster = _Broadcaster(pair[0], pair[1], request.static, device,
                                   self._tf_static_topic if request.static else self._tf_topic)
        self._publisher(request.static)  # create it now: discovery starts before the 1st send
        self.broadcasters[pair] = broadcaster
        self._by_device[device] = broadcaster
        self._hub.route(device, self._on_igtl)
        log.info("tf broadcaster %s -> %s (%s); clients send TRANSFORM to device %r",
                 pair[0], pair[1], broadcaster.topic, device)
        return Created(self._describe_broadcaster(broadcaster), existed=False)

    def remove_broadcaster(self, request: RemoveTfBroadcaster) -> TfBridgeRemoved:
        from tf2_msgs.msg import TFMessage

        pair = (request.parent, request.child)  # mapped by the dispatcher
        broadcaster = self.broadcasters.pop(pair, None)
        if broadcaster is None:
            raise CommandFailedError("child", "a broadcaster created by create_tf_broadcaster",
                                     f"{pair[0]} -> {pair[1]}", code=ErrorCode.NOT_FOUND)
        self._hub.unroute(broadcaster.device)
        del self._by_device[broadcaster.device]
        self._names.release(NameKey.tf_broadcaster(*pair))
        if broadcaster.static and self._static_transforms.pop(pair[1], None) is not None:
            # Later subscribers no longer get it; tf2 keeps static data forever, so current
            # ones keep it (there is no "delete" in tf2).
            self._static_publisher.publish(
                TFMessage(transforms=list(self._static_transforms.values())))
        return TfBridgeRemoved(pair[0], pair[1], broadcaster.device)

    def broadcast(self, request: BroadcastTransform) -> BroadcastTransformResult:
        pair = (request.parent, request.child)  # mapped by the dispatcher
        broadcaster = self.broadcasters.get(pair)
        if broadcaster is None:
            raise CommandFailedError("child", "a broadcaster (create_tf_broadcaster first)",
                                     f"{pair[0]} -> {pair[1]}", code=ErrorCode.NOT_FOUND)
        # The schema already validated the matrix (field "matrix[i][j]" / "matrix rotation").
        stamp_ns = _stamp_ns(request.stamp) or self._now_ns()
        subscribers = self._send(broadcaster, np.asarray(request.matrix, dtype=np.float64),
                                 stamp_ns)
        return BroadcastTransformResult(broadcaster.topic, Stamp.from_ns(stamp_ns), subscribers)

    def _on_igtl(self, message: Message, client: Replier) -> None:
        """A client sent a message to a broadcaster's device (loop thread)."""
        broadcaster = self._by_device.get(message.device_name)
        if broadcaster is None:  # removed while the message was on its way
            return
        body = message.body
        try:
            if not isinstance(body, Transform):
                raise ConversionError("message", "a TRANSFORM (4x4 matrix in mm)",
                                      message.type_name)
            matrix = validate_matrix(body.matrix, field="TRANSFORM matrix")
        except ConversionError as error:
            log.warning("refused %s for the tf broadcaster %s -> %s from a client: %s",
                        message.type_name, broadcaster.parent, broadcaster.child, error)
            client.send_status(message.device_name, StatusCode.CONFIG_ERROR,
                               f"not broadcast on {broadcaster.topic}: {error}")
            return
        self._send(broadcaster, matrix, self._now_ns())

    def _send(self, broadcaster: _Broadcaster, matrix_mm: npt.NDArray[np.float64],
              stamp_ns: int) -> int:
        from tf2_msgs.msg import TFMessage

        static = broadcaster.static
        # The stamp goes out even for a static transform (tf2 ignores it there, but a
        # stamp of 0 tells a reader nothing); the buffer ignores it for static data too.
        st = StampedTransform.from_matrix_mm(broadcaster.parent, broadcaster.child, stamp_ns,
                                             matrix_mm)
        msg = _transform_stamped(st)
        if static:
            # One latched message with every static transform of the daemon, as tf2_ros's
            # StaticTransformBroadcaster keeps: a late subscriber gets all of them.
            self._static_transforms[broadcaster.child] = msg
            tf_message = TFMessage(transforms=list(self._static_transforms.values()))
        else:
            tf_message = TFMessage(transforms=[msg])
        publisher = self._publisher(static)
        publisher.publish(tf_message)
        broadcaster.messages += 1
        # Read-your-writes: the daemon also hears its own /tf, but a lookup right after a
        # broadcast must already see it (the echo then changes nothing: same stamp, value).
        self._store([st], static=static)
        return int(publisher.get_subscription_count())

    def _publisher(self, static: bool) -> Any:
        from tf2_msgs.msg import TFMessage

        from bridge.ros.qos import LATCHED_QOS, TF_QOS

        node = self._ros.node
        if static:
            if self._static_publisher is None:
                self._static_publisher = node.create_publisher(
                    TFMessage, self._tf_static_topic, LATCHED_QOS)
            return self._static_publisher
        if self._tf_publisher is None:
            self._tf_publisher = node.create_publisher(TFMessage, self._tf_topic, TF_QOS)
        return self._tf_publisher

    def _now_ns(self) -> int:
        """The node clock's now (ROS time; sim time if the node uses it)."""
        return int(self._ros.node.get_clock().now().nanoseconds)

    # ------------------------------------------------------------------ capability

    def handlers(self) -> dict[type[Op], Handler]:
        return {
            **super().handlers(),
            CreateTfBroadcaster: lambda request, _: self.create_broadcaster(request),
            RemoveTfBroadcaster: lambda request, _: self.remove_broadcaster(request),
            BroadcastTransform: lambda request, _: self.broadcast(request),
        }

    def describe(self) -> list[dict[str, Any]]:
        out = super().describe()
        out.extend(self._describe_broadcaster(b).to_dict() for b in self.broadcasters.values())
        return out

    def _describe_broadcaster(self, broadcaster: _Broadcaster) -> TfBroadcasterBridge:
        return TfBroadcasterBridge("tf_broadcaster", broadcaster.parent, broadcaster.child,
                                   broadcaster.device, Transform.TYPE, broadcaster.static,
                                   broadcaster.topic, broadcaster.messages)

    def close(self) -> None:
        super().close()
        for broadcaster in self.broadcasters.values():
            self._hub.unroute(broadcaster.device)
        self.broadcasters.clear()
        self._by_device.clear()
        if self._reader is not None:
            self._reader.close()
        for subscription in self._subscriptions:
            self._ros.destroy(subscription)
        self._subscriptions = []
        for publisher in (self._tf_publisher, self._static_publisher):
            if publisher is not None:
                self._ros.destroy(publisher)
        self._tf_publisher = self._static_publisher = None


def _unavailable(pair: tuple[str, str], time_ns: int, error: TfError,
                 waited: float = 0.0) -> CommandFailedError:
    """The error reply of a failed one-shot lookup: tf2's words and its TF2Error code."""
    when = "the latest common time" if time_ns == 0 else \
        f"time {time_ns // _NS_PER_S}.{time_ns % _NS_PER_S:09d}"
    after = f" (after waiting {waited:g} s)" if waited else ""
    return CommandFailedError(
        _field_of(error, time_ns), f"a transform {pair[0]} <- {pair[1]} at {when}",
        f"TF2Error {int(error.code)} {error.code.name}: {error.message}{after}",
        code=ErrorCode.TRANSFORM_UNAVAILABLE)
