"""The player: a bag served to 3D Slicer over OpenIGTLink as the live daemon serves ROS.

    player thread (the "ROS thread")              asyncio loop (main thread)
    ────────────────────────────────              ──────────────────────────
    bag messages at the clock's pace ─► tf buffer ─► TfLookups ─► Hub ─► clients
      /tf, /tf_static                   (robots' links, lookups)   ▲
      joint states ─► JointStateTracker ─┘                         │
      subscribed topics ─► codec ─► stream_message ────────────────┘
                                                   Dispatcher ◄── COMMANDs

The same server, hub, dispatcher, device names, codecs, tf lookups and robot loading as
the daemon (bridge/core, protocol/naming, bridge/codecs, bridge/tf, bridge/robots): what a
client sees of a bag is what it saw of the live session. What ROS did and the bag cannot
(publishing, services, parameters, actions) is answered NOT_SUPPORTED by the dispatcher.

The bag stands in for robot_state_publisher too: each robot description it holds gets
its fixed joints as static tf and, from the joint states of its namespace, its moving
joints as tf (`bridge.robots.joint_states`, the rule the state publisher node uses). A bag
that also recorded that publisher's /tf gives the same transforms twice: harmless.

A seek (or a loop back to the start) clears the tf buffer and fills it with the state at
the new time, read backwards through the bag's index (`Bag.latest_before`): the latest
transform of each frame, the latest joint state of each topic, the latest message of each
subscribed topic; so the first pose and image shown after it are those at that time.
"""

from __future__ import annotations

import asyncio
import logging
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from bridge.core.threads import OnFailure, start_thread
from bridge.core.content_guards import TF_MESSAGE_TYPE
from bridge.codecs.base import TypeCodec, stream_message
from bridge.codecs.catalog import SPECIFIC_CODECS
from bridge.codecs.errors import CodecError
from bridge.core.content_guards import ContentGuard
from bridge.core.dispatch import Created, Dispatcher, Handler, made_bridge
from bridge.core.heavy import HeavyWork
from bridge.core.hub import Hub, StreamChannel, Subscriber, frame_for
from bridge.core.logging_limits import RateLimitedLog
from bridge.core.security import SecurityPolicy, is_loopback_host
from bridge.core.server import BridgeServer
from bridge.core.session import SessionLimits
from bridge.markers.capability import MarkerServing
from bridge.playback.bag import Bag, BagMessage
from bridge.playback.clock import PlayClock
from bridge.robots.capability import RobotServing, _Robot
from bridge.robots.errors import RobotError
from bridge.robots.joint_states import JointStateTracker, joint_frames
from bridge.tf.buffer import StampedTransform
from bridge.tf.capability import TfLookups, tf_cdr_to_transforms
from protocol import commands as c
from protocol.commands import CommandFailedError, ErrorCode, Op
from protocol.naming import DeviceNameRegistry, NameKey, metadata_for

__all__ = ["PlayOptions", "Player", "PlayerGraph", "run_player"]

log = logging.getLogger(__name__)

_NS_PER_S = 1_000_000_000
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
DESCRIPTION_TYPE = "std_msgs/msg/String"
# How far back a seek looks for each frame's latest transform and each topic's joint state
# (the tf buffer's own history, tf2's default): a frame silent longer is not shown.
PRIME_WINDOW_NS = 10 * _NS_PER_S
PLAYER_NODE = "/slicer_bridge_player"
# Messages already due are played together, at most this many (a lookup is then evaluated
# once per burst, not once per message).
BURST = 256


@dataclass(frozen=True)
class PlayOptions:
    bag: Path
    host: str = "127.0.0.1"
    port: int = 18944
    rate: float = 1.0
    loop: bool = False
    start_s: float = 0.0  # seconds from the bag's start
    paused: bool = False
    package_paths: tuple[tuple[str, str], ...] = ()


# ---------------------------------------------------------------------------- the graph


