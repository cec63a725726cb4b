"""Topic bridges: a ROS subscription streamed to clients, and clients' data published to ROS.

`SubscriberBridge` (ROS -> Slicer): its callback runs in the ROS executor thread and only
converts the message and hands it to the hub; it also keeps the last message for
`get_last_message` (the reference's GetLastMessage / GetLastMessageYAML).

`PublisherBridge` (Slicer -> ROS): messages clients send to its device, or `publish`
commands with a JSON value, become ROS messages. Publishing returns the number of ROS
subscribers, as the reference's Publish does.
"""

from __future__ import annotations

import asyncio
import json
import logging
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Optional, cast

from rclpy.serialization import deserialize_message
from std_msgs.msg import String as StringMsg

from bridge.codecs import CodecError, TypeCodec, codec_for, message_to_json
from bridge.codecs.base import Encoded, stream_message
from bridge.codecs.fast import (NotFast, RawPoseStream, pose_document,
                                read_raw_pose, transform_body)
from bridge.codecs.generic import document_to_json
from bridge.codecs.fast_image import RawImageStream
from bridge.codecs.generic import dict_to_message
from bridge.codecs.slicer_data import markup_labels
from bridge.core.dispatch import Created, Handler, made_bridge
from bridge.core.heavy import OffLoop
from bridge.core.hub import (Hub, Replier, Subscriber, frame_for,
                             is_large)
from bridge.core.logging_limits import RateLimitedLog
from bridge.core.content_guards import ContentGuard
from bridge.core.outbox import Frame, TemplateBulkFrame, TemplateFrame
from bridge.core.native_stream import LaneArrivals, new_lane
from bridge.core.stream_health import SMOOTHING, Arrivals, ArrivalsView, StreamHealth
from bridge.ros.graph_types import refuse_other_type
from bridge.ros.qos import default_depth, qos_profile
from bridge.ros.raw_reader import BatchTopic
from bridge.ros.ros_node import RosNode
from bridge.topics.routes import Route, route_for
from bridge.topics.whole_messages import WholeMessages, WholeStream
from protocol.commands import (LABELS_TYPE, CommandFailedError, CreatePublisher, CreateSubscriber,
                               ErrorCode, ForbiddenError, GetLastMessage, GetLastMessageResult, Op,
                               Publish, PublishResult, QoS, RemovePublisher, RemoveSubscriber,
                               TopicBridge, TopicBridgeRemoved, WrongTypeError)
from protocol.framing import StreamTemplate
from protocol.freshness import daemon_clock_ms
from protocol.messages import Message, PolyData, StatusCode
from protocol.messages import Point as PointBody
from protocol.naming import KEY_FRAME, DeviceNameRegistry, NameKey, metadata_for

log = logging.getLogger(__name__)

# `get_last_message` answers with the whole message (JSON and YAML): a larger one (a 20 MB
# point cloud) would be a reply of many MB, and keeping it would hold that much per topic.
LAST_MESSAGE_MAX_BYTES = 8 * 1024 * 1024
POSE_TYPE = "geometry_msgs/msg/Pose"  # the one hot pose type without a header



@dataclass
class TopicInfo:
    """What `list` reports of a bridge."""

    kind: str  # "subscriber" | "publisher"
    topic: str
    ros_type: str
    device: str
    igtl_type: str
    qos: dict[str, Any]
    max_rate_hz: Optional[float] = None
    messages: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


