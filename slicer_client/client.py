"""The Pythonic client: `connect()` -> `Client`, which hands out one object per resource.

    import slicer_client
    with slicer_client.connect("127.0.0.1", 18944) as ros:
        sub = ros.subscribe("/tool", "PoseStamped", callback=print)
        pub = ros.publisher("/cmd", "String"); pub.publish("hello")

Threads: callbacks never run on the transport's receive thread (slicer_client/events.py).
They run in `Client.Spin()` (the reference's name; `process_events` is the same) on the
thread that calls it, or, when nobody spins, on the client's dispatcher thread: one at a
time, in order, and free to call anything, blocking commands included. A GUI passes
``callbacks="spin"`` and spins from its own thread (a Qt timer): they then run there only.

Reconnection: if the daemon goes away the transport retries in the background; when it is
back, the client re-creates every resource in creation order (same objects, new device
names if they changed) and restores observers before user commands go through again.
"""

from __future__ import annotations

import dataclasses
import logging
import secrets
import ssl
import threading
import time
from pathlib import Path
from typing import (Any, Callable, Dict, Hashable, List, Mapping, Optional, Set, Tuple, TypeVar,
                    cast, overload)

import numpy as np

from protocol.auth import KeyFileError, proof, read_key_text
from protocol.freshness import DEFAULT_FRESHNESS_S, Freshness
from protocol.liveness import (DEAD_AFTER_S, HEARTBEAT_DEVICE, HEARTBEAT_INTERVAL_S,
                               stream_condition)
from protocol.messages import Command, Message
from protocol.naming import KEY_ROBOT, KEY_ROLE
from protocol import commands as c
from slicer_client.actions import (Accept, Action, Execute, GoalHandle, ServedAction,
                                   route_goal_event)
from slicer_client.bridge_state import REMOVE_OPS, BridgeSpec, BridgeState
from slicer_client.connection import DEFAULT_HOST, DEFAULT_PORT, CommandRefusedError
from slicer_client.events import EventDispatcher
from slicer_client.matrices import as_numpy
from slicer_client.recording import Recording
from slicer_client.resources import (MarkerSubscriber, ParameterClient, Publisher, Resource,
                                     Robot, Service, Subscriber, TfBroadcaster, TfLookup)
from slicer_client.transport import CommandFn, Transport, open_transport, request_with

__all__ = ["Client", "connect"]

log = logging.getLogger(__name__)

_R = TypeVar("_R", bound=Resource)
_Result = TypeVar("_Result", bound=c.Result)

# Earlier names of the modes: "thread" ran callbacks on the receive thread (now a dispatcher
# thread), "queue" left them to process_events (now Spin).
_MODES = {"auto": "auto", "thread": "auto", "spin": "spin", "queue": "spin"}