class _BagNode:
    """The ROS graph questions the dispatcher asks (`list_topics`), answered from the bag."""

    def __init__(self, bag: Bag) -> None:
        self._bag = bag

    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        return sorted((topic, [ros_type]) for topic, ros_type in self._bag.topics().items())

    def count_publishers(self, topic: str) -> int:
        return 1 if topic in self._bag.topics() else 0

    def get_service_names_and_types(self) -> list[tuple[str, list[str]]]:
        return []


class PlayerGraph:
    """The player's `RosGraph`: names resolve as for a node at the root namespace."""

    def __init__(self, bag: Bag) -> None:
        self.node = _BagNode(bag)

    @property
    def fully_qualified_name(self) -> str:
        return PLAYER_NODE

    def resolve_name(self, name: str, field: str) -> str:
        return name if name.startswith("/") else "/" + name.lstrip("~/")


def bag_type_resolver(bag: Bag) -> Callable[[str], str]:
    """A request's type name -> ``pkg/msg/Type`` by the protocol's grammar, a bare name
    looked up among the bag's types (not among installed ROS packages: there are none)."""
    types = tuple(sorted(set(bag.topics().values())))

    def resolve(name: str) -> str:
        return c.resolve_message_type(name, packages_of=lambda bare: tuple(
            t.split("/")[0] for t in types if t.endswith("/" + bare)), known=types)
    return resolve


# ---------------------------------------------------------------------------- topics


@dataclass(eq=False)
class _PlayedTopic:
    topic: str
    codec: TypeCodec
    device: str
    metadata: dict[str, str]
    channel: StreamChannel
    filter: Optional[Callable[[Any], Any]]
    messages: int = 0


class PlayedTopics:
    """``create_subscriber`` of a bag's topic: its messages, converted by the daemon's codec,
    on the device the daemon would name, as the clock reaches them."""

    def __init__(self, hub: Hub, names: DeviceNameRegistry, bag: Bag,
                 on_new: Callable[[str], None]) -> None:
        self._hub = hub
        self._names = names
        self._bag = bag
        self._on_new = on_new  # the player shows a new subscriber the message at the clock
        self.subscribers: dict[str, _PlayedTopic] = {}
        self._bad = RateLimitedLog(log)

    def create_subscriber(self, request: c.CreateSubscriber, client: Optional[Subscriber],
                          guard: ContentGuard) -> Created[c.TopicBridge]:
        topic = request.topic
        types = self._bag.topics()
        bag_type = types.get(topic)
        if bag_type is None:
            raise CommandFailedError("topic", "a topic of the bag (" + ", ".join(sorted(types))
                                     + ")", topic, code=ErrorCode.NOT_FOUND)
        ros_type = bag_type_resolver(self._bag)(request.type)
        if ros_type != bag_type:
            raise CommandFailedError("type", f"{bag_type} (what the bag holds on {topic})",
                                     ros_type, code=ErrorCode.WRONG_TYPE)
        codec = SPECIFIC_CODECS.get(ros_type)
        if codec is None:
            raise CommandFailedError("type", "a type the player converts: "
                                     + ", ".join(sorted(SPECIFIC_CODECS)), ros_type,
                                     code=ErrorCode.NOT_SUPPORTED)
        existing = self.subscribers.get(topic)
        if existing is not None:
            return Created(self._describe(existing), existed=True)
        key = NameKey.subscriber(topic)
        device = self._names.register(key)
        self._hub.bridge_device(made_bridge(request), device)  # before its first value
        channel = self._hub.open_channel(device)
        self._hub.set_rate_cap(device, request.rate_hz)
        self._hub.set_volatile(device, request.qos.durability != "transient_local")
        played = _PlayedTopic(topic, codec, device, metadata_for(key, ros_type=ros_type),
                              channel, guard.message_filter())
        self.subscribers[topic] = played
        log.info("playing %s (%s) as device %r", topic, ros_type, device)
        self._on_new(topic)
        return Created(self._describe(played), existed=False)

    def remove_subscriber(self, request: c.RemoveSubscriber) -> c.TopicBridgeRemoved:
        played = self.subscribers.pop(request.topic, None)
        if played is None:
            raise CommandFailedError("topic", "a topic with a subscriber bridge", request.topic,
                                     code=ErrorCode.NOT_FOUND)
        self._hub.close_channel(played.channel)
        self._names.release(NameKey.subscriber(played.topic))
        return c.TopicBridgeRemoved(played.topic, played.device)

    def play(self, topic: str, msg: Any) -> None:
        """One decoded message of ``topic`` to its subscribers (player thread)."""
        played = self.subscribers.get(topic)
        if played is None or played.channel.closed:
            return
        if played.filter is not None:
            msg = played.filter(msg)
            if msg is None:
                return
        try:
            encoded = played.codec.encode_fields(msg)
        except CodecError as error:
            self._bad.warning(topic, None, "cannot convert a %s from %s, not sent: %s",
                              played.codec.ros_type, topic, error)
            return
        played.messages += 1
        self._hub.post_frame(played.channel,
                             frame_for(stream_message(played.device, played.metadata, encoded)))

    def _describe(self, played: _PlayedTopic) -> c.TopicBridge:
        return c.TopicBridge("subscriber", played.topic, played.codec.ros_type, played.device,
                             played.codec.igtl_type, messages=played.messages)

    def handlers(self) -> dict[type[Op], Handler]:
        return {
            c.CreateSubscriber: self.create_subscriber,
            c.RemoveSubscriber: lambda request, _: self.remove_subscriber(request),
        }

    def describe(self) -> list[dict[str, Any]]:
        return [self._describe(played).to_dict() for played in self.subscribers.values()]

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        for played in self.subscribers.values():
            self._hub.close_channel(played.channel)
        self.subscribers.clear()