class SubscriberBridge:
    """One ROS topic streamed to every client as one device, by its kind's route
    (bridge/topics/routes.py). Each message becomes one `Frame` handed to the hub through
    the bridge's channel, which `close` closes first: a callback still running then cannot
    bring the device back. `last_message` deserializes the last bytes only when asked.
    """

    def __init__(self, ros: RosNode, hub: Hub, *, topic: str, codec: TypeCodec, qos: QoS,
                 device: str, metadata: dict[str, str],
                 max_rate_hz: Optional[float] = None,
                 message_filter: Optional[Callable[[Any], Any]] = None) -> None:
        self.topic = topic
        self.codec = codec
        self.qos = qos
        self.device = device
        self.max_rate_hz = max_rate_hz
        self._hub = hub
        self._ros = ros
        self._metadata = metadata
        # The security policy's view of a message (tf frames, parameters): None = drop it.
        self._filter = message_filter
        self._count = 0  # messages the Python path took (`count` adds the native lane's)
        self.arrivals: ArrivalsView = Arrivals()  # judged by StreamHealth: stale or not?
        # The message stream (`enable_messages`): the newest message whole, as JSON, at
        # display rate, for the clients that joined its device; None until one asks.
        self._messages: Optional[WholeStream] = None
        # (serialized bytes or None, message or None) of the last message, replaced whole;
        # (None, None) with `last_size` set when it was too large to keep.
        self._last: tuple[Optional[bytes], Any] = (None, None)
        self.last_size = 0
        self._bad = RateLimitedLog(log)  # a stream of bad messages: one line per interval
        self._channel = hub.open_channel(device)
        hub.set_rate_cap(device, max_rate_hz)
        # A volatile image or cloud is not kept for clients that connect later (a late ROS
        # subscriber would not get it either): 20 MB clouds would stay in memory for good.
        hub.set_volatile(device, qos.durability != "transient_local")
        self.route = route_for(codec, filtered=message_filter is not None)
        self._fast = (RawPoseStream(codec, device, metadata) if self.route is Route.POSE
                      else None)
        self._images = RawImageStream() if self.route is Route.IMAGE else None
        # Hot poses are taken by the stream reader, without the interpreter's lock, a burst
        # at a time (bridge/ros/raw_reader.py); the rest through the executor.
        # Where it is built, the reader's thread also converts and writes them itself, without
        # the interpreter, while nothing needs the Python path (bridge/core/native_stream.py).
        # The reader may call back before read_stream returns: all is set before it.
        lane = (new_lane(hub.fanout, codec.ros_type, LAST_MESSAGE_MAX_BYTES, SMOOTHING)
                if self._fast is not None else None)
        self._lane: Any = None  # set once the lane may write (the hub knows it)
        self._lane_template: Optional[StreamTemplate] = None
        if lane is not None:
            self.arrivals = LaneArrivals(lane, hub.fanout)
        self._reader = (ros.read_stream(BatchTopic(topic, codec.message_class,
                                                   qos_profile(qos), self._on_batch, lane))
                        if self._fast is not None else None)
        if lane is not None and self._reader is not None:
            self._lane = lane
            hub.add_lane(device, lane, self._lane_frame)
        self._subscription = (None if self._reader is not None else
                              ros.stream_node.create_subscription(
                                  codec.message_class, topic, self._on_raw, qos_profile(qos),
                                  raw=True))

    @property
    def count(self) -> int:
        """Messages received (and sent on, unless filtered out)."""
        if self._lane is None:
            return self._count
        with self._hub.fanout:
            return self._count + int(self._lane.count)

    def _last_kept(self) -> tuple[Optional[bytes], Any]:
        """(serialized bytes or None, message or None) of the last message: the lane's
        bytes if it took the last one, else what this path kept."""
        if self._lane is not None:
            with self._hub.fanout:
                data = self._lane.last()
            if data is not None:  # the lane took the last one
                return data, None
        return self._last

    @property
    def last_message(self) -> Any:
        """The last message received (None before the first, or if it was larger than
        `LAST_MESSAGE_MAX_BYTES`: see `last_size`), as an rclpy message."""
        last = self._last_kept()
        data, msg = last
        if msg is None and data is not None:
            msg = deserialize_message(data, self.codec.message_class)
            if self._last is last:
                self._last = (data, msg)
        return msg

    def whole_document(self) -> Optional[tuple[str, Optional[tuple[int, int]]]]:
        """The last message as the message stream's JSON, with its header stamp (None: the
        type has none); None before the first or if it was too large to keep. A hot pose
        is read from its bytes, without building the rclpy message."""
        data, msg = self._last_kept()
        ros_type = self.codec.ros_type
        if msg is None and data is not None and self._fast is not None:
            try:
                raw = read_raw_pose(ros_type, data)
            except NotFast:
                pass  # the ordinary way, below
            else:
                stamp = None if ros_type == POSE_TYPE else (raw[0], raw[1])
                return document_to_json(pose_document(ros_type, raw)), stamp
        msg = self.last_message
        if msg is None:
            return None
        header_stamp = getattr(getattr(msg, "header", None), "stamp", None)
        return message_to_json(msg), (None if header_stamp is None
                                      else (header_stamp.sec, header_stamp.nanosec))

    def _keep(self, data: bytes, msg: Any = None) -> None:
        self.last_size = len(data)
        if len(data) > LAST_MESSAGE_MAX_BYTES:
            self._last = (None, None)
        elif msg is not None:
            self._last = (None, msg)
        else:
            self._last = (data, None)

    def enable_messages(self, device: str, metadata: dict[str, str],
                        pacer: WholeMessages) -> str:
        """Open the message stream on `device` (once); clients then `join` it on the hub."""
        if self._messages is None:
            self._hub.limit_to_audience(device)
            self._messages = WholeStream(self._hub.open_channel(device), metadata,
                                         lambda: self.count, self.whole_document,
                                         polled=self._lane is not None)
            pacer.add(self._messages)
        return self._messages.channel.device

    def _on_raw(self, data: bytes) -> None:  # ROS executor thread
        self._on_batch([data])

    def _on_batch(self, messages: list[bytes]) -> None:  # a ROS thread: convert, hand off
        """Messages taken together, in order (one, from the executor). Hot poses become
        `TemplateFrame`s that reach each client in one write; the rest go one by one."""
        if self._channel.closed:
            return
        if self._lane is not None:
            self._settle_lane()
            if not messages:
                return
            with self._hub.fanout:
                self._lane.forget()  # these came after what it wrote
        self.arrivals.note(time.monotonic())
        fast = self._fast
        if fast is None:
            for data in messages:
                self._on_message(data)
            return
        frames: list[tuple[str, Frame]] = []
        last: Optional[bytes] = None  # the last one converted here, kept as the last message
        for data in messages:
            try:
                template, content, timestamp, values = fast.convert(data)
            except NotFast:  # the ordinary way says what is wrong with it, after those before
                self._hub.post_frames(frames, self._channel)
                frames = []
                if last is not None:
                    self._keep(last)
                    last = None
                self._on_message(data)  # keeps it, if it can be read at all
                continue
            self._count += 1
            frames.append((self.device, TemplateFrame(template, content, timestamp, values,
                                                      transform_body)))
            last = data
        if last is not None:
            self._keep(last)
            if self._lane is not None:
                self._lane_takes(fast, frames[-1][1])
        self._hub.post_frames(frames, self._channel)
        self.poke_messages()

    def _lane_takes(self, fast: RawPoseStream, frame: Frame) -> None:
        """The lane takes the frame ids of the last message from now on (it compares the
        next ones' with them, and leaves others to this path)."""
        assert isinstance(frame, TemplateFrame)
        template = frame.template
        if template is self._lane_template:
            return
        frame_id, child = fast.ids
        with self._hub.fanout:
            assert self._lane is not None
            self._lane.set_template(frame_id.encode(), child.encode(), *template.wire_parts())
            self._lane_template = template

    def _lane_frame(self, latest: tuple[bytes, int, int, tuple[float, ...]]) -> Frame:
        """The lane's newest value as a `Frame` (the hub holds the fanout)."""
        content, timestamp, clock, values = latest
        assert self._lane_template is not None, "a lane writes only with a template"
        frame = TemplateFrame(self._lane_template, content, timestamp, values, transform_body)
        frame.clock = clock
        return frame

    def _settle_lane(self) -> None:
        """Reader thread: the clients the lane could not write its last value to get it
        through the loop (`hand_over`); those it wrote only part of, the rest."""
        assert self._lane is not None
        with self._hub.fanout:
            missed, stashed = self._lane.settle()
            latest = self._lane.latest() if missed else None
            frame = self._lane_frame(latest) if latest is not None else None
        for ref in missed:  # weak references to the sessions
            session = ref() if ref is not None else None
            if session is not None and frame is not None:
                session.hand_over(self.device, frame)
        for ref in stashed:
            session = ref() if ref is not None else None
            if session is not None:
                session.stash_left()

    def _on_message(self, data: bytes) -> None:
        if self.route is not Route.MESSAGE and self._encode_serialized(data):
            return
        try:
            msg = deserialize_message(data, self.codec.message_class)
        except Exception as error:  # noqa: BLE001 - bytes rclpy cannot read: one line, go on
            self._bad.warning("deserialize", None, "cannot read a %s from %s (%d bytes), not "
                              "sent: %s", self.codec.ros_type, self.topic, len(data), error)
            return
        if self._filter is not None:
            msg = self._filter(msg)
            if msg is None:
                return
            self._keep(data, msg)  # what the policy lets through, not the bytes
        else:
            self._keep(data)
        self._count += 1
        self._convert(msg)
        self.poke_messages()

    def poke_messages(self) -> None:
        """The message stream (if any) has a newer message to make when due."""
        if self._messages is not None:
            self._messages.poke()

    def _encode_serialized(self, data: bytes) -> bool:
        """Sent (or refused) straight from the bytes, if the codec reads them (images)."""
        images = self._images
        same = images.convert(data) if images is not None else None
        if same is not None:
            self._keep(data)
            self._count += 1
            template, lead, pixels, timestamp = same
            self._hub.post_frame(self._channel, TemplateBulkFrame(template, lead, pixels,
                                                                  timestamp, daemon_clock_ms()))
            self.poke_messages()
            return True
        try:
            encoded: Encoded | CodecError | None = self.codec.encode_serialized(data)
        except CodecError as error:
            encoded = error
        if encoded is None:
            return False
        self._keep(data)
        self._count += 1
        if isinstance(encoded, CodecError):
            self._refused(encoded)
        else:
            message = self._post(encoded)
            if images is not None and is_large(message):  # a small one goes as the others
                images.learn(data, message)
        self.poke_messages()
        return True

    def _refused(self, error: CodecError) -> None:
        self._bad.warning("convert", None, "cannot convert a %s from %s, not sent: %s",
                          self.codec.ros_type, self.topic, error)

    def _convert(self, msg: Any) -> None:
        try:
            encoded = self.codec.encode(msg)
        except CodecError as error:
            self._refused(error)
            return
        self._post(encoded)

    def _post(self, encoded: Encoded) -> Message:
        message = stream_message(self.device, self._metadata, encoded)
        self._hub.post_frame(self._channel, frame_for(message))
        return message

    def info(self) -> TopicInfo:
        extra: dict[str, Any] = {}
        if self._lane is not None:  # its route: how many the native lane wrote
            with self._hub.fanout:
                extra["lane_written"] = int(self._lane.count)
        return TopicInfo("subscriber", self.topic, self.codec.ros_type, self.device,
                         self.codec.igtl_type, self.qos.to_dict(), self.max_rate_hz, self.count,
                         extra)

    def close(self) -> None:
        self._hub.remove_lane(self.device)
        self._hub.close_channel(self._channel)
        if self._messages is not None:
            self._messages.close()
            self._hub.close_channel(self._messages.channel)
        if self._reader is not None:
            self._reader.close()
        if self._subscription is not None:
            self._ros.destroy(self._subscription)