class Client:
    """A session with the daemon over any `Transport`; see the module docstring."""

    def __init__(self, transport: Transport, *, callbacks: str = "auto",
                 key: Optional[bytes] = None,
                 freshness: float = DEFAULT_FRESHNESS_S) -> None:
        if callbacks not in _MODES:
            raise ValueError(f"callbacks: expected 'auto' or 'spin', got {callbacks!r}")
        self._transport = transport
        self._key = key  # the daemon's key (protocol/auth.py): presented on every connection
        self.may_write = False  # what the daemon said of this connection, once connected
        self._events = EventDispatcher(_MODES[callbacks])
        self._lock = threading.RLock()
        self._resources: Dict[Tuple[str, ...], Resource] = {}  # creation order
        self._by_device: Dict[str, Resource] = {}
        self._latest: Dict[str, Message] = {}
        self._connection_callbacks: List[Callable[[bool, str], None]] = []
        self.errors: List[str] = []  # STATUS errors and unreadable messages, newest last
        self.daemon_info: Dict[str, Any] = {}
        # Stream values that came later than `freshness` seconds (a stalled link's
        # backlog): never made current (protocol/freshness.py). Counted in `late_dropped`.
        self._freshness = Freshness(freshness)
        self._valued: Set[str] = set()  # devices with a value on this connection
        self.late_dropped = 0
        self._logic: Any = None
        self._types: Dict[Tuple[str, str], c.TypeDescription] = {}
        # Actions: goals waiting for their events (by goal id), actions this client serves.
        self._goals: Dict[str, GoalHandle] = {}
        self._served_actions: Dict[str, ServedAction] = {}
        transport.set_listener(self)

    # --- transport listener (receive / reconnect threads) -------------------------------
    def on_message(self, message: Message) -> None:
        if isinstance(message.body, Command):
            self._on_daemon_command(message)
            return
        if route_goal_event(self._goals, message):
            return
        late = self._judge_freshness(message)
        if late is None:
            return
        condition = stream_condition(message)
        if condition is not None:  # a stream went stale or came back: not its value
            with self._lock:
                resource = self._by_device.get(message.device_name)
            if isinstance(resource, Subscriber):
                resource._set_stale(condition)
            return
        with self._lock:
            self._latest[message.device_name] = message
            resource = self._by_device.get(message.device_name)
            if resource is None and message.metadata.get(KEY_ROBOT):
                resource = self._resources.get((c.CreateRobot.op,
                                                message.metadata[KEY_ROBOT]))
            # Marker devices come and go with the markers: routed by their metadata.
            markers = [] if resource is not None or not message.metadata.get(
                KEY_ROLE, "").startswith("marker") else [
                r for r in self._resources.values()
                if isinstance(r, MarkerSubscriber) and r.owns(message)]
        if message.type_name == "STATUS" and getattr(message.body, "code", 1) != 1:
            self.errors.append(f"{message.device_name}: {getattr(message.body, 'text', '')}")
        for target in ([resource] if resource is not None else markers):
            try:
                target._handle(message)
            except Exception:  # noqa: BLE001 - one bad message must not stop the stream
                log.exception("handling %s for %r failed", message.type_name, target)
        if late and isinstance(resource, Subscriber):
            resource._set_stale(late)

    def _judge_freshness(self, message: Message) -> Optional[str]:
        """None: drop this message (a heartbeat, or a stream value that came late while a
        newer one was already here); else "" or, for the first value of a device on this
        connection that is old (a stream that has stopped), why it is stale."""
        stamp = message.message_id
        if not stamp:
            return ""
        now = time.monotonic_ns() // 1_000_000
        if message.device_name == HEARTBEAT_DEVICE:
            self._freshness.heartbeat(stamp, now)
            return None
        if message.type_name == "STATUS":
            return ""
        age = self._freshness.age_ms(stamp, now)
        device = message.device_name
        first = device not in self._valued
        self._valued.add(device)
        if age is None or age <= self._freshness.bound_ms:
            return ""
        if first:
            return f"its newest value is {age / 1000:.1f} s old"
        self.late_dropped += 1
        if self.late_dropped in (1, 10, 100) or self.late_dropped % 1000 == 0:
            log.warning("%d stream values came later than %.0f ms (a stalled link's "
                        "backlog?) and were dropped, the last on %s (%.0f ms late)",
                        self.late_dropped, self._freshness.bound_ms, device, age)
        return None

    def on_connected(self, command: CommandFn, first: bool) -> None:
        """Re-create everything (in order) on a new connection, then tell the user."""
        hello = c.Hello(client="slicer_client 0.1", heartbeat=HEARTBEAT_INTERVAL_S
                        if self._transport.watches_silence else None,
                        stamps=self._transport.drops_late_values,
                        display_hz=self._transport.display_hz)
        self.daemon_info = command(hello.op, hello.to_args())  # kept whole: the module shows it
        greeting = hello.parse_result(self.daemon_info)
        self._valued = set()
        if greeting.clock_ms:
            self._freshness.reset(greeting.clock_ms, time.monotonic_ns() // 1_000_000)
        if greeting.heartbeat:
            self._transport.expect_data_within(DEAD_AFTER_S)
        self._authenticate(command, greeting)
        with self._lock:
            resources = list(self._resources.values())
            self._by_device.clear()
        for resource in resources:
            self._apply(resource, command)
        for served in list(self._served_actions.values()):
            served.advertise(command)
        if not first:
            for callback in list(self._connection_callbacks):
                self.emit(callback, True, "")

    def _authenticate(self, command: CommandFn, greeting: c.HelloResult) -> None:
        """Present the key if the daemon asks for one; `may_write` says what came of it."""
        self.may_write = greeting.writes
        challenge = greeting.challenge
        if self._key is None or not challenge:
            if self._key is not None:
                log.warning("the daemon at %s takes no key: this connection %s", self.address,
                            "writes" if self.may_write else "is read-only")
            return
        nonce = secrets.token_hex(16)
        request = c.Authenticate(nonce=nonce, proof=proof(self._key, challenge, nonce))
        try:
            self.may_write = request_with(command, request).writes
        except CommandRefusedError as error:  # a wrong key: read-only, and said why
            log.warning("the daemon at %s refused this client's key: the connection is "
                        "read-only (%s)", self.address, error)
            self.errors.append(f"authenticate: {error}")

    def on_disconnected(self, reason: str) -> None:
        # The daemon cancels the goals of a client that leaves: their events never come.
        for handle in list(self._goals.values()):
            handle._on_event({"event": "result", "status": "lost",
                              "error": f"the connection to the daemon was lost ({reason}); "
                                       f"the daemon cancels the goals of a client that leaves"})
        for callback in list(self._connection_callbacks):
            self.emit(callback, False, reason)

    # --- event delivery ------------------------------------------------------------------
    def emit(self, callback: Callable[..., None], *args: Any) -> None:
        """Queue `callback(*args)` where callbacks run (never here, on the receive thread)."""
        self._events.post(callback, *args)

    def emit_newest(self, key: Hashable, callback: Callable[..., None], *args: Any) -> None:
        """`emit`, replacing the arguments of the one queued under `key` that has not run
        yet (a stream's newest value)."""
        self._events.post_newest(key, callback, *args)

    def process_events(self, timeout: float = 0.0, max_events: Optional[int] = None) -> int:
        """Run the callbacks queued so far on the calling thread (waiting up to `timeout` s
        for the first), then the tick hooks; returns how many callbacks ran."""
        return self._events.spin(timeout, max_events)

    def serve_other_threads(self) -> None:
        """Let the transport run what other threads handed to this thread (a caller that
        waits here for another thread's command calls it between waits)."""
        self._transport.serve_other_threads()

    def Spin(self) -> None:  # noqa: N802 - the reference logic's name
        """The reference's ``logic.Spin()``: run what arrived since the last spin, here."""
        self._events.spin()

    @property
    def events(self) -> EventDispatcher:
        return self._events

    def on_connection_change(self, callback: Callable[[bool, str], None]) -> None:
        """`callback(connected, reason)` after a loss and after each re-sync."""
        self._connection_callbacks.append(callback)

    # --- resources -----------------------------------------------------------------------
    def _apply(self, resource: Resource, command: CommandFn) -> None:
        result = command(resource.spec.op, resource.spec.args)
        resource._created(result)
        restore = getattr(resource, "_restore", None)
        if restore is not None:
            restore(command)
        if resource.spec.kept:
            command(*resource.spec.keep_command())
        with self._lock:
            for device in resource.devices():
                self._by_device[device] = resource
            # Messages that arrived before the reply told us their device (a late joiner
            # gets the current state at once): hand over the latest of each.
            early = [self._latest[d] for d in resource.devices() if d in self._latest]
        for message in early:
            resource._handle(message)

    def _add(self, resource: _R) -> _R:
        key = resource.spec.key
        with self._lock:
            existing = self._resources.get(key)
        if existing is not None and existing.spec.args == resource.spec.args:
            # Creating is idempotent, as on the daemon. The key starts with the op, and each
            # op has one resource class: `existing` is a `_R` too.
            return cast(_R, existing)
        self._apply(resource, self.command)
        with self._lock:
            self._resources[key] = resource
        return resource

    def remove_resource(self, resource: Resource) -> None:
        op, args = resource.spec.remove_command()
        try:
            self.command(op, args)
        finally:
            with self._lock:
                self._resources.pop(resource.spec.key, None)
                for device in resource.devices():
                    self._by_device.pop(device, None)

    def keep_resource(self, resource: Resource) -> None:
        self.command(*resource.spec.keep_command())
        resource.spec = dataclasses.replace(resource.spec, kept=True)
        self.spec_changed(resource)

    def spec_changed(self, resource: Resource) -> None:
        """A resource's follow-up commands changed (kept for re-sync and saving)."""

    def subscribe(self, topic: str, type: str, *, qos: Optional[Mapping[str, Any]] = None,
                  rate_hz: Optional[float] = None,
                  callback: Optional[Callable[[Any], None]] = None,
                  messages: bool = False, native: bool = True) -> Subscriber:
        """Subscribe to a ROS topic. `type`: "String", "PoseStamped", "pkg/msg/Type"...
        `callback(value)` on every message (see the module docstring for the thread).
        `messages`: also keep the newest message whole (`Subscriber.last_whole`, sent at
        most once a display frame), where the transport can carry it (not 3D Slicer's
        connector: then the native stream only). `native=False` (with `messages`): the
        whole messages only, none of the native values (`Subscriber`)."""
        messages = messages and self._transport.carries_whole_messages
        sub: Subscriber = self._add(Subscriber(self, topic, type, qos=qos, rate_hz=rate_hz,
                                               messages=messages, native=native))
        if callback is not None:
            sub.add_callback(callback)
        return sub

    def publisher(self, topic: str, type: str, *,
                  qos: Optional[Mapping[str, Any]] = None, frame: Optional[str] = None,
                  labels_topic: Optional[str] = None) -> Publisher:
        """A ROS publisher this client feeds (`Publisher.publish` / `send`). ``frame``:
        the frame id of what it publishes (judged by the daemon's frame globs);
        ``labels_topic``: where markups labels go."""
        return self._add(Publisher(self, topic, type, qos=qos, frame=frame,
                                   labels_topic=labels_topic))

    def publish_model(self, topic: str, model: Any, *, frame: str,
                      type: str = "shape_msgs/msg/Mesh", ns: Optional[str] = None,
                      marker_id: Optional[int] = None,
                      color: Optional[Any] = None) -> Publisher:
        """Send a model made in Slicer (a `PolyData` in mm, or (points mm, triangles)) to
        ROS on ``topic`` as a shape_msgs/Mesh (default) or a visualization_msgs/Marker
        TRIANGLE_LIST, in metres, in ``frame``. Streams: a refusal by the daemon (bad
        polygons, too large, a denied frame) comes back as a STATUS in `errors`."""
        pub = self.publisher(topic, type, frame=frame)
        pub.send_model(model, ns=ns, marker_id=marker_id, color=color)
        return pub

    def publish_points(self, topic: str, points: Any, labels: Optional[Any] = None, *,
                       frame: str, type: str = "PoseArray",
                       labels_topic: Optional[str] = None) -> Publisher:
        """Send markups points ((N, 3) mm, labels) to ROS on ``topic`` as a PoseArray
        (default), one PointStamped per point, or a nav_msgs/Path (a line or curve), in
        metres, in ``frame``; labels go to ``labels_topic`` as a JSON list."""
        pub = self.publisher(topic, type, frame=frame, labels_topic=labels_topic)
        pub.send_points(points, labels)
        return pub

    def parameters(self, node: str) -> ParameterClient:
        return self._add(ParameterClient(self, node))

    def tf_lookup(self, parent: str, child: str, *, rate_hz: Optional[float] = None,
                  callback: Optional[Callable[[np.ndarray], None]] = None) -> TfLookup:
        lookup: TfLookup = self._add(TfLookup(self, parent, child, rate_hz=rate_hz))
        if callback is not None:
            lookup.add_callback(callback)
        return lookup

    def tf_broadcaster(self, parent: str, child: str, *, static: bool = False
                       ) -> TfBroadcaster:
        return self._add(TfBroadcaster(self, parent, child, static=static))

    def service(self, service: str, type: str) -> Service:
        return Service(self, service, type)

    def record(self, path: str, topics: Optional[List[str]] = None, *,
               overwrite: bool = False, compression: str = "none",
               timeout: float = 10.0) -> Recording:
        """Have the daemon record a ROS 2 bag (MCAP) at ``path``, an absolute path on the
        daemon's machine: the ``topics`` given, or what it bridges (tf, robots, every
        subscribed and published topic). `Recording.stop()` finishes it. It writes: a
        read-only connection is refused (FORBIDDEN)."""
        return Recording.start(self.request, path, topics, overwrite=overwrite,
                               compression=compression, timeout=timeout)

    def action(self, name: str, type: str) -> Action:
        """A ROS action to send goals to: ``ros.action(name, type).send_goal(goal,
        feedback=cb)`` returns a `GoalHandle` (``result(timeout)``, ``cancel()``)."""
        return Action(self, name, type, self._goals)

    def serve_action(self, name: str, type: str, execute: Execute, *,
                     goal_timeout: float = 300.0, accept: Optional[Accept] = None
                     ) -> ServedAction:
        """Serve a ROS action from this client: `execute(goal, feedback, cancelled)` runs
        for each goal in a worker thread and returns ``(status, result)`` (see
        slicer_client/actions.py). The daemon aborts a goal not ended in `goal_timeout` s.
        `accept(goal)`, if given, decides first: False or ``(False, reason)`` rejects the
        goal (the ROS client gets REJECTED); it must answer within 10 s."""
        served = ServedAction(self, name, type, execute, goal_timeout=goal_timeout,
                              accept=accept)
        served.advertise(self.command)
        with self._lock:
            self._served_actions[served.device] = served
        return served

    def stop_serving_action(self, served: ServedAction) -> None:
        with self._lock:
            self._served_actions.pop(served.device, None)
        served.unadvertise()

    def _on_daemon_command(self, message: Message) -> None:
        """A COMMAND the daemon sends (receive thread): a goal or cancel of a served action."""
        with self._lock:
            served = self._served_actions.get(message.device_name)
        if served is None:
            log.warning("a %s COMMAND for %r, which this client does not serve",
                        getattr(message.body, "name", "?"), message.device_name)
            return
        try:
            served._on_command(message)
        except Exception:  # noqa: BLE001 - a bad command must not stop the receive thread
            log.exception("handling a command for %r failed", message.device_name)

    def robot(self, name: str, *, node: str = "/robot_state_publisher",
              parameter: str = "robot_description", fixed_frame: Optional[str] = None,
              tf_prefix: str = "", namespace: str = "",
              source: Optional[Mapping[str, Any]] = None,
              callback: Optional[Callable[[str, str, Any], None]] = None,
              timeout: float = 30.0, wait: bool = False) -> Robot:
        """Load a robot from its URDF (default: /robot_state_publisher's
        robot_description). Its meshes and link transforms then arrive in `Robot.links`.

        A description that is not there (its node not on the ROS graph, its parameter
        not set, nothing on its topic) raises `CommandRefusedError` (``NOT_FOUND``, naming
        the node and parameter); ``wait=True`` creates the robot anyway, to load when its
        description appears (`Robot.state` "waiting"). A re-sync after a reconnect always
        waits: the robot was there before."""
        robot = Robot(self, name, node=node, parameter=parameter, fixed_frame=fixed_frame,
                      tf_prefix=tf_prefix, namespace=namespace, source=source)
        if callback is not None:
            robot.add_callback(callback)
        key = robot.spec.key
        with self._lock:
            existing = self._resources.get(key)
        if existing is not None and existing.spec.args == robot.spec.args:
            return existing  # type: ignore[return-value]
        # Meshes may follow the reply at once: index by robot name before the reply.
        with self._lock:
            self._resources[key] = robot
        try:
            self._apply(robot, lambda op, args: self.command(op, {**args, "wait": wait},
                                                             timeout=timeout))
        except BaseException:
            with self._lock:
                self._resources.pop(key, None)
            raise
        return robot

    def markers(self, topic: str, type: str, fixed_frame: str, *,
                qos: Optional[Mapping[str, Any]] = None,
                callback: Optional[Callable[..., None]] = None) -> MarkerSubscriber:
        """Show an RViz marker topic (`type` Marker or MarkerArray) or a Path,
        PolygonStamped or PointStamped topic as models placed by tf in `fixed_frame`.
        `callback(kind, ...)`: see `MarkerSubscriber`."""
        with self._lock:
            existed = (c.CreateMarkerSubscriber.op, topic) in self._resources
        resource: MarkerSubscriber = self._add(MarkerSubscriber(self, topic, type, fixed_frame,
                                                                qos=qos))
        if callback is not None:
            resource.add_callback(callback)
        if not existed:
            # What arrived before the reply named the topic; the topic's list of live
            # markers last, so models of markers deleted since are dropped again.
            with self._lock:
                early = sorted((m for m in self._latest.values()
                                if m.metadata.get(KEY_ROLE, "").startswith("marker")
                                and resource.owns(m)),
                               key=lambda m: m.metadata.get(KEY_ROLE) == "marker_topic")
            for message in early:
                resource._handle(message)
        return resource

    def resources(self) -> List[Resource]:
        with self._lock:
            return list(self._resources.values())

    def find(self, op: str, *identity: str) -> Optional[Resource]:
        with self._lock:
            return self._resources.get((op, *identity))

    def remove_bridge(self, op: str, *identity: str) -> bool:
        """Remove the bridge `op` (its create op) with `identity` made: this client's own
        resource, or one the daemon keeps from an earlier connection or another client (the
        daemon's rules decide: docs/security.md). False if the daemon has no such bridge;
        a refusal raises `CommandRefusedError`."""
        resource = self.find(op, *identity)
        if resource is not None:
            try:
                resource.remove()
            except CommandRefusedError as error:
                if error.code != c.ErrorCode.NOT_FOUND:
                    raise
                return False
            return True
        if op not in REMOVE_OPS:
            raise ValueError(f"op: expected one of {', '.join(REMOVE_OPS)}, got {op!r}")
        remove_op, fields = REMOVE_OPS[op]
        if len(identity) != len(fields):
            raise ValueError(f"identity: expected {', '.join(fields)}, got {identity!r}")
        try:
            self.command(remove_op, dict(zip(fields, identity)))
        except CommandRefusedError as error:
            if error.code == c.ErrorCode.NOT_FOUND:
                return False
            raise
        return True

    # --- state (re-sync list, scene saving) ---------------------------------------------
    def state(self) -> BridgeState:
        return BridgeState(tuple(r.spec for r in self.resources()))

    def restore(self, state: BridgeState) -> List[Resource]:
        """Create what a saved `BridgeState` lists, in order."""
        made: List[Resource] = []
        for spec in state.specs:
            made.append(self._from_spec(spec))
        return made

    def _from_spec(self, spec: BridgeSpec) -> Resource:
        a = spec.args
        resource: Resource
        if spec.op == c.CreateSubscriber.op:
            resource = self.subscribe(a["topic"], a["type"], qos=a.get("qos"),
                                      rate_hz=a.get("rate_hz"),
                                      messages=bool(a.get("messages", False)))
        elif spec.op == c.CreatePublisher.op:
            resource = self.publisher(a["topic"], a["type"], qos=a.get("qos"),
                                      frame=a.get("frame"), labels_topic=a.get("labels_topic"))
        elif spec.op == c.CreateParameterClient.op:
            params = self.parameters(a["node"])
            for op, args in spec.then:
                if op == c.ObserveParameters.op:
                    params.observe(args.get("names", []),
                                   all_changes=bool(args.get("all_changes", False)))
            resource = params
        elif spec.op == c.CreateTfLookup.op:
            resource = self.tf_lookup(a["parent"], a["child"], rate_hz=a.get("rate_hz"))
        elif spec.op == c.CreateTfBroadcaster.op:
            resource = self.tf_broadcaster(a["parent"], a["child"],
                                           static=bool(a.get("static", False)))
        elif spec.op == c.CreateRobot.op:
            resource = self.robot(a["name"], source=a.get("source"),
                                  fixed_frame=a.get("fixed_frame"),
                                  tf_prefix=a.get("tf_prefix", ""),
                                  namespace=a.get("namespace", ""), wait=True)
        elif spec.op == c.CreateMarkerSubscriber.op:
            resource = self.markers(a["topic"], a["type"], a["fixed_frame"], qos=a.get("qos"))
        else:  # a bridge kind without a Pythonic class yet: its spec alone re-creates it
            resource = self._add(Resource(self, spec))
        if spec.kept and not resource.spec.kept:
            resource.keep()
        return resource

    # --- direct commands -----------------------------------------------------------------
    @property
    def address(self) -> str:
        return self._transport.address

    @property
    def connected(self) -> bool:
        return self._transport.connected

    @property
    def transport(self) -> Transport:
        return self._transport

    def command(self, op: str, arguments: Optional[Mapping[str, Any]] = None, *,
                timeout: float = 10.0) -> Dict[str, Any]:
        """Any op of protocol/README.md; returns its result or raises a typed error."""
        return self._transport.command(op, arguments, timeout=timeout)

    @overload
    def request(self, request: c.Answered[_Result], *, timeout: float = 10.0) -> _Result: ...
    @overload
    def request(self, request: c.Op, *, timeout: float = 10.0) -> Dict[str, Any]: ...
    def request(self, request: Any, *, timeout: float = 10.0) -> Any:
        """Send a request built from the protocol's op classes (``c.Publish(topic=...,
        value=...)``): its typed result if the op declares one (`c.Answered`), else the
        reply's result object. Raises as `command` does, or `c.ResultFormatError`."""
        return request_with(self.command, request, timeout=timeout)

    def describe_type(self, type_name: str, kind: str = "message") -> c.TypeDescription:
        """What an interface type installed in the daemon's environment is made of (kept:
        types do not change while the daemon runs)."""
        key = (type_name, kind)
        described = self._types.get(key)
        if described is None:
            described = c.TypeDescription.from_dict(
                self.request(c.DescribeType(type=type_name, kind=kind)))
            self._types[key] = described
        return described

    def send(self, message: Message) -> None:
        self._transport.send(message)

    def list_bridges(self) -> Dict[str, Any]:
        return self.request(c.ListBridges())

    def list_topics(self) -> List[Dict[str, Any]]:
        return list(self.request(c.ListTopics()).topics)

    def list_services(self) -> List[Dict[str, Any]]:
        return list(self.request(c.ListServices()).services)

    def lookup_transform(self, parent: str, child: str, *, timeout: float = 0.5,
                         stamp: Optional[Tuple[int, int]] = None) -> np.ndarray:
        """parent -> child now (or at `stamp`), 4x4 mm; waits up to `timeout` s for tf."""
        at = None if stamp is None else c.Stamp(sec=int(stamp[0]), nanosec=int(stamp[1]))
        result = self.request(c.LookupTransform(parent=parent, child=child, time=at,
                                                timeout=timeout), timeout=timeout + 5.0)
        return as_numpy(result.matrix, field="lookup_transform.matrix", rigid=False)

    # --- a player's clock (`slicer-ros2-bridge play BAG`; the live daemon refuses these) --
    def playback(self) -> c.PlaybackResult:
        """The player's clock: the bag's time now (``time``, ``offset`` s from its start),
        its ``rate``, and whether it is ``paused``, loops or has ``ended``."""
        return self.request(c.PlaybackStatus())

    def pause(self) -> c.PlaybackResult:
        return self.request(c.PausePlayback())

    def resume(self) -> c.PlaybackResult:
        return self.request(c.ResumePlayback())

    def seek(self, offset: float) -> c.PlaybackResult:
        """Play from ``offset`` seconds into the bag; what is shown next is the state then
        (each stream's last message at or before it)."""
        return self.request(c.SeekPlayback(offset=float(offset)))

    def set_rate(self, rate: float) -> c.PlaybackResult:
        return self.request(c.SetPlaybackRate(rate=float(rate)))

    def latest(self, device: str) -> Optional[Message]:
        with self._lock:
            return self._latest.get(device)

    # --- the reference-compatible facade -------------------------------------------------
    @property
    def logic(self) -> Any:
        """The reference's module logic over this client (slicer_client/reference):
        ``Spin()``, ``GetDefaultROS2Node()``, ``AddRobot``..."""
        if self._logic is None:
            from slicer_client.reference.logic import ROS2Logic
            self._logic = ROS2Logic(self)
        return self._logic

    def GetDefaultROS2Node(self) -> Any:  # noqa: N802 - the reference's name
        """The CamelCase facade's default node: the same resources, reference names."""
        return self.logic.GetDefaultROS2Node()

    # --- lifetime ------------------------------------------------------------------------
    def close(self) -> None:
        self._transport.close()
        self._events.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "connected" if self.connected else "disconnected"
        return f"<slicer_client.Client {self.address} {state}, {len(self._resources)} bridges>"


def connect(host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *, reconnect: bool = True,
            callbacks: str = "auto", key_file: Optional[str] = None,
            freshness: float = DEFAULT_FRESHNESS_S,
            tls: bool = False, ca_file: Optional[str] = None,
            retry_interval: float = 0.5, max_interval: float = 5.0,
            connect_timeout: float = 3.0) -> Client:
    """Connect to the daemon. Raises `DaemonUnreachableError` (naming host:port and how to
    start the daemon) if nothing listens there.

    `key_file`: the daemon's key (`slicer-ros2-bridge keygen`), presented on every
    connection: a daemon with a key lets only its holders write (docs/deployment.md).
    `freshness`: a stream value that arrives later than this many seconds (a stalled
    link's backlog) is dropped, never made current (protocol/freshness.py).
    `tls`: connect to the daemon's TLS port, checking its certificate against `ca_file`
    (its own certificate, for a self-signed one) or the system's authorities."""
    key = read_key_file(key_file) if key_file is not None else None
    context = tls_context(ca_file) if tls else None
    transport = open_transport(host, port, reconnect=reconnect, retry_interval=retry_interval,
                               max_interval=max_interval, connect_timeout=connect_timeout,
                               tls=context)
    try:
        return Client(transport, callbacks=callbacks, key=key, freshness=freshness)
    except BaseException:
        transport.close()
        raise


def read_key_file(path: str) -> bytes:
    """The key in a key file; `KeyFileError` naming the file if it is not one."""
    try:
        text = Path(path).read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as error:
        raise KeyFileError(f"{path}: expected a key file (`slicer-ros2-bridge keygen "
                           f"{path}`), got {error}") from None
    return read_key_text(text, path)


def tls_context(ca_file: Optional[str]) -> ssl.SSLContext:
    """A client's TLS context: the daemon's certificate is checked, names included."""
    return ssl.create_default_context(cafile=ca_file)