# ---------------------------------------------------------------------------- markers


class PlayedMarkers(MarkerServing):
    """``create_marker_subscriber`` of a bag's Marker, MarkerArray, Path, PolygonStamped or
    PointStamped topic: its messages (decoded from the bag) go to the daemon's marker
    workers, as a ROS subscription's do."""

    def __init__(self, hub: Hub, names: DeviceNameRegistry, *, tf: TfLookups, bag: Bag,
                 package_paths: Mapping[str, Path], on_new: Callable[[str], None]) -> None:
        super().__init__(hub, names, tf=tf, package_paths=package_paths)
        self._bag = bag
        self._on_new = on_new

    def _check_source(self, topic: str, ros_type: str, type_name: str) -> tuple[Any, bool]:
        types = self._bag.topics()
        bag_type = types.get(topic)
        if bag_type is None:
            raise CommandFailedError("topic", "a topic of the bag (" + ", ".join(sorted(types))
                                     + ")", topic, code=ErrorCode.NOT_FOUND)
        if bag_type != ros_type:
            raise CommandFailedError("type", f"{bag_type} (what the bag holds on {topic})",
                                     type_name, code=ErrorCode.WRONG_TYPE)
        return None, False  # decoded by the player, not read as CDR

    def _open_source(self, sub: Any) -> None:
        self._on_new(sub.topic)

    def play(self, topic: str, msg: Any) -> None:
        """One decoded message of ``topic`` to its marker worker (player thread)."""
        sub = self.subscriptions.get(topic)
        if sub is not None and not sub.closed:
            sub.on_message(msg)


# ---------------------------------------------------------------------------- robots


@dataclass
class _Description:
    """A robot description the bag holds, and the state publisher it stands in for."""

    topic: str
    text: str
    joint_states_topic: str
    tracker: Optional[JointStateTracker] = None
    static: list[StampedTransform] = field(default_factory=list)