class PublisherBridge:
    def __init__(self, ros: RosNode, hub: Hub, *, topic: str, codec: TypeCodec, qos: QoS,
                 device: str, frame_id: str = "",
                 check: Optional[Callable[[Any], None]] = None,
                 labels_topic: Optional[str] = None) -> None:
        self.topic = topic
        self.codec = codec
        self.qos = qos
        self.device = device
        self.frame_id = frame_id
        self.labels_topic = labels_topic
        self._guard = check  # the policy on what a message writes (tf frames...): raises
        self._refusals = RateLimitedLog(log)
        self.count = 0
        self._ros = ros
        self._hub = hub
        self._publisher = ros.node.create_publisher(codec.message_class, topic, qos_profile(qos))
        # Markups labels (POINT names): PoseArray / PointStamped have no field for them.
        self._labels = (ros.node.create_publisher(StringMsg, labels_topic, qos_profile(qos))
                        if labels_topic is not None else None)
        # Models converted off the loop (see on_igtl): one waiting slot, one worker at most.
        self._heavy_lock = threading.Lock()
        self._heavy_next: Optional[tuple[Message, Callable[[str, int, str], None]]] = None
        self._heavy_running = False
        self._closed = False
        hub.route(device, self.on_igtl)

    def _stamp_now(self) -> tuple[int, int]:
        now = self._ros.node.get_clock().now().seconds_nanoseconds()
        return int(now[0]), int(now[1])

    def publish_value(self, value: Any) -> int:
        """Publish a client's JSON value; returns the number of ROS subscribers.
        Raises `CodecError` naming the bad part of the value, `ForbiddenError` if it writes
        what the security policy denies."""
        msg = self.codec.from_value(value, stamp=self._stamp_now(), frame_id=self.frame_id)
        self._check(msg)
        return self._publish_open(msg)

    def publish_message(self, fields: dict[str, Any]) -> int:
        """Publish a whole message given as generic JSON (ROS units, every field checked);
        an empty header stamp is stamped now, and an empty frame id gets the publisher's."""
        msg = dict_to_message(self.codec.message_class, fields)
        header = getattr(msg, "header", None)
        if header is not None:
            if header.stamp.sec == 0 and header.stamp.nanosec == 0:
                header.stamp.sec, header.stamp.nanosec = self._stamp_now()
            if not header.frame_id:
                header.frame_id = self.frame_id
        self._check(msg)
        return self._publish_open(msg)

    def _publish_open(self, msg: Any) -> int:
        """Publish unless the bridge was removed meanwhile (a worker thread publishes:
        TopicBridges.publish)."""
        with self._heavy_lock:
            if self._closed:
                raise CommandFailedError("topic", "a publisher bridge", f"{self.topic}, "
                                         f"removed meanwhile", code=ErrorCode.NOT_FOUND)
            return self._publish(msg)

    def _check(self, msg: Any) -> None:
        if self._guard is not None:
            self._guard(msg)

    def on_igtl(self, message: Message, client: Replier) -> None:
        """A client sent data to this publisher's device (loop thread). A body may become
        several messages (a POINT list as one PointStamped per point): all are checked
        before any is published. A model (POLYDATA for a Mesh, Marker or Path) is
        converted in a worker thread, newest first (`_heavy_worker`)."""
        if self.codec.heavy_polydata and isinstance(message.body, PolyData):
            try:
                loop = asyncio.get_running_loop()
            except RuntimeError:  # called outside the daemon's loop (tests): inline
                loop = None
            if loop is not None:
                self._offload(loop, message, client)
                return
        self._convert_and_publish(message, client.send_status)

    def _offload(self, loop: asyncio.AbstractEventLoop, message: Message,
                 client: Replier) -> None:
        """Queue a model for the worker: one slot, so a newer model waiting replaces an
        older one (a model update supersedes it) and memory stays bounded."""
        def reply(device: str, code: int, text: str) -> None:  # worker -> loop thread
            loop.call_soon_threadsafe(client.send_status, device, code, text)

        with self._heavy_lock:
            self._heavy_next = (message, reply)
            if self._heavy_running:
                return
            self._heavy_running = True
        loop.run_in_executor(None, self._heavy_worker)

    def _heavy_worker(self) -> None:
        while True:
            with self._heavy_lock:
                item, self._heavy_next = self._heavy_next, None
                if item is None or self._closed:
                    self._heavy_running = False
                    return
            try:
                self._convert_and_publish(*item)
            except Exception:  # noqa: BLE001 - a worker must not die silently
                log.exception("converting a model for %s failed", self.topic)

    def _convert_and_publish(self, message: Message,
                             reply: Callable[[str, int, str], None]) -> None:
        frame_id = message.metadata.get(KEY_FRAME, "") or self.frame_id
        try:
            msgs: list[Any] = []
            raw = (self.codec.from_igtl_raw(message.body, stamp=self._stamp_now(),
                                            frame_id=frame_id, metadata=message.metadata)
                   if self.codec.heavy_polydata else None)
            if raw is not None:  # a model serialized with numpy; the probe has its header
                data, probe = raw
                self._check(probe)
                msgs.append(data)
            else:
                msgs = self.codec.from_igtl_all(message.body, stamp=self._stamp_now(),
                                                frame_id=frame_id, metadata=message.metadata)
                for msg in msgs:
                    self._check(msg)
        except ForbiddenError as error:
            self._refusals.warning(self.topic, None, "refused %s for %s from a client: %s",
                                   message.type_name, self.topic, error)
            reply(message.device_name, StatusCode.ACCESS_DENIED,
                  f"not published to {self.topic}: {error}")
            return
        except CodecError as error:
            # A client can send bad data as fast as it likes: the log says it once a while.
            self._refusals.warning(self.topic, None, "refused %s for %s from a client: %s",
                                   message.type_name, self.topic, error)
            reply(message.device_name, StatusCode.CONFIG_ERROR,
                  f"not published to {self.topic}: {error}")
            return
        with self._heavy_lock:  # close() may run meanwhile (a worker thread publishes)
            if self._closed:
                return
            if self._labels is not None and isinstance(message.body, PointBody):
                self._labels.publish(StringMsg(data=json.dumps(markup_labels(message.body),
                                                               ensure_ascii=False)))
            for msg in msgs:
                self._publish(msg)

    def _publish(self, msg: Any) -> int:
        self._publisher.publish(msg)
        self.count += 1
        return int(self._publisher.get_subscription_count())

    def info(self) -> TopicInfo:
        extra: dict[str, Any] = {"subscribers": int(self._publisher.get_subscription_count())}
        if self.frame_id:
            extra["frame"] = self.frame_id
        if self.labels_topic is not None:
            extra["labels_topic"] = self.labels_topic
        return TopicInfo("publisher", self.topic, self.codec.ros_type, self.device,
                         self.codec.igtl_type, self.qos.to_dict(), None, self.count, extra)

    def close(self) -> None:
        self._hub.unroute(self.device)
        with self._heavy_lock:  # a model being converted is then dropped, not published
            self._closed = True
            self._heavy_next = None
        self._ros.destroy(self._publisher)
        if self._labels is not None:
            self._ros.destroy(self._labels)


