"""Recording ROS topics into a bag: the ROS side of `bridge.record.bag.BagWriter`.

A `Recorder` subscribes raw (the serialized CDR bytes as received, never re-serialized)
to the topics its ``wanted`` callable names, as they appear in the graph (polled every
`POLL_S`), and hands each burst to the bag. The subscriptions are taken by a raw reader
thread of their own, without the interpreter's lock (bridge/ros/raw_reader.py), or by
rclpy's ``raw=True`` subscriptions where the compiled reader is not built. Either way the
callback only offers bytes to the bag's queue.

QoS as ``ros2 bag record`` chooses it: reliable if every publisher is, transient local if
every publisher is (so /tf_static and robot descriptions published before the recording
are in it), and each publisher's offered QoS in the channel's ``offered_qos_profiles``, in
rosbag2's YAML, for players that republish.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Optional, cast

from bridge.core.threads import OnFailure, start_thread
from bridge.record.bag import BagStats, BagWriter
from bridge.record.definitions import DefinitionError, full_definition
from protocol.commands import RecordingResult

if TYPE_CHECKING:
    from bridge.ros.ros_node import RosNode

__all__ = ["POLL_S", "Recorder", "Wanted"]

log = logging.getLogger(__name__)

POLL_S = 0.5  # how often the graph is looked at for the topics still to subscribe
DEPTH = 1000  # a second of 1 kHz tf waiting in the middleware if the reader thread stalls
BULK_DEPTH = 30  # a second of images
_BULK_TYPES = frozenset({"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage",
                         "sensor_msgs/msg/PointCloud2"})
# Durations rosbag2 writes for "infinite" (rmw's RMW_DURATION_INFINITE).
_INFINITE = "\n    sec: 9223372036\n    nsec: 854775807"

# topic -> its type if the caller knows it (None: the graph's, once it has one).
Wanted = Callable[[], Mapping[str, Optional[str]]]


@dataclass
class _Topic:
    topic: str
    ros_type: str
    channel: int
    subscription: Any = None


@dataclass
class _State:
    topics: dict[str, _Topic] = field(default_factory=dict)
    pending: dict[str, str] = field(default_factory=dict)  # topic -> why not yet recorded
    attached: set[str] = field(default_factory=set)


def _offered_qos(infos: list[Any]) -> str:
    """The publishers' QoS in rosbag2's ``offered_qos_profiles`` YAML."""
    entries = []
    for info in infos:
        qos = info.qos_profile
        entries.append(
            f"- history: {int(qos.history)}\n  depth: {int(qos.depth)}\n"
            f"  reliability: {int(qos.reliability)}\n  durability: {int(qos.durability)}\n"
            f"  deadline:{_INFINITE}\n  lifespan:{_INFINITE}\n"
            f"  liveliness: {int(qos.liveliness)}\n"
            f"  liveliness_lease_duration:{_INFINITE}\n"
            f"  avoid_ros_namespace_conventions: false")
    return "\n".join(entries)


class Recorder:
    """Records what ``wanted`` names into ``bag`` until `stop`; ``attachments`` names the
    files (URI -> path) to carry in the bag, each attached once."""

    def __init__(self, ros: RosNode, bag: BagWriter, wanted: Wanted, *,
                 attachments: Callable[[], Mapping[str, Path]] = dict,
                 on_topic: Optional[Callable[[str, str], None]] = None) -> None:
        self._ros = ros
        self.bag = bag
        self._wanted = wanted
        self._attachments = attachments
        self._on_topic = on_topic
        self._state = _State()
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        self._reader: Any = None
        self._thread: Optional[threading.Thread] = None

    def start(self) -> None:
        """Subscribe what the graph has now, then watch it in a thread of its own."""
        self.poll()
        self._thread = start_thread("recorder", self._watch, OnFailure.RESTART)

    def _watch(self) -> None:
        while not self._stopping.wait(POLL_S):
            if not self.bag.running:  # the disk refused it: its subscriptions go
                self._unsubscribe()
                return
            self.poll()

    def poll(self) -> None:
        """Subscribe the wanted topics the graph now has a type for; attach new files."""
        wanted = dict(self._wanted())
        graph = dict(self._ros.node.get_topic_names_and_types())
        with self._lock:
            if self._stopping.is_set():
                return
            for topic, ros_type in wanted.items():
                if topic in self._state.topics:
                    continue
                types = [ros_type] if ros_type else graph.get(topic, [])
                if len(types) != 1:
                    self._state.pending[topic] = (
                        "not in the ROS graph yet" if not types else
                        f"several types in the graph ({', '.join(types)})")
                    continue
                # Subscribed once it has a publisher, whose QoS it then matches: a latched
                # topic asked for as volatile would miss what was latched before.
                publishers = self._ros.node.get_publishers_info_by_topic(topic)
                if not publishers:
                    self._state.pending[topic] = "no publisher yet"
                    continue
                self._subscribe(topic, types[0], publishers)
        self._attach()

    def _subscribe(self, topic: str, ros_type: str, publishers: list[Any]) -> None:
        from bridge.codecs import CodecError
        from bridge.codecs.registry import message_class

        try:
            definition = full_definition(ros_type)
            cls = message_class(ros_type)
        except (DefinitionError, CodecError) as error:
            self._state.pending[topic] = f"{ros_type} cannot be recorded: {error}"
            return
        channel = self.bag.add_channel(topic, ros_type, definition, _offered_qos(publishers))
        entry = _Topic(topic, ros_type, channel)
        entry.subscription = self._take(entry, cls, self._qos(publishers, ros_type))
        self._state.topics[topic] = entry
        self._state.pending.pop(topic, None)
        log.info("recording %s (%s) into %s", topic, ros_type, self.bag.path)
        if self._on_topic is not None:
            self._on_topic(topic, ros_type)

    @staticmethod
    def _qos(publishers: list[Any], ros_type: str) -> Any:
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        reliable = all(
            p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers)
        latched = all(
            p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers)
        return QoSProfile(
            depth=BULK_DEPTH if ros_type in _BULK_TYPES else DEPTH,
            reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
            durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                        else DurabilityPolicy.VOLATILE))

    def _take(self, entry: _Topic, cls: Any, qos: Any) -> Any:
        """The topic's raw subscription: the reader thread's, else rclpy's."""
        from bridge.ros.raw_reader import BatchTopic, ReaderError

        offer = self.bag.offer
        channel = entry.channel
        if self._reader is None:
            self._reader = self._ros.raw_reader([], name="recorder-reader", batches=True)
            if self._reader is None:
                self._reader = False  # not built here: rclpy takes them
        if self._reader:
            try:
                return self._reader.add(BatchTopic(entry.topic, cls, qos,
                                                   lambda batch: offer(channel, batch)))
            except ReaderError as error:
                log.warning("%s is taken through rclpy: %s", entry.topic, error)
        return self._ros.stream_node.create_subscription(
            cls, entry.topic, lambda data: offer(channel, [cast(bytes, data)]), qos,
            raw=True)  # raw: the bytes as received

    def _attach(self) -> None:
        for name, path in dict(self._attachments()).items():
            if name in self._state.attached:
                continue
            self._state.attached.add(name)
            try:
                data = path.read_bytes()
            except OSError as error:
                log.warning("%s: its file %s is not attached to %s: %s", name, path,
                            self.bag.path, error.strerror)
                continue
            self.bag.attach(name, data)

    def status(self) -> RecordingResult:
        stats = self.bag.stats()
        with self._lock:
            pending = dict(self._state.pending)
        return stats.result(pending)

    @property
    def topics(self) -> list[str]:
        with self._lock:
            return sorted(self._state.topics)

    def stop(self) -> BagStats:
        """Unsubscribe, finish the bag."""
        self._stopping.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()
        self._unsubscribe()
        return self.bag.close()

    def _unsubscribe(self) -> None:
        from bridge.ros.raw_reader import RawSubscription

        with self._lock:
            self._stopping.set()
            entries = [entry for entry in self._state.topics.values()
                       if entry.subscription is not None]
            for entry in entries:
                subscription, entry.subscription = entry.subscription, None
                if isinstance(subscription, RawSubscription):
                    subscription.close()
                else:
                    self._ros.destroy(subscription)
            if self._reader:
                self._reader.close()