class PlayedRobots(RobotServing):
    """``create_robot`` from the bag: its description topics (a parameter source means the
    topic its node publishes the parameter on: ``<node's namespace>/<parameter>``), meshes
    from the bag's attachments or ``--package-path``."""

    def __init__(self, hub: Hub, names: DeviceNameRegistry, *, tf: TfLookups,
                 descriptions: Mapping[str, _Description],
                 package_paths: Mapping[str, Path],
                 attachment_files: Mapping[str, Path]) -> None:
        super().__init__(hub, names, tf=tf, package_paths=package_paths)
        self._descriptions = descriptions
        self._attachment_files = attachment_files  # URI in a URDF -> the file extracted

    def _description_of(self, robot: _Robot) -> _Description:
        source = robot.source
        if source.kind == "topic":
            wanted = source.topic
        else:
            wanted = f"{source.node.rsplit('/', 1)[0]}/{source.parameter}"
        found = self._descriptions.get(wanted)
        if found is None and source.kind == "parameter" and len(self._descriptions) == 1:
            found = next(iter(self._descriptions.values()))  # the bag's one robot
        if found is None:
            held = ", ".join(sorted(self._descriptions)) or "none"
            raise CommandFailedError(
                "source.topic" if source.kind == "topic" else "source.node",
                f"a robot description the bag holds (on {wanted})",
                f"the bag's descriptions: {held}", code=ErrorCode.NOT_FOUND)
        return found

    async def _first_description(self, robot: _Robot) -> Optional[str]:
        if robot.source.kind == "file":
            return "<file>"
        return _with_attachments(self._description_of(robot).text, self._attachment_files)

    def _joint_states_topic(self, robot: _Robot) -> str:
        if robot.source.kind == "file":
            namespace = robot.request.namespace.strip("/")
            return f"/{namespace}/joint_states" if namespace else "/joint_states"
        return self._description_of(robot).joint_states_topic


def _with_attachments(urdf: str, files: Mapping[str, Path]) -> str:
    """The URDF with each mesh URI the bag carries as an attachment (not a package:// one:
    those resolve through the package folders made of them) pointing at its extracted file."""
    for uri, path in files.items():
        if not uri.startswith("package://"):
            urdf = urdf.replace(f'"{uri}"', f'"file://{path}"')
    return urdf


# ---------------------------------------------------------------------------- the player