class TopicBridges:
    """The daemon's subscriber and publisher bridges, one of each kind per topic."""

    def __init__(self, ros: RosNode, hub: Hub, names: DeviceNameRegistry, *,
                 health: Optional[StreamHealth] = None) -> None:
        self._ros = ros
        self._hub = hub
        self._health = health  # tells clients when a stream goes stale (None: nobody)
        self._names = names
        self.subscribers: dict[str, SubscriberBridge] = {}
        self.publishers: dict[str, PublisherBridge] = {}
        self._whole = WholeMessages(hub)  # every subscriber's message stream, paced

    def _codec(self, type_name: str) -> TypeCodec:
        try:
            return codec_for(type_name)
        except CodecError as error:
            raise CommandFailedError("type", "a message type installed in the daemon's "
                                     "environment", f"{type_name!r} ({error})",
                                     code=ErrorCode.UNKNOWN_ROS_TYPE) from None

    def _check_graph(self, topic: str, ros_type: str) -> None:
        refuse_other_type(self._ros, topic, ros_type, "type")

    @staticmethod
    def _check_existing(existing: SubscriberBridge | PublisherBridge | None, topic: str,
                        ros_type: str) -> bool:
        """True if an identical bridge exists (creating is idempotent, so a client that
        reconnects can re-create what it had); a type clash is refused."""
        if existing is None:
            return False
        if existing.codec.ros_type != ros_type:
            kind = "subscriber" if isinstance(existing, SubscriberBridge) else "publisher"
            raise CommandFailedError(
                "type", f"{existing.codec.ros_type} (the {kind} bridge on {topic} has it; "
                f"a bridge outlives the client that made it. Ask with that type to share "
                f"it, or remove it first: op remove_{kind} "
                f"{{\"topic\": \"{topic}\"}}; Python: "
                f"ros.remove_bridge(\"create_{kind}\", \"{topic}\"))", ros_type,
                code=ErrorCode.ALREADY_EXISTS)
        return True

    def create_subscriber(self, request: CreateSubscriber, client: Optional[Subscriber],
                          guard: ContentGuard) -> Created[TopicBridge]:
        """``guard`` judges what its messages name (a tf topic's frames) on their way to
        clients; an existing bridge keeps its own (the policy is the daemon's: the same)."""
        topic = request.topic
        codec = self._codec(request.type)  # a bare name is looked up among installed packages
        ros_type = codec.ros_type
        if self._check_existing(self.subscribers.get(topic), topic, ros_type):
            return Created(self._with_messages(request, client, self.subscribers[topic],
                                               _describe(self.subscribers[topic].info())),
                           existed=True)
        self._check_graph(topic, ros_type)
        key = NameKey.subscriber(topic)
        device = self._names.register(key)
        self._hub.bridge_device(made_bridge(request), device)  # before its first value
        self._decline_values(request, client, device, codec.bulk)  # so is this
        bridge = SubscriberBridge(
            self._ros, self._hub, topic=topic, codec=codec,
            qos=request.qos.with_default_depth(default_depth(codec.bulk)),
            device=device, metadata=metadata_for(key, ros_type=ros_type),
            max_rate_hz=request.rate_hz, message_filter=guard.message_filter())
        self.subscribers[topic] = bridge
        if self._health is not None:
            node = self._ros.node
            self._health.watch(device, topic, bridge.arrivals,
                               lambda: node.count_publishers(topic))
        log.info("subscribed to %s (%s) as device %r", topic, ros_type, device)
        return Created(self._with_messages(request, client, bridge, _describe(bridge.info())),
                       existed=False)

    def _with_messages(self, request: CreateSubscriber, client: Optional[Subscriber],
                       bridge: SubscriberBridge, reply: TopicBridge) -> TopicBridge:
        """Join `client` to the bridge's message stream if it asked (not for images and
        point clouds: their IMAGE / POLYDATA stream is the whole message already), and
        let it decline the native values (``native`` false) or take them again."""
        self._decline_values(request, client, bridge.device, bridge.codec.bulk)
        if not request.messages or client is None or bridge.codec.bulk:
            return reply
        key = NameKey.subscriber_messages(bridge.topic)
        device = bridge.enable_messages(self._names.register(key),
                                        metadata_for(key, ros_type=bridge.codec.ros_type),
                                        self._whole)
        self._hub.join(device, client)
        # Its pacer stops looking while nobody listens, and what a lane writes in C pokes
        # nothing: the newest of a pose topic reached no client that joined after the last
        # one left (a reconnected module, a second script).
        bridge.poke_messages()
        return replace(reply, message_device=device)

    def _decline_values(self, request: CreateSubscriber, client: Optional[Subscriber],
                        device: str, bulk: bool) -> None:
        """`client` takes the native values of `device` unless it reads the messages whole
        only (``native`` false); an image's or a cloud's native stream is its whole one."""
        if client is not None and not bulk:
            self._hub.set_declined(device, client, request.messages and not request.native)

    def remove_subscriber(self, request: RemoveSubscriber) -> TopicBridgeRemoved:
        topic = request.topic
        bridge = self.subscribers.pop(topic, None)
        if bridge is None:
            raise CommandFailedError("topic", "a topic with a subscriber bridge", topic,
                                     code=ErrorCode.NOT_FOUND)
        bridge.close()
        if self._health is not None:
            self._health.unwatch(bridge.device)
        self._names.release(NameKey.subscriber(topic))
        self._names.release(NameKey.subscriber_messages(topic))
        return TopicBridgeRemoved(topic, bridge.device)

    def create_publisher(self, request: CreatePublisher,
                         guard: ContentGuard) -> Created[TopicBridge]:
        topic = request.topic
        codec = self._codec(request.type)  # a bare name is looked up among installed packages
        ros_type = codec.ros_type
        labels = request.labels_topic
        existing = self.publishers.get(topic)
        if self._check_existing(existing, topic, ros_type):
            assert existing is not None
            if (existing.frame_id, existing.labels_topic) != (request.frame or "", labels):
                raise CommandFailedError("frame", f"frame {existing.frame_id!r} and labels "
                                         f"topic {existing.labels_topic} (the bridge on "
                                         f"{topic} has them)", f"{request.frame or ''!r} and "
                                         f"{labels}", code=ErrorCode.ALREADY_EXISTS)
            return Created(_describe(existing.info()), existed=True)
        self._check_graph(topic, ros_type)
        if labels is not None:
            self._check_graph(labels, LABELS_TYPE)
        device = self._names.register(NameKey.publisher(topic))
        bridge = PublisherBridge(self._ros, self._hub, topic=topic, codec=codec,
                                 qos=request.qos.with_default_depth(default_depth(codec.bulk)),
                                 device=device, frame_id=request.frame or "", labels_topic=labels,
                                 check=guard.message_check())
        self.publishers[topic] = bridge
        log.info("publishing %s (%s); clients send to device %r", topic, ros_type, device)
        return Created(_describe(bridge.info()), existed=False)

    def remove_publisher(self, request: RemovePublisher) -> TopicBridgeRemoved:
        topic = request.topic
        bridge = self.publishers.pop(topic, None)
        if bridge is None:
            raise CommandFailedError("topic", "a topic with a publisher bridge", topic,
                                     code=ErrorCode.NOT_FOUND)
        bridge.close()
        self._names.release(NameKey.publisher(topic))
        return TopicBridgeRemoved(topic, bridge.device)

    def publish(self, request: Publish) -> OffLoop[PublishResult]:
        topic = request.topic
        bridge = self.publishers.get(topic)
        if bridge is None:
            raise CommandFailedError("topic", "a topic with a publisher bridge (create_publisher "
                                     "first)", topic, code=ErrorCode.NOT_FOUND)
        field = "value" if request.message is None else "message"

        def work() -> PublishResult:  # a message of a megabyte of JSON takes a second
            try:
                if request.message is None:
                    subscribers = bridge.publish_value(request.value)
                else:
                    subscribers = bridge.publish_message(request.message)
            except CodecError as error:
                raise WrongTypeError(f"{field}.{error.field}" if error.field else field,
                                     error.expected, error.got) from None
            return PublishResult(topic, subscribers)
        return OffLoop(work)

    def get_last_message(self, request: GetLastMessage) -> GetLastMessageResult:
        topic = request.topic
        bridge = self.subscribers.get(topic)
        if bridge is None:
            raise CommandFailedError("topic", "a topic with a subscriber bridge", topic,
                                     code=ErrorCode.NOT_FOUND)
        message = bridge.last_message
        if message is None and bridge.count:
            raise CommandFailedError(
                "topic", f"a last message of at most {LAST_MESSAGE_MAX_BYTES} bytes (larger "
                "ones stream to the subscriber's device but are not kept)",
                f"{bridge.last_size} bytes on {topic}", code=ErrorCode.NOT_SUPPORTED)
        result = GetLastMessageResult(topic, bridge.codec.ros_type, bridge.count, False)
        if message is not None:
            result = replace(result, received=True, value=bridge.codec.to_value(message),
                             text=(bridge.codec.to_yaml(message) if request.format == "yaml"
                                   else message_to_json(message)))
        return result

    def handlers(self) -> dict[type[Op], Handler]:
        return {
            # The client is its session, a Subscriber as well as a Replier.
            CreateSubscriber: lambda request, client, guard: self.create_subscriber(
                request, cast(Optional[Subscriber], client), guard),
            RemoveSubscriber: lambda request, _: self.remove_subscriber(request),
            CreatePublisher: lambda request, _, guard: self.create_publisher(request, guard),
            RemovePublisher: lambda request, _: self.remove_publisher(request),
            Publish: lambda request, _: self.publish(request),
            GetLastMessage: lambda request, _: self.get_last_message(request),
        }

    def recorded_topics(self) -> dict[str, Optional[str]]:
        """What a recording takes from here (any thread): every subscribed topic and
        every topic clients publish on, with its type."""
        topics: dict[str, Optional[str]] = {
            topic: bridge.codec.ros_type for topic, bridge in tuple(self.subscribers.items())}
        topics.update((topic, publisher.codec.ros_type)
                      for topic, publisher in tuple(self.publishers.items()))
        return topics

    def describe(self) -> list[dict[str, Any]]:
        bridges: list[SubscriberBridge | PublisherBridge] = [*self.subscribers.values(),
                                                            *self.publishers.values()]
        described = []
        for bridge in bridges:
            entry = _describe(bridge.info()).to_dict()
            stale = self._health.stale(bridge.device) if self._health is not None else None
            if stale is not None and isinstance(bridge, SubscriberBridge):
                entry["stale"] = stale
            described.append(entry)
        return described

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        bridges: list[SubscriberBridge | PublisherBridge] = [*self.subscribers.values(),
                                                            *self.publishers.values()]
        for bridge in bridges:
            bridge.close()
        self.subscribers.clear()
        self.publishers.clear()
        self._whole.close()


def _describe(info: TopicInfo) -> TopicBridge:
    return TopicBridge(info.kind, info.topic, info.ros_type, info.device, info.igtl_type,
                       info.qos, info.messages, info.max_rate_hz or None, dict(info.extra))
