"""One object per daemon-side resource: what a `Client` hands out (through the
`ResourceOwner` protocol, so this module does not import the client).

Each resource knows the command that creates it (its `BridgeSpec`, replayed after a
reconnect), the device name the daemon answered with, and how to read the messages that
arrive for it. A resource's state changes as messages arrive (on the receive thread, which
only stores them: values are decoded when read); its callbacks run where the client runs
callbacks, never on the receive thread (`Client.Spin()` or its dispatcher: events.py).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import threading
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from protocol import commands as c
from protocol.commands.fields import Args
from protocol.conversions import quaternion_to_rotation
from protocol.messages import (Message, Point, PointElement, PolyData, Status, StatusCode,
                               String, TrackingData, Transform, cells_from_array)
from protocol.naming import (KEY_COLOR, KEY_COUNT, KEY_FRAME, KEY_LINK, KEY_LINK_COUNT,
                             KEY_LINK_DEVICES,
                             KEY_MARKER_ID, KEY_MARKER_NS, KEY_MARKER_TYPE, KEY_MARKERS,
                             KEY_PARENT_DEVICE, KEY_POSITION, KEY_ROLE, KEY_TOPIC, KEY_VISUAL,
                             KEY_VISUAL_COUNT, KEY_WARNINGS)
from slicer_client.bridge_state import BridgeSpec
from slicer_client.errors import (BridgeClientError, IkFailedError, PointsError,
                                  RobotNotLoadedError)
from slicer_client.matrices import as_numpy, as_rows
from slicer_client.owner import ResourceOwner
from slicer_client.transport import CommandFn, request_with
from slicer_client.values import value_from_message

__all__ = ["MarkerItem", "MarkerSubscriber", "ParameterClient", "Publisher", "Resource",
           "Robot", "RobotLink", "Service", "Subscriber", "TfBroadcaster", "TfLookup",
           "markups_point_body", "model_polydata", "parameter_to_python"]

Callback = Callable[..., None]
log = logging.getLogger("slicer_client")


def _qos(qos: Optional[Mapping[str, Any]]) -> c.QoS:
    return c.QoS(**dict(qos or {}))  # TypeError names an unknown field


class Resource:
    """Base: creation spec, device name, callbacks, removal."""

    def __init__(self, client: ResourceOwner, spec: BridgeSpec) -> None:
        self._client = client
        self.spec = spec
        self.device: str = ""
        self.info: Dict[str, Any] = {}
        self.removed = False
        self._callbacks: List[Callback] = []
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)

    # --- plumbing the client calls ------------------------------------------------------
    def _created(self, result: Mapping[str, Any]) -> None:
        self.info = dict(result)
        self.device = str(result.get("device", ""))

    def devices(self) -> Tuple[str, ...]:
        return (self.device,) if self.device else ()

    def _handle(self, message: Message) -> None:
        """A message for one of `devices()` (receive thread)."""

    def _notify(self, *args: Any) -> None:
        for callback in list(self._callbacks):
            self._client.emit(callback, *args)

    def _notify_newest(self, make_args: Callable[[], Tuple[Any, ...]]) -> None:
        """Call the callbacks with ``make_args()`` of a stream's newest value, made where
        they run (a message is decoded there, not on the receive thread), once for all of
        them; a value that comes while they wait to run replaces this one."""
        callbacks = list(self._callbacks)
        if callbacks:
            self._client.emit_newest((id(self), "value"), _call_each, callbacks, make_args)

    def _wait(self, predicate: Callable[[], bool], timeout: float, what: str) -> None:
        with self._changed:
            if not self._changed.wait_for(predicate, timeout):
                raise TimeoutError(f"{what}: nothing within {timeout} s (daemon at "
                                   f"{self._client.address}, device {self.device!r})")

    # --- user API -----------------------------------------------------------------------
    def add_callback(self, callback: Callback) -> Callback:
        self._callbacks.append(callback)
        return callback

    def remove_callback(self, callback: Callback) -> None:
        if callback in self._callbacks:
            self._callbacks.remove(callback)

    def remove(self) -> None:
        """Remove it daemon-side and forget it (it is no longer re-created)."""
        if not self.removed:
            self._client.remove_resource(self)
            self.removed = True

    def keep(self) -> None:
        """Have the daemon keep it when this client is gone (a bridge ends with the last
        client holding it otherwise). Any client may still remove it; saved state and a
        re-sync after a reconnect keep it again."""
        self._client.keep_resource(self)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.spec.key[1:]} device={self.device!r}>"


class Subscriber(Resource):
    """A ROS subscription streamed to this client (the reference's subscriber node).

    With ``messages``, this client also gets the newest message whole, at most once a
    display frame (the daemon's message stream: lossless JSON in ROS units, with the
    subscription's own message count), kept as `last_whole`; `add_whole_callback` hears of
    each. Images and point clouds have no such
    stream (their native one is whole): `message_device` stays empty.

    With ``messages`` and ``native=False``, this client takes the whole messages only: the
    daemon sends it none of the native values (a message it reads once, not twice), so
    `last_value`, `count`, value callbacks and `wait_for_message` are not fed (their use
    raises); images and point clouds keep their native stream (`native` is then True)."""

    def __init__(self, client: ResourceOwner, topic: str, type: str, *,
                 qos: Optional[Mapping[str, Any]] = None,
                 rate_hz: Optional[float] = None, messages: bool = False,
                 native: bool = True) -> None:
        native = native or not messages  # values come one way at least
        super().__init__(client, BridgeSpec.of(c.CreateSubscriber(
            topic=topic, type=type, qos=_qos(qos), rate_hz=rate_hz, messages=messages,
            native=native)))
        self.topic = topic
        self.type = type
        self.native = native
        self.count = 0  # messages this client received (the daemon may coalesce a burst)
        self.last_message: Optional[Message] = None
        self._last_value: Tuple[Optional[Message], Any] = (None, None)  # decoded once
        self.message_device = ""
        self.last_whole: Optional[Message] = None
        # Messages the daemon's subscription received, as its message stream said last.
        self.received_by_daemon = 0
        self._whole_callbacks: List[Callable[[Message], None]] = []
        # Why the stream is stale (its publisher gone, silent past its period), as the
        # daemon said; "" while it is live.
        self.stale = ""
        self._stale_callbacks: List[Callable[[str], None]] = []

    def _created(self, result: Mapping[str, Any]) -> None:
        super()._created(result)
        self.message_device = str(result.get("message_device", ""))
        self.received_by_daemon = int(result.get("messages", 0) or 0)
        if not self.message_device:
            self.native = True  # no message stream (an image): its values are its messages

    def _require_native(self, what: str) -> None:
        if not self.native:
            raise ValueError(f"{what}: this subscriber of {self.topic} reads its messages "
                             "whole only (native=False); use last_whole, wait_for_whole or "
                             "add_whole_callback, or subscribe with native=True")

    def add_callback(self, callback: Callback) -> Callback:
        self._require_native("add_callback")
        return super().add_callback(callback)

    def devices(self) -> Tuple[str, ...]:
        return tuple(d for d in (self.device, self.message_device) if d)

    def add_stale_callback(self, callback: Callable[[str], None]) -> None:
        """`callback(reason)` when the stream goes stale, `callback("")` when it is live
        again (where callbacks run, never on the receive thread)."""
        self._stale_callbacks.append(callback)

    def _set_stale(self, reason: str) -> None:
        with self._changed:
            if reason == self.stale:
                return
            self.stale = reason
            self._changed.notify_all()
        for callback in list(self._stale_callbacks):
            self._client.emit(callback, reason)

    def add_whole_callback(self, callback: Callable[[Message], None]) -> None:
        """`callback(message)` for each message of the message stream, at most one a
        display frame (where callbacks run, never on the receive thread)."""
        self._whole_callbacks.append(callback)

    def wait_for_whole(self, predicate: Optional[Callable[[Message], bool]] = None,
                       timeout: float = 10.0) -> Message:
        """Block until the message stream's newest (satisfying `predicate`) has arrived.
        The daemon sends the newest message whole at most once a display frame."""
        def ready() -> bool:
            return self.last_whole is not None and (predicate is None
                                                    or bool(predicate(self.last_whole)))
        self._wait(ready, timeout, f"a whole message on {self.topic}")
        assert self.last_whole is not None
        return self.last_whole

    @property
    def ros_type(self) -> str:
        # The daemon's (it looks bare names up among installed packages), else the grammar's.
        return str(self.info.get("type") or c.resolve_message_type(self.type))

    def _handle(self, message: Message) -> None:
        if self.message_device and message.device_name == self.message_device:
            with self._changed:
                self.last_whole = message
                self.received_by_daemon = _count_of(message, self.received_by_daemon)
                self._changed.notify_all()
            whole = list(self._whole_callbacks)
            if whole:
                self._client.emit_newest((id(self), "whole"), _call_each, whole,
                                         lambda: (message,))
            return
        if self.stale:
            self._set_stale("")  # a new message: live again, whatever the STATUS says later
        with self._changed:
            self.count += 1
            self.last_message = message
            self._changed.notify_all()
        self._notify_newest(lambda: (self._value_of(message),))

    def _value_of(self, message: Message) -> Any:
        cached, value = self._last_value
        if cached is not message:
            value = value_from_message(message)
            self._last_value = (message, value)
        return value

    @property
    def last_value(self) -> Any:
        """The last message as a Python value: str/bool/int/float, a 4x4 numpy matrix in
        mm, a list/dict for JSON types, numpy pixels, PolyData; None before the first."""
        self._require_native("last_value")
        message = self.last_message
        return None if message is None else self._value_of(message)

    def wait_for_message(self, timeout: float = 10.0,
                         predicate: Optional[Callable[[Any], bool]] = None) -> Any:
        """Block until a message (satisfying `predicate` on its value) has arrived."""
        self._require_native("wait_for_message")

        def ready() -> bool:
            return self.last_message is not None and (
                predicate is None or bool(predicate(value_from_message(self.last_message))))
        try:
            self._wait(ready, timeout, f"a message on {self.topic}")
        except TimeoutError as error:
            unpublished = self._unpublished()
            if not unpublished:
                raise
            raise TimeoutError(f"{error}; {unpublished}") from None
        return self.last_value

    def _unpublished(self) -> str:
        """"no publisher of <topic> on the ROS graph" if the daemon's graph has none of
        this topic (the likely reason nothing came), else ""."""
        topic = str(self.info.get("topic") or self.topic)
        try:
            listed = self._client.request(c.ListTopics(), timeout=10.0).topics
        except BridgeClientError as error:
            log.info("cannot ask the daemon for the publishers of %s: %s", topic, error)
            return ""
        publishers = sum(int(entry.get("publishers", 0)) for entry in listed
                         if entry.get("topic") == topic)
        return f"no publisher of {topic} on the ROS graph" if publishers == 0 else ""

    def last_message_yaml(self, timeout: float = 10.0) -> str:
        """The daemon's last message as YAML (`ros2 topic echo` style); "" before any."""
        return self._last_yaml(timeout).text

    def daemon_count(self, timeout: float = 10.0) -> int:
        """How many messages the daemon's subscription received (exact, not coalesced)."""
        return self._last_yaml(timeout).count

    def _last_yaml(self, timeout: float) -> c.GetLastMessageResult:
        return self._client.request(c.GetLastMessage(topic=self.topic, format="yaml"),
                                    timeout=timeout)


class Publisher(Resource):
    """A ROS publisher fed by this client. ``frame``: the frame id of what it publishes (a
    model, markups, a curve); ``labels_topic``: where markups labels go (a std_msgs/String
    JSON list per POINT sent; PoseArray and PointStamped have no field for them)."""

    def __init__(self, client: ResourceOwner, topic: str, type: str, *,
                 qos: Optional[Mapping[str, Any]] = None, frame: Optional[str] = None,
                 labels_topic: Optional[str] = None) -> None:
        super().__init__(client, BridgeSpec.of(c.CreatePublisher(
            topic=topic, type=type, qos=_qos(qos), frame=frame, labels_topic=labels_topic)))
        self.topic = topic
        self.type = type
        self.frame = frame
        self.labels_topic = labels_topic
        self.sent = 0

    def publish(self, value: Any, timeout: float = 10.0) -> int:
        """Publish one message; returns the number of ROS subscribers (as the reference).
        `value`: the message as a dict of its fields, or a bare value for one-field types
        (str, bool, int, float, lists/tables), or a 4x4 matrix (numpy, lists or
        vtkMatrix4x4, mm) for Pose/PoseStamped/Transform types."""
        result = self._client.request(c.Publish(topic=self.topic, value=_json_value(value)),
                                      timeout=timeout)
        self.sent += 1
        return result.subscribers

    def publish_message(self, message: Mapping[str, Any], timeout: float = 10.0) -> int:
        """Publish one whole message given as generic JSON in ROS units (metres,
        quaternions; as a subscriber's `last_whole` holds it); returns the number of ROS
        subscribers. An empty header stamp is stamped now by the daemon."""
        result = self._client.request(c.Publish(topic=self.topic, message=dict(message)),
                                      timeout=timeout)
        self.sent += 1
        return result.subscribers

    def send(self, body: Any, metadata: Optional[Mapping[str, str]] = None) -> None:
        """Stream an OpenIGTLink body (Transform, String, Image, PolyData...) to this
        publisher's device: no reply, so bad data comes back as a STATUS in
        `Client.errors`. A matrix or a str is wrapped for you."""
        if isinstance(body, str):
            body = String(body)
        elif not hasattr(body, "pack"):
            body = Transform(as_numpy(body))
        self._client.send(Message(self.device, body, metadata=dict(metadata or {})))
        self.sent += 1


    def send_model(self, model: Any, *, ns: Optional[str] = None,
                   marker_id: Optional[int] = None,
                   color: Optional[Sequence[float]] = None) -> None:
        """Stream a model (a `PolyData` in mm, or ``(points (N, 3) mm, triangles (M, 3))``)
        to this publisher: a shape_msgs/Mesh or a visualization_msgs/Marker TRIANGLE_LIST
        in metres (or a nav_msgs/Path from a polyline). For a Marker: ``ns`` (default
        "slicer"), ``marker_id`` (default 0) and ``color`` (r, g, b, a in 0..1)."""
        body = model if isinstance(model, PolyData) else model_polydata(*model)
        metadata: Dict[str, str] = {}
        if ns is not None:
            metadata[KEY_MARKER_NS] = ns
        if marker_id is not None:
            metadata[KEY_MARKER_ID] = str(int(marker_id))
        if color is not None:
            metadata[KEY_COLOR] = " ".join(f"{float(v):.6g}" for v in color)
        self.send(body, metadata)

    def send_points(self, points: Any, labels: Optional[Sequence[str]] = None) -> None:
        """Stream markups points ((N, 3) mm, with optional labels) as one POINT: a
        PoseArray, one PointStamped per point, or a nav_msgs/Path, in metres; the labels
        go to ``labels_topic`` if the publisher has one."""
        self.send(markups_point_body(points, labels))


def points_mm(points: Any, *, flat: bool = False) -> np.ndarray:
    """(N, 3) finite millimetres as float64 (``flat``: any array of 3N numbers), or
    `PointsError` naming the shape, or the first row holding a NaN or an infinity."""
    pts = np.asarray(points, dtype=np.float64)
    if flat and pts.size % 3 == 0:
        pts = pts.reshape(-1, 3)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise PointsError("shape (N, 3) in mm", f"shape {pts.shape}")
    bad = np.flatnonzero(~np.isfinite(pts).all(axis=1))
    if bad.size:
        row = int(bad[0])
        raise PointsError("finite coordinates in mm", f"{pts[row].tolist()} at row {row}")
    return pts


def model_polydata(points: Any, triangles: Any) -> PolyData:
    """(N, 3) points in mm and (M, k) polygons (point indices) -> a POLYDATA body."""
    return PolyData(points=points_mm(points).astype(np.float32),
                    polygons=cells_from_array(np.asarray(triangles, dtype=np.int64)))


def markups_point_body(points: Any, labels: Optional[Sequence[str]] = None) -> Point:
    """(N, 3) positions in mm and their labels -> a POINT body (one element per point)."""
    pts = points_mm(points, flat=True)
    names = list(labels) if labels is not None else [""] * len(pts)
    if len(names) != len(pts):
        raise ValueError(f"labels: expected {len(pts)} (one per point), got {len(names)}")
    return Point([PointElement(name=str(name), position=p) for name, p in zip(names, pts)])


def _call_each(callbacks: List[Callback], make_args: Callable[[], Tuple[Any, ...]]) -> None:
    args = make_args()
    for callback in callbacks:
        try:
            callback(*args)
        except Exception:  # noqa: BLE001 - one callback must not stop the others
            log.exception("callback %r raised", callback)


def _count_of(message: Message, previous: int) -> int:
    try:
        return int(message.metadata.get(KEY_COUNT, previous))
    except ValueError:
        return previous


def _json_value(value: Any) -> Any:
    """numpy and vtk values -> JSON-able ones (matrices stay in mm)."""
    if hasattr(value, "GetElement"):
        return as_rows(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {k: _json_value(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_value(v) for v in value]
    return value


def parameter_to_python(value: c.ParameterValue) -> Any:
    return list(value.value) if isinstance(value.value, tuple) else value.value


class ParameterClient(Resource):
    """Another ROS node's parameters: list, get, set, observe (typed values)."""

    def __init__(self, client: ResourceOwner, node: str) -> None:
        super().__init__(client, BridgeSpec.of(c.CreateParameterClient(node=node)))
        self.node = node
        self.observed: Tuple[str, ...] = ()
        self.all_changes = False
        self.values: Dict[str, c.ParameterValue] = {}  # last known, kept by observe/get
        # The node's parameter services answered (observe's reply, then each update's).
        self.ready = False

    def _restore(self, command: CommandFn) -> None:
        if self.observed or self.all_changes:
            request_with(command, c.ObserveParameters(node=self.node, names=self.observed,
                                                      all_changes=self.all_changes))

    def _handle(self, message: Message) -> None:
        if not isinstance(message.body, String):
            return
        try:
            data = json.loads(message.body.text)
            values = {name: c.ParameterValue.from_json_value(raw, f"values.{name}")
                      for name, raw in dict(data.get("values", {})).items()}
        except (ValueError, c.CommandError, AttributeError) as error:
            self._client.errors.append(f"{self.device}: unreadable parameter update: {error}")
            return
        with self._changed:
            self.values.update(values)
            self.ready = bool(data.get("ready", self.ready))
            self._changed.notify_all()
        for name, value in values.items():
            self._notify(name, parameter_to_python(value))

    def list(self, timeout: float = 10.0) -> List[str]:
        return list(self._client.request(c.ListParameters(node=self.node),
                                         timeout=timeout).names)

    def get_typed(self, names: Sequence[str], timeout: float = 10.0
                  ) -> Dict[str, c.ParameterValue]:
        values = self._client.request(c.GetParameters(node=self.node, names=tuple(names)),
                                      timeout=timeout).values
        with self._changed:
            self.values.update(values)
        return values

    def get(self, name: str, timeout: float = 10.0) -> Any:
        """One parameter's value as Python (None when not set)."""
        return parameter_to_python(self.get_typed([name], timeout)[name])

    def set(self, name: str, value: Any, *, type: Optional[str] = None,
            timeout: float = 10.0) -> None:
        """Set one parameter; `type` (e.g. "double") overrides the inferred one. Raises
        `ParameterRejectedError` with the node's reason if the node refuses."""
        typed = c.ParameterValue(type, value) if type else c.ParameterValue.infer(value)
        result = self._client.request(c.SetParameters(node=self.node, values={name: typed}),
                                      timeout=timeout)
        outcome = result.results.get(name, c.ParameterOutcome(ok=True))
        if not outcome.ok:
            from slicer_client.errors import ParameterRejectedError
            raise ParameterRejectedError(self.node, name, outcome.reason)

    def observe(self, names: Sequence[str], timeout: float = 10.0, *,
                all_changes: bool = False) -> bool:
        """Have changes of `names` pushed (replaces the observed set; [] stops), and when
        the node is absent, pushed once it appears; with `all_changes`, also every other
        parameter of the node that is declared or changed from now on. Callbacks get
        (name, value). Returns whether the node is there now."""
        request = c.ObserveParameters(node=self.node, names=tuple(names),
                                      all_changes=all_changes)
        result = self._client.request(request, timeout=timeout)
        self.ready = result.ready
        with self._changed:
            self.values.update(result.values)
        self.observed = tuple(names)
        self.all_changes = all_changes
        self.spec = dataclasses.replace(self.spec, then=(
            (request.op, {k: v for k, v in request.to_args().items() if k != "schema"}),)
            if names or all_changes else ())
        self._client.spec_changed(self)
        return self.ready


class TfLookup(Resource):
    """parent -> child from tf2, streamed as a 4x4 matrix in mm whenever it changes."""

    def __init__(self, client: ResourceOwner, parent: str, child: str, *,
                 rate_hz: Optional[float] = None) -> None:
        super().__init__(client, BridgeSpec.of(c.CreateTfLookup(parent=parent, child=child,
                                                                 rate_hz=rate_hz)))
        self.parent = parent
        self.child = child
        self.matrix: Optional[np.ndarray] = None
        self.count = 0

    def _handle(self, message: Message) -> None:
        if not isinstance(message.body, Transform):
            return
        with self._changed:
            self.matrix = matrix = np.array(message.body.matrix, dtype=np.float64)
            self.count += 1
            self._changed.notify_all()
        self._notify_newest(lambda: (matrix,))

    def wait_for_matrix(self, timeout: float = 10.0,
                        predicate: Optional[Callable[[np.ndarray], bool]] = None
                        ) -> np.ndarray:
        self._wait(lambda: self.matrix is not None and (predicate is None
                                                         or bool(predicate(self.matrix))),
                   timeout, f"tf {self.parent} -> {self.child}")
        assert self.matrix is not None
        matrix: np.ndarray = self.matrix.copy()  # mypy's 3.10 target reads numpy's Self as Any
        return matrix

    def lookup(self, timeout: float = 0.5) -> np.ndarray:
        """One lookup now (waits up to `timeout` s daemon-side for tf to connect)."""
        return self._client.lookup_transform(self.parent, self.child, timeout=timeout)


class TfBroadcaster(Resource):
    def __init__(self, client: ResourceOwner, parent: str, child: str, *,
                 static: bool = False) -> None:
        super().__init__(client, BridgeSpec.of(c.CreateTfBroadcaster(parent=parent, child=child,
                                                                      static=static)))
        self.parent = parent
        self.child = child
        self.count = 0

    def broadcast(self, matrix_mm: Any, stamp: Optional[Tuple[int, int]] = None,
                  timeout: float = 10.0) -> None:
        """Broadcast parent -> child (a rigid 4x4 in mm: numpy, lists or vtkMatrix4x4);
        the daemon stamps it now unless `stamp` (sec, nanosec) is given."""
        at = None if stamp is None else c.Stamp(sec=int(stamp[0]), nanosec=int(stamp[1]))
        self._client.request(c.BroadcastTransform(
            parent=self.parent, child=self.child, stamp=at,
            matrix=c.matrix_from(as_rows(matrix_mm), "matrix")), timeout=timeout)
        self.count += 1

    def send(self, matrix_mm: Any) -> None:
        """Stream a TRANSFORM to the broadcaster's device (no reply; for high rates)."""
        self._client.send(Message(self.device, Transform(as_numpy(matrix_mm))))
        self.count += 1


class Service:
    """A ROS service client (nothing is created daemon-side: each call is one command)."""

    def __init__(self, client: ResourceOwner, service: str, type: str) -> None:
        c.resolve_service_type(type)  # fail early on a bad type name
        self._client = client
        self.service = service
        self.type = type

    def call(self, request: Optional[Mapping[str, Any]] = None, timeout: float = 4.0
             ) -> Dict[str, Any]:
        """Call and wait; returns the response fields. The daemon gives up after `timeout`
        (TIMEOUT refusal); this client waits a little longer for that answer."""
        result = self._client.request(c.CallService(
            service=self.service, type=self.type, request=_json_value(dict(request or {})),
            timeout=timeout), timeout=timeout + 2.0)
        return dict(result.response)

    def call_async(self, request: Optional[Mapping[str, Any]],
                   callback: Callable[[Optional[Dict[str, Any]], Optional[Exception]], None],
                   timeout: float = 4.0) -> threading.Thread:
        """Call in a worker thread; `callback(response, error)` runs there (or is queued)."""
        def run() -> None:
            try:
                response = self.call(request, timeout)
            except Exception as error:  # noqa: BLE001 - handed to the callback
                self._client.emit(callback, None, error)
            else:
                self._client.emit(callback, response, None)
        worker = threading.Thread(target=run, name=f"service {self.service}", daemon=True)
        worker.start()
        return worker


@dataclass
class RobotLink:
    """One link: its transform from the fixed frame (mm) and its visuals' meshes."""

    name: str
    device: str = ""
    matrix: Optional[np.ndarray] = None
    meshes: Dict[int, PolyData] = None  # type: ignore[assignment]
    metadata: Dict[int, Dict[str, str]] = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        self.meshes = {} if self.meshes is None else self.meshes
        self.metadata = {} if self.metadata is None else self.metadata


class Robot(Resource):
    """A robot: one mesh (PolyData, mm, in its link's frame) per link visual and one
    transform per link, as they arrive (every link's in one TDATA, each element named by
    its link's device); read from the messages' ros2.* metadata.
    Callbacks get (kind, link_name, value) with kind "transform" or "mesh", and
    ("warning", "", text) for each warning of a load (also logged, and in `warnings`)."""

    def __init__(self, client: ResourceOwner, name: str, *, node: str = "/robot_state_publisher",
                 parameter: str = "robot_description", fixed_frame: Optional[str] = None,
                 tf_prefix: str = "", namespace: str = "",
                 source: Optional[Mapping[str, Any]] = None) -> None:
        src = c.RobotSource(node=node, parameter=parameter) if source is None else \
            c.RobotSource.from_args(Args(dict(source), "source."))
        super().__init__(client, BridgeSpec.of(c.CreateRobot(
            name=name, source=src, fixed_frame=fixed_frame or None, tf_prefix=tf_prefix,
            namespace=namespace)))
        self.name = name
        self.links: Dict[str, RobotLink] = {}
        self._devices: Dict[str, Tuple[str, Optional[int]]] = {}
        self._poses_device = ""  # the TDATA of every link's pose (create_robot's reply)
        # (links, visuals) from the daemon's "loaded" STATUS: a robot created while its
        # description was not there yet learns its size only then.
        self._expected: Optional[Tuple[int, int]] = None
        self.warnings: List[str] = []  # of the latest load: missing meshes, skipped joints
        self._joints: Optional[Dict[str, Any]] = None  # describe_robot_joints, once asked
        # What the daemon last said of the description: "loaded", "waiting" or "error"
        # (create_robot's reply, then its STATUS), and why it is not loaded.
        self.state = ""
        self.reason = ""

    def _warn(self, warnings: Sequence[str]) -> None:
        """Each new warning of a load is logged once and given to the callbacks as
        ("warning", "", text): a robot that loads with missing meshes must not look fine."""
        fresh = [w for w in warnings if w not in self.warnings]
        self.warnings = list(warnings)
        for warning in fresh:
            log.warning("robot %s: %s", self.name, warning)
            self._notify("warning", "", warning)

    def progress(self) -> Tuple[int, Optional[int]]:
        """(meshes received, meshes expected); expected is None until the daemon said."""
        if self._expected is not None:  # the daemon's count at the newest load
            return self.mesh_count(), self._expected[1]
        visuals = sum(1 for _, index in self._devices.values() if index is not None)
        return self.mesh_count(), visuals if self._devices else None

    def _created(self, result: Mapping[str, Any]) -> None:
        super()._created(result)
        self._warn([str(w) for w in result.get("warnings", [])])
        with self._changed:
            self.state = str(result.get("state", ""))
            self.reason = str(result.get("reason", ""))
            self._poses_device = str(result.get("poses_device", ""))
            for item in result.get("links", []):
                link = self.links.setdefault(item["link"], RobotLink(item["link"]))
                link.device = item.get("device", "")
                if link.device:
                    self._devices[link.device] = (link.name, None)
                for index, device in enumerate(item.get("visuals", [])):
                    self._devices[device] = (link.name, index)

    def devices(self) -> Tuple[str, ...]:
        return tuple(self._devices) + ((self._poses_device,) if self._poses_device else ())

    def _handle(self, message: Message) -> None:
        meta = message.metadata
        if isinstance(message.body, TrackingData):
            self._poses(message.body)
            return
        if isinstance(message.body, Status) and KEY_LINK_COUNT not in meta:
            self._description_status(message.body)
            return
        if isinstance(message.body, Status):
            with self._changed:
                self._expected = (int(meta[KEY_LINK_COUNT]), int(meta.get(KEY_VISUAL_COUNT, 0)))
                self.state, self.reason = "loaded", ""
                self._learn_links(meta.get(KEY_LINK_DEVICES, "{}"))
                self._changed.notify_all()
            try:
                warnings = json.loads(meta.get(KEY_WARNINGS, "[]"))
            except ValueError:
                warnings = [f"unreadable warnings from the daemon: {meta[KEY_WARNINGS]!r}"]
            self._warn([str(w) for w in warnings] if isinstance(warnings, list) else [])
            return
        known = self._devices.get(message.device_name)
        link_name = meta.get(KEY_LINK) or (known[0] if known else "")
        if not link_name:
            return
        value: Union[np.ndarray, PolyData]  # a link matrix or mesh, as `kind` says
        with self._changed:
            link = self.links.setdefault(link_name, RobotLink(link_name))
            if isinstance(message.body, PolyData):
                index = int(meta.get(KEY_VISUAL, known[1] if known and known[1] is not None
                                     else 0))
                link.meshes[index] = message.body
                link.metadata[index] = dict(meta)
                kind, value = "mesh", message.body
            else:
                return
            self._changed.notify_all()
        self._notify(kind, link_name, value)

    def _learn_links(self, text: str) -> None:
        """The link devices of a load ("loaded" STATUS): a robot created while it waited
        learns there which TDATA element is which link."""
        try:
            devices = json.loads(text)
        except ValueError:
            devices = None
        if not isinstance(devices, dict):
            log.warning("robot %s: unreadable link devices from the daemon: %r", self.name,
                        text[:200])
            return
        for name, device in devices.items():
            link = self.links.setdefault(str(name), RobotLink(str(name)))
            link.device = str(device)
            self._devices[link.device] = (link.name, None)

    def _poses(self, poses: TrackingData) -> None:
        """Link poses, one element each, named by the link's device; the "transform"
        callbacks run for the links whose pose changed (the daemon's message holds every
        placed link)."""
        moved = []
        with self._changed:
            for element in poses.elements:
                known = self._devices.get(element.name)
                if known is None or known[1] is not None:
                    continue  # not a link of this robot (as the create reply named them)
                link = self.links.get(known[0])
                if link is None:
                    link = self.links.setdefault(known[0], RobotLink(known[0], element.name))
                matrix = np.asarray(element.matrix, dtype=np.float64)
                # Bytes, not np.array_equal: a robot's links at 50 Hz on 3D Slicer's main
                # thread, where the comparison cost more than the rest of the message.
                if link.matrix is not None and link.matrix.tobytes() == matrix.tobytes():
                    continue
                link.matrix = matrix.copy()
                moved.append((link.name, link.matrix))
            if moved:
                self._changed.notify_all()
        for link_name, matrix in moved:
            self._notify("transform", link_name, matrix)

    def _description_status(self, status: Status) -> None:
        """The daemon's word on the description: waiting for it, or not loaded (why)."""
        with self._changed:
            if status.code == StatusCode.OK:
                self.state, self.reason = "loaded", ""
            else:
                # "waiting: <reason>" or "description not loaded: <reason>"; a failed
                # reload keeps the loaded robot (the daemon keeps the previous one).
                waiting = status.code == StatusCode.NOT_READY
                self.reason = status.text.split(": ", 1)[1] if waiting and ": " in \
                    status.text else status.text
                if self.state != "loaded" or waiting:
                    self.state = "waiting" if waiting else "error"
            self._changed.notify_all()

    @property
    def transforms(self) -> Dict[str, np.ndarray]:
        return {name: link.matrix.copy() for name, link in self.links.items()
                if link.matrix is not None}

    def mesh_count(self) -> int:
        return sum(len(link.meshes) for link in self.links.values())

    def joints(self, timeout: float = 10.0, *, refresh: bool = False) -> Dict[str, Any]:
        """The robot's joints from its URDF (the daemon's `describe_robot_joints` reply:
        ``joints`` with type, limits, mimic, ``actuated``; ``joint_states_topic``). Kept
        until `refresh` (a reloaded description may change them)."""
        if self._joints is None or refresh:
            request = c.DescribeRobotJoints(name=self.name)  # the table as it came: public
            self._joints = self._client.command(request.op, request.to_args(), timeout=timeout)
        return self._joints

    def set_joints(self, positions: Mapping[str, float], *, topic: Optional[str] = None,
                   timeout: float = 10.0) -> Dict[str, float]:
        """Publish a sensor_msgs/JointState (radians, metres) for the given actuated joints
        on the robot's joint-states topic (or ``topic``). The daemon checks names and
        limits from the URDF (an out-of-limit value raises `CommandRefusedError` naming
        the joint and its limit) and adds the mimic joints; returns what it published."""
        target = topic or c.DescribeRobotJoints(name=self.name).parse_result(
            self.joints(timeout)).joint_states_topic
        result = self._client.request(c.SetRobotJoints(
            name=self.name, topic=target,
            positions=tuple((str(k), float(v)) for k, v in positions.items())),
            timeout=timeout)
        return result.positions

    def ik(self, target: Any, *, tip: str, seed: Optional[Mapping[str, float]] = None,
           collisions: bool = True, timeout: float = 10.0) -> c.SolveIkResult:
        """`solve_ik`'s whole answer, solved or not, without raising: the positions, the
        residual, the failure, and each link's pose at those positions (``links``, mm, in
        the root link's frame), which is what a preview of the solution draws."""
        request = c.SolveIk(
            name=self.name, tip=tip, target=c.matrix_from(_target_rows(target), "target"),
            seed=None if seed is None else tuple((str(k), float(v)) for k, v in seed.items()),
            collisions=collisions)
        return self._client.request(request, timeout=timeout)

    def solve_ik(self, target: Any, *, tip: str, seed: Optional[Mapping[str, float]] = None,
                 collisions: bool = True, timeout: float = 10.0) -> Dict[str, float]:
        """Joint positions (radians, metres) putting link ``tip`` at ``target``, in the
        robot's root link frame, in MILLIMETRES: a 4x4 matrix (numpy, rows, vtkMatrix4x4)
        or a pose ``(position_mm, quaternion_xyzw)``. Starts from ``seed`` (omitted: the
        robot's current joint state), within the URDF's limits, clear of the robot's
        obstacles unless ``collisions`` is False. The robot does not move: pass the result
        to `set_joints` to move it. Raises `IkFailedError` (reason, residual) when no
        solution exists."""
        result = self.ik(target, tip=tip, seed=seed, collisions=collisions, timeout=timeout)
        if not result.solved:
            raise IkFailedError(self.name, tip, result.failure or {},
                                residual_mm=result.residual_mm,
                                residual_deg=result.residual_deg, positions=result.positions)
        return result.positions

    def set_obstacle(self, obstacle: str, topic: str, *, type: str = "Marker",
                     frame: Optional[str] = None, timeout: float = 10.0) -> Dict[str, Any]:
        """Make the model published on ROS ``topic`` (`Client.publish_model`: a Marker, in
        its frame, or a Mesh, in ``frame``) obstacle ``obstacle`` of this robot: solve_ik
        avoids it and `obstacle_distances` measures it. It follows its tf frame."""
        return self._client.request(c.SetObstacle(
            name=self.name, obstacle=obstacle, topic=topic, type=type, frame=frame),
            timeout=timeout)

    def remove_obstacle(self, obstacle: str, timeout: float = 10.0) -> None:
        self._client.request(c.RemoveObstacle(name=self.name, obstacle=obstacle),
                             timeout=timeout)

    def obstacle_distances(self, link: str, timeout: float = 10.0) -> Dict[str, Any]:
        """At the robot's current joint state: ``distances`` (each ``obstacle``,
        ``distance_mm``, nearest points ``on_link_mm`` / ``on_obstacle_mm``), ``contacts``
        (``link``, ``obstacle``) and the ``positions`` used."""
        return self._client.request(c.ObstacleDistances(name=self.name, link=link),
                                    timeout=timeout)

    def publish_distance(self, link: str, obstacle: str, topic: str, *,
                         rate_hz: float = 50.0, timeout: float = 10.0) -> Dict[str, Any]:
        """Have the daemon publish the distance from ``link`` to ``obstacle`` on ROS
        ``topic`` as std_msgs/Float64 (metres), ``rate_hz`` times a second (0 stops);
        read it back with ``subscribe(topic, "Float64")``."""
        return self._client.request(c.PublishDistance(
            name=self.name, link=link, obstacle=obstacle, topic=topic, rate_hz=rate_hz),
            timeout=timeout)

    def plan(self, positions: Mapping[str, float], *, resolution: float = 0.01,
             preview: int = 0, timeout: float = 10.0) -> Dict[str, Any]:
        """A straight joint-space path from the robot's current joint state to
        ``positions`` (radians, metres; the joints not given stay), within limits, checked
        for contact with its obstacles every ``resolution`` (rad or m): ``path`` (rows of
        ``joints``), ``clear``, ``collision`` (link, obstacle, where), ``duration_s``; with
        ``preview`` = n, also ``preview``: n configurations picked evenly along it, each
        with its ``step``, ``time_s`` and every link's pose (``links``, mm, the root link's
        frame). A read, for a preview: nothing moves."""
        return self._client.request(c.PlanMotion(
            name=self.name, positions=tuple((str(k), float(v)) for k, v in positions.items()),
            resolution=resolution, preview=preview), timeout=timeout)

    def execute(self, positions: Mapping[str, float], *,
                action: str = c.DEFAULT_TRAJECTORY_ACTION, resolution: float = 0.01,
                duration_s: Optional[float] = None, feedback: Optional[Any] = None,
                timeout: float = 4.0, result_timeout: Optional[float] = None) -> Any:
        """Move the robot to ``positions`` along the path `plan` gives, through its
        control_msgs/FollowJointTrajectory ``action``: a `GoalHandle` (``result()``,
        ``cancel()``, feedback) once the controller accepted it. A path touching an
        obstacle is refused before anything is sent (`CommandRefusedError`, code
        REJECTED, naming the link and the obstacle). A write."""
        goal = tuple((str(k), float(v)) for k, v in positions.items())
        owner: Any = self._client
        return owner.action(action, c.FOLLOW_JOINT_TRAJECTORY).send_goal_by(
            lambda goal_id: c.ExecuteMotion(
                name=self.name, positions=goal, action=action, resolution=resolution,
                duration_s=duration_s, timeout=timeout, result_timeout=result_timeout,
                goal_id=goal_id),
            feedback=feedback, timeout=timeout)

    def wait_until_loaded(self, timeout: float = 30.0) -> None:
        """Wait until every link named in the create reply has a transform and every
        visual its mesh."""
        def loaded() -> bool:
            if not self._devices and self._expected is not None:
                links, visuals = self._expected
                with_pose = sum(1 for link in self.links.values() if link.matrix is not None)
                return with_pose >= links and self.mesh_count() >= visuals
            for link, index in self._devices.values():
                entry = self.links.get(link)
                if entry is None:
                    return False
                if index is None and entry.matrix is None:
                    return False
                if index is not None and index not in entry.meshes:
                    return False
            return bool(self._devices)
        with self._changed:
            if self._changed.wait_for(loaded, timeout):
                return
            received, expected = self.progress()
            state, reason = self.state, self.reason
        # Outside the lock: the receive thread takes it to deliver this robot's messages.
        # Asked whatever the state said: the daemon's "loaded" STATUS may trail the meshes.
        unposed = self._unposed() if state != "error" else {}
        raise RobotNotLoadedError(self.name, timeout, state=state, reason=reason,
                                  received=received, expected=expected,
                                  unposed=[str(n) for n in unposed.get("links", ())],
                                  unposed_reason=str(unposed.get("reason", "")))

    def _unposed(self) -> Dict[str, Any]:
        """The daemon's word on this robot's links that tf cannot place (list_robots'
        ``unposed``: the links and why); empty if it has none or cannot say."""
        try:
            listed = self._client.command(c.ListRobots.op, {}, timeout=10.0)
        except BridgeClientError as error:
            log.info("robot %s: cannot ask the daemon which links lack tf: %s", self.name,
                     error)
            return {}
        for summary in listed.get("robots", []):
            if summary.get("name") == self.name:
                return dict(summary.get("unposed") or {})
        return {}


def _target_rows(target: Any) -> List[List[float]]:
    """An IK target as 4 rows (mm): a 4x4 as it is, a (position_mm, quaternion_xyzw) pose
    through the protocol's one quaternion conversion."""
    if isinstance(target, (tuple, list)) and len(target) == 2 and np.shape(target[1]) == (4,):
        position = np.asarray(target[0], dtype=np.float64)
        if position.shape != (3,):
            raise PointsError("a position of 3 numbers (mm)", f"shape {position.shape}")
        matrix = np.eye(4)
        matrix[:3, :3] = quaternion_to_rotation(target[1])
        matrix[:3, 3] = position
        return as_rows(matrix, field="target")
    return as_rows(target, field="target")


@dataclass
class MarkerItem:
    """One live marker as the client has it: its model (PolyData in mm in its frame, or a
    String for text, placed by metadata ros2.position), its identity and the TRANSFORM
    device of its frame."""

    device: str
    ns: str
    id: int
    kind: str
    body: Any
    metadata: Dict[str, str]
    frame: str
    frame_device: str


class MarkerSubscriber(Resource):
    """An RViz marker topic (Marker, MarkerArray) or a Path, PolygonStamped or
    PointStamped topic: one `MarkerItem` per live marker in `markers` (device -> item), the
    fixed-frame pose of each of their frames in `frames` (TRANSFORM device -> 4x4 mm).
    Markers that the daemon deletes (DELETE, DELETEALL, lifetime) leave `markers`.
    Callbacks get ("marker", item), ("deleted", item) and ("frame", device, matrix)."""

    def __init__(self, client: ResourceOwner, topic: str, type: str, fixed_frame: str, *,
                 qos: Optional[Mapping[str, Any]] = None) -> None:
        c.marker_source_type(type)  # fail early on a type the daemon refuses
        super().__init__(client, BridgeSpec.of(c.CreateMarkerSubscriber(
            topic=topic, type=type, fixed_frame=fixed_frame, qos=_qos(qos))))
        self.topic = topic
        self.type = type
        self.fixed_frame = fixed_frame
        self.markers: Dict[str, MarkerItem] = {}
        self.frames: Dict[str, np.ndarray] = {}
        self.live: Optional[Tuple[str, ...]] = None  # the daemon's last list of live devices
        self.status = ""  # the daemon's last refusal on this topic (it names the marker)

    @property
    def resolved_topic(self) -> str:
        return str(self.info.get("topic", self.topic))

    def owns(self, message: Message) -> bool:
        """Is `message` (routed by its metadata) this topic's or one of its frames'?"""
        role = message.metadata.get(KEY_ROLE)
        if role == "marker_frame":
            return True  # frames are shared by topics: each keeps the ones it uses
        return role in ("marker", "marker_topic") and \
            message.metadata.get(KEY_TOPIC) == self.resolved_topic

    def _handle(self, message: Message) -> None:
        meta = message.metadata
        role = meta.get(KEY_ROLE)
        events: List[Tuple[Any, ...]] = []
        with self._changed:
            if role == "marker_topic" and isinstance(message.body, String):
                try:
                    live = tuple(str(d) for d in json.loads(meta.get(KEY_MARKERS, "[]")))
                    summary = json.loads(message.body.text)
                    error = str(summary.get("error", "")) if isinstance(summary, dict) else ""
                except ValueError:
                    self._client.errors.append(f"{message.device_name}: unreadable marker "
                                               f"list {meta.get(KEY_MARKERS)!r}")
                    return
                if error and error != self.status:
                    self._client.errors.append(f"{message.device_name}: {error}")
                self.status = error
                self.live = live
                for device in [d for d in self.markers if d not in live]:
                    events.append(("deleted", self.markers.pop(device)))
            elif role == "marker_frame" and isinstance(message.body, Transform):
                self.frames[message.device_name] = np.array(message.body.matrix,
                                                            dtype=np.float64)
                events.append(("frame", message.device_name,
                               self.frames[message.device_name]))
            elif role == "marker" and isinstance(message.body, (PolyData, String)):
                item = MarkerItem(message.device_name, meta.get(KEY_MARKER_NS, ""),
                                  int(meta.get(KEY_MARKER_ID, "0")),
                                  meta.get(KEY_MARKER_TYPE, ""), message.body, dict(meta),
                                  meta.get(KEY_FRAME, ""), meta.get(KEY_PARENT_DEVICE, ""))
                self.markers[message.device_name] = item
                events.append(("marker", item))
            self._changed.notify_all()
        for event in events:
            self._notify(*event)

    def find(self, ns: str, marker_id: int) -> Optional[MarkerItem]:
        with self._lock:
            for item in self.markers.values():
                if item.ns == ns and item.id == marker_id:
                    return item
        return None

    def points_in_fixed_frame(self, item: MarkerItem) -> Optional[np.ndarray]:
        """The model's points (mm) in the fixed frame, or None until its frame is known."""
        matrix = self.frames.get(item.frame_device)
        if matrix is None:
            return None
        if isinstance(item.body, PolyData):
            local = np.asarray(item.body.points, dtype=np.float64).reshape(-1, 3)
        else:  # a text marker: its position is in the metadata
            local = np.array([[float(v) for v in item.metadata.get(KEY_POSITION,
                                                                     "0 0 0").split()]])
        return np.asarray(local @ matrix[:3, :3].T + matrix[:3, 3])

    def wait_for_markers(self, predicate: Callable[[Dict[str, MarkerItem]], bool],
                         timeout: float = 10.0, *, placed: bool = True
                         ) -> Dict[str, MarkerItem]:
        """Block until `predicate(markers)` holds (e.g. ``lambda m: len(m) == 3``) and,
        with ``placed``, every marker's frame pose has come too (a frame's TRANSFORM may
        follow its marker's model), so `points_in_fixed_frame` has them all."""
        def ready() -> bool:
            return bool(predicate(self.markers)) and (not placed or all(
                item.frame_device in self.frames for item in self.markers.values()))
        self._wait(ready, timeout, f"markers on {self.topic}"
                   + (" with their frames' poses" if placed else ""))
        with self._lock:
            return dict(self.markers)