class Player:
    """The bag, its clock, the thread that plays it, and the capabilities clients use."""

    def __init__(self, options: PlayOptions, bag: Bag, loop: asyncio.AbstractEventLoop,
                 workdir: Path) -> None:
        self.options = options
        self.bag = bag
        self.hub = Hub(loop)
        self.heavy = HeavyWork()
        names = DeviceNameRegistry()
        topics = bag.topics()
        self._tf_topics = {t: t.endswith("tf_static") for t, ty in topics.items()
                           if ty == TF_MESSAGE_TYPE}
        self.tf = TfLookups(self.hub, names)
        package_paths, attachment_files = _extract_attachments(bag, workdir)
        package_paths.update({name: Path(folder) for name, folder in options.package_paths})
        self.descriptions = self._read_descriptions()
        self._by_joint_topic: dict[str, list[_Description]] = {}
        for description in self.descriptions.values():
            self._by_joint_topic.setdefault(description.joint_states_topic, []).append(
                description)
        self.topics = PlayedTopics(self.hub, names, bag, self._show_topic)
        self.markers = PlayedMarkers(self.hub, names, tf=self.tf, bag=bag,
                                     package_paths=package_paths, on_new=self._show_topic)
        self.robots = PlayedRobots(self.hub, names, tf=self.tf,
                                   descriptions=self.descriptions,
                                   package_paths=package_paths,
                                   attachment_files=attachment_files)
        roots = (workdir, *package_paths.values())
        # The daemon's rule for who may write (here: move the clock): on loopback every
        # client; listening beyond it, only loopback clients (play takes no key).
        self.policy = SecurityPolicy(robot_dirs=tuple(str(r) for r in roots),
                                     resolve_type=bag_type_resolver(bag),
                                     beyond_loopback=not is_loopback_host(options.host))
        self.dispatcher = Dispatcher(PlayerGraph(bag), self.hub,
                                     [self.topics, self.tf, self.robots, self.markers,
                                      _Controls(self)],
                                     policy=self.policy,
                                     resolve_frame=self.tf.resolve_client_frame,
                                     resolve_file=self.robots.file_path, heavy=self.heavy)
        self.server = BridgeServer(self.hub, self.dispatcher.handle, host=options.host,
                                   port=options.port, limits=SessionLimits(),
                                   policy=self.policy, heavy=self.heavy)
        # The clock and what the thread is asked to do, under one condition.
        self._cond = threading.Condition()
        start = bag.start_ns + int(options.start_s * _NS_PER_S)
        self.clock = PlayClock(bag.start_ns, bag.end_ns, rate=options.rate,
                               paused=options.paused)
        self.clock.seek(start, time.monotonic_ns())
        self._seek_to: Optional[int] = self.clock.anchor_bag_ns  # the thread primes first
        self._seek_waiters: list[asyncio.Future[None]] = []  # seeks answered once primed
        self._shown: list[str] = []  # topics whose new subscriber waits for its message
        self._stopped = False
        self._failed = ""  # why the playing thread stopped (a bug), for the clock's ops
        self.ended = False
        self._warned: set[str] = set()
        self._thread: Optional[threading.Thread] = None  # started by start()

    # ------------------------------------------------------------------ set-up

    def _read_descriptions(self) -> dict[str, _Description]:
        """The bag's robot descriptions (std_msgs/String topics named *robot_description),
        each with the fixed joints its state publisher would latch on /tf_static."""
        found: dict[str, _Description] = {}
        for topic, ros_type in sorted(self.bag.topics().items()):
            if ros_type != DESCRIPTION_TYPE or not topic.endswith("robot_description"):
                continue
            first = next(iter(self.bag.messages(self.bag.start_ns, [topic])), None)
            msg = self.bag.decode(first) if first is not None else None
            if msg is None:
                continue
            base = topic.rsplit("/", 1)[0]
            description = _Description(topic, str(msg.data), f"{base}/joint_states")
            try:
                from bridge.robots.description import parse_urdf

                parsed = parse_urdf(description.text)
            except RobotError as error:
                log.warning("robot description on %s does not parse (robots from it are "
                            "refused at create_robot, saying why): %s", topic, error)
            else:
                description.tracker = JointStateTracker(parsed, self._warn_once)
                fixed = description.tracker.kinematics.fixed_joint_transforms()
                description.static = [
                    StampedTransform(f.parent, f.child, 0, f.translation, f.rotation)
                    for f in joint_frames(parsed, fixed)]
            found[topic] = description
        if not found:
            log.warning("%s holds no robot description (a std_msgs/String topic named "
                        "robot_description): robots cannot be shown; tf, images and the "
                        "other topics play", self.bag.path.name)
        return found

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            log.warning("%s", text)

    # ------------------------------------------------------------------ control (loop)

    def start(self) -> None:
        # It says its own failure (the clock's ops report it): a thread that cannot die.
        self._thread = start_thread("player", self._run, OnFailure.RESTART)

    def status(self) -> c.PlaybackResult:
        with self._cond:
            now = time.monotonic_ns()
            at = self.clock.bag_time(now)
            return c.PlaybackResult(
                bag=str(self.bag.path), start=c.Stamp.from_ns(self.bag.start_ns),
                end=c.Stamp.from_ns(self.bag.end_ns), time=c.Stamp.from_ns(at),
                offset=(at - self.bag.start_ns) / _NS_PER_S,
                duration=(self.bag.end_ns - self.bag.start_ns) / _NS_PER_S,
                rate=self.clock.rate, paused=self.clock.paused, loop=self.options.loop,
                ended=self.ended)

    def pause(self) -> c.PlaybackResult:
        with self._cond:
            if not self.clock.paused:
                self.clock.pause(time.monotonic_ns())
                self._cond.notify_all()
        return self.status()

    def resume(self) -> c.PlaybackResult:
        with self._cond:
            if self.ended:  # played to the end: from the start again
                self._seek(self.bag.start_ns)
            if self.clock.paused:
                self.clock.resume(time.monotonic_ns())
            self._cond.notify_all()
        return self.status()

    async def seek(self, offset_s: float) -> c.PlaybackResult:
        """Move the clock; answered once the state at the new time is sent, so a client
        has the poses at that time by the reply."""
        shown: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        with self._cond:
            self._refuse_if_failed()
            self._seek(self.bag.start_ns + int(offset_s * _NS_PER_S))
            self._seek_waiters.append(shown)
        await shown
        with self._cond:
            self._refuse_if_failed()
        return self.status()

    def _refuse_if_failed(self) -> None:  # under the condition
        if self._failed:
            raise CommandFailedError("op", "a player that is playing", "its playing thread "
                                     f"stopped on an error ({self._failed}; its log has it)",
                                     code=ErrorCode.INTERNAL)

    def _seek(self, bag_ns: int) -> None:  # under the condition
        self._seek_to = self.clock.seek(bag_ns, time.monotonic_ns())
        self.ended = False
        self._cond.notify_all()

    def set_rate(self, rate: float) -> c.PlaybackResult:
        with self._cond:
            self.clock.set_rate(rate, time.monotonic_ns())
            self._cond.notify_all()
        return self.status()

    def _show_topic(self, topic: str) -> None:
        with self._cond:
            self._shown.append(topic)
            self._cond.notify_all()

    def stop(self) -> None:
        with self._cond:
            self._stopped = True
            waiters, self._seek_waiters = self._seek_waiters, []
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=10)
        for waiter in waiters:
            waiter.cancel()

    def _answer(self, waiters: list[asyncio.Future[None]]) -> None:
        """The seeks the state just sent answers (player thread -> loop)."""
        for waiter in waiters:
            self.hub.call_soon(_settle, waiter)

    # ------------------------------------------------------------------ the thread

    def _run(self) -> None:
        try:
            self._play_all()
        except Exception as error:  # noqa: BLE001 - said; clients keep what they have
            log.exception("playing stopped: an unexpected error")
            with self._cond:
                self._failed = f"{type(error).__name__}: {error}"
                waiters, self._seek_waiters = self._seek_waiters, []
            self._answer(waiters)

    def _play_all(self) -> None:
        messages: Iterator[BagMessage] = iter(())
        pending: Optional[BagMessage] = None  # the next message, waiting for its time
        while True:
            with self._cond:
                if self._stopped:
                    return
                seek, self._seek_to = self._seek_to, None
                waiters, self._seek_waiters = self._seek_waiters, []
                shown, self._shown = self._shown, []
            if seek is not None:
                self._prime(seek, self._all_topics())
                self._answer(waiters)
                messages, pending = iter(self.bag.messages(seek + 1)), None
            elif shown:
                with self._cond:
                    at = self.clock.bag_time(time.monotonic_ns())
                self._prime(min(at, pending.log_time - 1) if pending else at, shown,
                            reset=False)
            if pending is None:
                pending = next(messages, None)
                if pending is None:
                    if self._at_end():
                        return
                    continue
            if self._wait_until(pending.log_time):
                pending = self._play_due(pending, messages)

    def _play_due(self, first: BagMessage, messages: Iterator[BagMessage]
                  ) -> Optional[BagMessage]:
        """Play ``first`` and the messages after it that are due already (a rate the
        thread barely holds, or kHz topics: up to `BURST`), together; the next message,
        not due yet (None: the bag's end, or a full burst)."""
        with self._cond:
            now = self.clock.bag_time(time.monotonic_ns())
        burst = [first]
        following: Optional[BagMessage] = None
        while len(burst) < BURST:
            following = next(messages, None)
            if following is None or following.log_time > now:
                break
            burst.append(following)
            following = None
        self._play_many(burst)
        return following

    def _at_end(self) -> bool:
        """The bag played out: loop, or wait for a seek (True: stopped)."""
        with self._cond:
            if self.options.loop:
                self._seek(self.bag.start_ns)
                return False
            self.ended = True
            self.clock.seek(self.bag.end_ns, time.monotonic_ns())
            log.info("played to the end of %s", self.bag.path.name)
            while not self._stopped and self._seek_to is None and not self._shown:
                self._cond.wait()
            return self._stopped

    def _wait_until(self, log_time: int) -> bool:
        """Wait for the clock to reach ``log_time``; False if a seek, a stop or a new
        subscriber came first (then this message is not played now)."""
        with self._cond:
            while True:
                if self._stopped or self._seek_to is not None or self._shown:
                    return False
                if self.clock.paused:
                    self._cond.wait()
                    continue
                wait_ns = self.clock.due_mono(log_time) - time.monotonic_ns()
                if wait_ns <= 0:
                    return True
                self._cond.wait(wait_ns / _NS_PER_S)

    def _all_topics(self) -> list[str]:
        return [*self._tf_topics, *self._by_joint_topic, *self.topics.subscribers,
                *self.markers.subscriptions]

    def _prime(self, t_ns: int, topics: list[str], *, reset: bool = True) -> None:
        """Show the state at ``t_ns``: each frame's, joint state topic's and subscribed
        topic's latest message at or before it (``reset``: the tf buffer starts afresh)."""
        static = [t for t, is_static in self._tf_topics.items() if is_static]
        dynamic = [t for t in topics if t in self._tf_topics and t not in static]
        others = [t for t in topics if t not in self._tf_topics]
        if reset:
            latched = [st for d in self.descriptions.values() for st in d.static]
            for message in self.bag.latest_before(t_ns, static, self._frames_of,
                                                  t_ns - self.bag.start_ns + 1):
                latched.extend(self._transforms(message))
            moving: list[StampedTransform] = []
            for message in self.bag.latest_before(t_ns, dynamic, self._frames_of,
                                                  PRIME_WINDOW_NS):  # frames: not known
                moving.extend(self._transforms(message))
            self.tf.reset(latched, moving)
        for message in self.bag.latest_before(t_ns, others, lambda m: (m.channel.topic,),
                                              t_ns - self.bag.start_ns + 1,
                                              keys=set(others)):
            self._play(message)

    def _frames_of(self, message: BagMessage) -> tuple[str, ...]:
        return tuple(t.child for t in self._transforms(message))

    def _transforms(self, message: BagMessage) -> list[StampedTransform]:
        """A tf message's transforms, read as the daemon reads /tf (its own reader of the
        plain CDR TFMessage, bridge/codecs/cdr.py); bytes it does not take go to the bag's
        decoder. The decoder still judges the channel's schema first (named once)."""
        if self.bag.decoder(message.channel) is None:
            return []
        try:
            return tf_cdr_to_transforms(message.data, self._decode_tf(message))
        except Exception as error:  # noqa: BLE001 - bad bytes: said once per topic
            self.bag.skip_message(message, error)
            return []

    def _decode_tf(self, message: BagMessage) -> Callable[[bytes], Any]:
        def decode(data: bytes) -> Any:  # None: not decodable, named by the bag already
            msg = self.bag.decode(message)
            return _NO_TRANSFORMS if msg is None else msg
        return decode

    def _play(self, message: BagMessage) -> None:
        self._play_many([message])

    def _play_many(self, messages: list[BagMessage]) -> None:
        """Messages due together. Their transforms (tf, and the links joint states move)
        are stored as one batch per kind, as the daemon stores a burst of /tf: the lookups
        they change are evaluated and sent once for the burst. Other topics go in order."""
        batch: dict[bool, list[StampedTransform]] = {False: [], True: []}
        for message in messages:
            topic = message.channel.topic
            static = self._tf_topics.get(topic)
            if static is not None:
                batch[static].extend(self._transforms(message))
                continue
            descriptions = self._by_joint_topic.get(topic)
            subscribed = topic in self.topics.subscribers
            marked = topic in self.markers.subscriptions
            if descriptions is None and not subscribed and not marked:
                self.bag.decoder(message.channel)  # a topic without schema is named once
                continue
            msg = self.bag.decode(message)
            if msg is None:
                continue
            if descriptions is not None and message.channel.type == JOINT_STATE_TYPE:
                batch[False].extend(self._joint_state(msg, message.log_time, descriptions))
            if subscribed:
                self.topics.play(topic, msg)
            if marked:
                self.markers.play(topic, msg)
        if self._seek_to is not None:
            return  # a seek came meanwhile: its state is shown next, not this burst's
        for static, transforms in batch.items():
            if transforms:
                self.tf.store_transforms(transforms, static=static)

    def _joint_state(self, msg: Any, log_time: int,
                     descriptions: list[_Description]) -> list[StampedTransform]:
        """The link transforms a joint state moves, stamped as robot_state_publisher does
        (the message's stamp; its log time if that is zero)."""
        stamp = msg.header.stamp
        stamp_ns = int(stamp.sec) * _NS_PER_S + int(stamp.nanosec) or log_time
        out: list[StampedTransform] = []
        for description in descriptions:
            tracker = description.tracker
            if tracker is None:
                continue
            moved = tracker.update(list(msg.name), [float(p) for p in msg.position])
            out.extend(StampedTransform(f.parent, f.child, stamp_ns, f.translation, f.rotation)
                       for f in joint_frames(tracker.description, moved))
        return out

    # ------------------------------------------------------------------ serving

    async def serve(self) -> None:
        await self.server.start(serving=False)
        self.start()
        await self.server.serve()

    async def close(self) -> None:
        self.stop()
        await self.server.close()
        self.dispatcher.close()
        self.heavy.close()
        self.bag.close()


@dataclass(frozen=True)
class _NoTransforms:
    transforms: tuple[Any, ...] = ()


_NO_TRANSFORMS = _NoTransforms()


def _settle(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)


class _Controls:
    """The playback ops (protocol/commands/playback.py) on the player's clock."""

    def __init__(self, player: Player) -> None:
        self._player = player

    def handlers(self) -> dict[type[Op], Handler]:
        player = self._player
        return {
            c.PlaybackStatus: lambda request, _: player.status(),
            c.PausePlayback: lambda request, _: player.pause(),
            c.ResumePlayback: lambda request, _: player.resume(),
            c.SeekPlayback: lambda request, _: player.seek(request.offset),
            c.SetPlaybackRate: lambda request, _: player.set_rate(request.rate),
        }

    def describe(self) -> list[dict[str, Any]]:
        return []

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        return {"playback": self._player.status(), "bag_problems": list(
            self._player.bag.problems)}

    def close(self) -> None:
        pass


def _extract_attachments(bag: Bag, workdir: Path) -> tuple[dict[str, Path], dict[str, Path]]:
    """The bag's attachments as files under ``workdir``: package:// ones in one folder per
    package (for the package resolver), others by their path; (package folders, URI ->
    file)."""
    packages: dict[str, Path] = {}
    files: dict[str, Path] = {}
    for name, data in bag.attachments():
        if name.startswith("package://"):
            package, _, rest = name[len("package://"):].partition("/")
            target = workdir / "packages" / package / rest
            packages[package] = workdir / "packages" / package
        else:
            relative = name.split("://", 1)[-1].lstrip("/")
            target = workdir / "files" / relative
        if ".." in Path(name.split("://", 1)[-1]).parts or not target.resolve().is_relative_to(
                workdir.resolve()):
            log.warning("attachment %r skipped: its name leaves the folder it goes in", name)
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
        files[name] = target
    if files:
        log.info("%d attachment(s) of %s extracted for robots' meshes", len(files),
                 bag.path.name)
    return packages, files


async def run_player(options: PlayOptions,
                     started: Optional[Callable[[Player], Any]] = None) -> None:
    """Play until SIGINT/SIGTERM."""
    from bridge.core.shutdown import StopSignals
    from bridge.playback.bag import open_bag

    loop = asyncio.get_running_loop()
    signals = StopSignals(loop, timeout_s=10.0)
    signals.install()
    bag = open_bag(options.bag)
    with tempfile.TemporaryDirectory(prefix="slicer-ros2-bridge-play-") as workdir:
        player = Player(options, bag, loop, Path(workdir))
        try:
            await player.serve()
            for problem in bag.problems:
                log.warning("%s", problem)
            log.info("playing %s: %.1f s, %d topics, from %.1f s at rate %g%s%s",
                     bag.path.name, (bag.end_ns - bag.start_ns) / _NS_PER_S,
                     len(bag.topics()), options.start_s, options.rate,
                     " (looping)" if options.loop else "",
                     " (paused)" if options.paused else "")
            log.info("listening on %s:%d (OpenIGTLink); playing %s", options.host,
                     player.server.port, bag.path)
            if started is not None:
                started(player)
            await signals.requested.wait()
            log.info("shutting down (%s)", signals.signal_name)
        finally:
            signals.watchdog.start()
            await player.close()
