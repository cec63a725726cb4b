"""Marker reading without a daemon: the CDR reader gives the same events as rclpy's own
deserialization (every field it reads, on markers that fill every field, the texture and
embedded mesh included), bounds and bad input, and the model geometry's invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import ColorRGBA
from geometry_msgs.msg import Point
from visualization_msgs.msg import Marker, MarkerArray, UVCoordinate

from bridge.codecs.cdr import CdrError
from bridge.markers.cdr import layout_supported, read_marker, read_marker_array
from bridge.markers.convert import MarkerEvent, events_of
from bridge.markers.geometry import MAX_MARKER_POINTS, MarkerError, MarkerSpec, build_model
from protocol.messages import PolyData, unpack_body


def full_marker(i: int) -> Marker:
    m = Marker()
    m.header.stamp.sec, m.header.stamp.nanosec = 100 + i, 5000 + i
    m.header.frame_id = f"frame_{i}" * (i % 3)  # empty, and lengths that shift alignment
    m.ns = "n" * i
    m.id = -i
    m.type = i % 12
    m.action = [0, 1, 2, 3][i % 4]
    m.pose.position.x, m.pose.position.y, m.pose.position.z = 0.1 * i, -0.2, 0.3
    m.pose.orientation.z, m.pose.orientation.w = math.sqrt(0.5), math.sqrt(0.5)
    m.scale.x, m.scale.y, m.scale.z = 0.5, 0.25, 0.125 * (i + 1)
    m.color = ColorRGBA(r=0.5, g=0.25, b=1.0, a=0.75)
    m.lifetime.sec, m.lifetime.nanosec = i, 250_000_000
    m.frame_locked = bool(i % 2)
    m.points = [Point(x=float(k), y=0.5 * k, z=-1.0 * k) for k in range(i)]
    m.colors = [ColorRGBA(r=0.25, g=0.5, b=0.75, a=1.0) for _ in range(i % 3)]
    m.texture_resource = "embedded://x" if i % 2 else ""
    m.texture.format = "png"
    m.texture.data = bytes(range(i * 3 % 7))
    m.uv_coordinates = [UVCoordinate(u=0.5, v=0.25)] * (i % 4)
    m.text = "é" * i
    m.mesh_resource = "package://p/m.stl" if i % 3 == 1 else ""
    m.mesh_file.filename = "f.stl" * (i % 2)
    m.mesh_file.data = bytes(i % 5)
    m.mesh_use_embedded_materials = bool(i % 3)
    return m


def same(a: MarkerEvent, b: MarkerEvent) -> None:
    assert (a.action, a.ns, a.id) == (b.action, b.ns, b.id)
    assert (a.error is None) == (b.error is None)
    if a.error is not None:
        assert str(a.error) == str(b.error)
    assert (a.spec is None) == (b.spec is None)
    if a.spec is not None and b.spec is not None:
        assert a.spec.digest() == b.spec.digest()
        for name in ("kind", "frame", "text", "mesh_resource", "use_embedded_materials",
                     "lifetime_ns", "frame_locked", "stamp", "color"):
            assert getattr(a.spec, name) == getattr(b.spec, name), name
        np.testing.assert_array_equal(a.spec.points, b.spec.points)


def test_the_installed_marker_is_the_layout_read() -> None:
    assert layout_supported(Marker.get_fields_and_field_types())


def test_cdr_reader_equals_rclpy_for_every_field() -> None:
    markers = [full_marker(i) for i in range(24)]
    array = MarkerArray(markers=markers)
    raw = read_marker_array(serialize_message(array))
    slow = events_of("visualization_msgs/msg/MarkerArray", array)
    assert len(raw) == len(slow) == 24
    for a, b in zip(raw, slow):
        same(a, b)
    for m in markers[:5]:
        (one,) = read_marker(serialize_message(m))
        (two,) = events_of("visualization_msgs/msg/Marker", m)
        same(one, two)


def test_cdr_reader_refuses_what_it_cannot_read() -> None:
    data = serialize_message(MarkerArray(markers=[full_marker(5)]))
    with pytest.raises(CdrError):
        read_marker_array(b"\x01\x00" + data[2:])  # big-endian: not read here
    with pytest.raises(CdrError):
        read_marker_array(data[:len(data) // 2])


def test_too_many_points_is_refused_by_both_readers() -> None:
    m = Marker(type=Marker.POINTS)
    m.points = [Point()] * (MAX_MARKER_POINTS + 1)
    (raw,) = read_marker(serialize_message(m))
    (slow,) = events_of("visualization_msgs/msg/Marker", m)
    for event in (raw, slow):
        assert event.error is not None and event.error.field == "points"
        assert f"at most {MAX_MARKER_POINTS} points" in str(event.error)


def test_an_array_over_the_bound_is_refused_whole() -> None:
    from bridge.markers.geometry import MAX_ARRAY_MARKERS

    array = MarkerArray(markers=[Marker()] * (MAX_ARRAY_MARKERS + 1))
    for read in (lambda: read_marker_array(serialize_message(array)),
                 lambda: events_of("visualization_msgs/msg/MarkerArray", array)):
        with pytest.raises(MarkerError, match=f"at most {MAX_ARRAY_MARKERS} markers"):
            read()


def test_models_bound_and_check_their_input() -> None:
    with pytest.raises(MarkerError, match="at most"):
        build_model(MarkerSpec(kind="sphere_list", scale=np.full(3, 0.1),
                               points=np.zeros((30_000, 3))))
    with pytest.raises(MarkerError, match="scale.z"):
        build_model(MarkerSpec(kind="cylinder", scale=np.array([1.0, 1.0, 0.0])))
    with pytest.raises(MarkerError, match="points.* finite"):
        build_model(MarkerSpec(kind="line_strip", points=np.array([[0, 0, np.inf]] * 2)))
    for kind in ("cube", "sphere_list"):  # a template's shape, and a list's points
        with pytest.raises(MarkerError) as info:  # finite in metres, not as float32 in mm
            build_model(MarkerSpec(kind=kind, position=np.array([1e36, 0.0, 0.0]),
                                   scale=np.ones(3), points=np.zeros((2, 3))))
        assert info.value.field == "points[0]" and "within float32 once in mm" in str(info.value)
    with pytest.raises(MarkerError, match="different places"):
        build_model(MarkerSpec(kind="arrow", points=np.zeros((2, 3)), scale=np.ones(3)))
    # An unset quaternion is identity (as RViz): a cube at the origin, axis-aligned.
    model = build_model(MarkerSpec(kind="cube", orientation=np.zeros(4), scale=np.ones(3)))
    body = unpack_body(model.type_name, model.body.pack())  # packed from a template
    assert isinstance(body, PolyData) and model.point_count == 8
    assert set(map(tuple, np.asarray(body.points))) == {
        (x, y, z) for x in (-500.0, 500.0) for y in (-500.0, 500.0) for z in (-500.0, 500.0)}


def test_a_namespace_no_device_name_can_hold_is_refused_not_raised() -> None:
    import asyncio
    import json

    from bridge.core.hub import Hub
    from bridge.core.security import SecurityPolicy
    from bridge.markers.capability import MarkerBridges, _Show, _Subscription
    from protocol.commands import CreateMarkerSubscriber
    from protocol.naming import DeviceNameRegistry, NameKey

    class Tf:  # the tf capability's two calls, for the loop-side logic alone
        def stream_lookup(self, *args: object, **kwargs: object) -> object:
            return object()

        def stop_lookup(self, handle: object) -> None:
            pass

    async def run() -> None:
        hub = Hub(asyncio.get_running_loop())
        markers = MarkerBridges(None, hub, DeviceNameRegistry(), tf=Tf())  # type: ignore[arg-type]
        request = CreateMarkerSubscriber(topic="/m", type="Marker", fixed_frame="world")
        sub = _Subscription("/m", "visualization_msgs/msg/Marker", request, "world",
                            NameKey.marker_topic("/m"), "mks:m", markers,
                            SecurityPolicy().content_guard(request))
        markers.subscriptions["/m"] = sub
        spec = MarkerSpec(kind="cube", ns="a\x00b", scale=np.ones(3), frame="base")
        good = MarkerSpec(kind="cube", ns="ok", scale=np.ones(3), frame="base")
        markers.apply(sub, [_Show(("a\x00b", 0), "base", "base", spec.digest(),
                                  build_model(spec), 0),
                            _Show(("ok", 0), "base", "base", good.digest(), build_model(good),
                                  0)])
        assert list(sub.markers) == [("ok", 0)]
        (error,) = sub.errors.values()
        assert "ns/frame: expected a namespace and frame id usable as names" in error
        index = hub.latest("mks:m")
        assert index is not None and len(json.loads(index.metadata["ros2.markers"])) == 1

    asyncio.run(run())


def test_a_worker_behind_folds_what_waits_into_its_end_state() -> None:
    from bridge.markers.capability import _Gone, _Show, _Worker

    class Sub:  # what the worker uses of its subscription
        topic = "/m"
        ros_type = "visualization_msgs/msg/MarkerArray"
        message_class = MarkerArray

        def hand_over(self, updates: object) -> None:
            pass

    def cube(marker_id: int, x: float = 0.0, action: int = Marker.ADD) -> Marker:
        m = Marker(type=Marker.CUBE, id=marker_id, action=action)
        m.pose.position.x = x
        m.scale.x = m.scale.y = m.scale.z = 0.1
        return m

    def raw(*markers: Marker) -> bytes:
        return bytes(serialize_message(MarkerArray(markers=list(markers))))

    worker = _Worker(Sub(), (), {})  # type: ignore[arg-type]
    try:
        # Moved twice then deleted, another added: only the end state is handed on.
        updates = worker._updates(worker._fold([raw(cube(1), cube(2)), raw(cube(1, 0.5)),
                                                raw(cube(1, action=Marker.DELETE), cube(3))]))
        assert [(type(u).__name__, getattr(u, "key", None)) for u in updates] == [
            ("_Show", ("", 2)), ("_Gone", ("", 1)), ("_Show", ("", 3))]
        # DELETEALL in between: everything before it goes, what follows stays.
        updates = worker._updates(worker._fold([raw(cube(4)), raw(
            Marker(action=Marker.DELETEALL), cube(5, 1.0))]))
        assert isinstance(updates[0], _Gone) and updates[0].key is None
        assert [u.key for u in updates[1:] if isinstance(u, _Show)] == [("", 5)]
        # The same state again costs nothing: no update at all.
        assert worker._updates(worker._fold([raw(cube(5, 1.0))])) == []
        # Folded in two goes (the loop was behind in between): the same end state as one.
        early = worker._fold([raw(cube(6)), raw(cube(7))])
        updates = worker._updates(worker._fold([raw(cube(6, action=Marker.DELETE))], early))
        assert [(type(u).__name__, getattr(u, "key", None)) for u in updates] == [
            ("_Show", ("", 7)), ("_Gone", ("", 6))]
    finally:
        worker.stop()


def test_a_delete_is_not_lost_while_the_loop_is_behind() -> None:
    """The loop stops taking batches (its `_MAX_IN_FLIGHT` are not applied): the worker
    keeps reading what arrives into its end state, so a DELETE followed by hundreds of
    messages still reaches the loop once it takes batches again."""
    import threading
    import time

    from bridge.markers.capability import _MAX_IN_FLIGHT, _Gone, _Show, _Worker
    from support import scaled

    handed: list[list[object]] = []
    arrived = threading.Condition()

    class Sub:
        topic = "/m"
        ros_type = "visualization_msgs/msg/MarkerArray"
        message_class = MarkerArray

        def hand_over(self, updates: list[object]) -> None:
            with arrived:
                handed.append(updates)
                arrived.notify_all()

    def cube(marker_id: int, x: float = 0.0, action: int = Marker.ADD) -> bytes:
        m = Marker(type=Marker.CUBE, id=marker_id, action=action)
        m.pose.position.x = x
        m.scale.x = m.scale.y = m.scale.z = 0.1
        return bytes(serialize_message(MarkerArray(markers=[m])))

    def wait_for(predicate: object, what: str) -> None:
        with arrived:
            assert arrived.wait_for(predicate, scaled(30)), what  # type: ignore[arg-type]

    def drained() -> None:  # the worker read all that waits (not a timing guess)
        deadline = time.monotonic() + scaled(30)
        while worker._queue and time.monotonic() < deadline:
            time.sleep(0.001)
        assert not worker._queue

    worker = _Worker(Sub(), (), {})  # type: ignore[arg-type]
    try:
        for i in range(_MAX_IN_FLIGHT):  # the loop takes these and applies none
            worker.put(cube(100 + i))
            wait_for(lambda i=i: len(handed) == i + 1, "a batch per message while not behind")
        worker.put(cube(9))
        worker.put(cube(9, action=Marker.DELETE))
        for chunk in range(10):  # 300 more, far over the 64 a queue holds
            drained()
            for n in range(30):
                worker.put(cube(10, x=0.001 * (30 * chunk + n)))
        drained()
        assert worker.dropped == 0 and len(handed) == _MAX_IN_FLIGHT
        for _ in range(_MAX_IN_FLIGHT):
            worker.applied()
        wait_for(lambda: len(handed) == _MAX_IN_FLIGHT + 1, "the folded end state")
        last = handed[-1]
        assert [(type(u).__name__, getattr(u, "key", None)) for u in last] == [
            ("_Gone", ("", 9)), ("_Show", ("", 10))]
        shown = last[1]
        assert isinstance(shown, _Show) and isinstance(last[0], _Gone)
    finally:
        worker.stop()


def test_an_unlocked_marker_is_placed_by_tf_at_its_stamp() -> None:
    """place_unlocked against a real TfBuffer; the expected poses are worked out by hand:
    tool is at x=0.1 m at 1 s and x=0.3 m at 2 s, turned 90 degrees about z."""
    from bridge.markers.capability import place_unlocked
    from bridge.tf.buffer import StampedTransform, TfBuffer

    s = 1_000_000_000
    z90 = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))
    buffer = TfBuffer()
    buffer.set_transforms([StampedTransform("world", "tool", 1 * s, (0.1, 0.0, 0.0), z90)],
                          static=False)
    buffer.set_transforms([StampedTransform("world", "tool", 2 * s, (0.3, 0.0, 0.0), z90)],
                          static=False)

    def marker(stamp: tuple[int, int], frame: str = "tool") -> MarkerSpec:
        return MarkerSpec("cube", frame=frame, position=np.array([0.1, 0.0, 0.05]),
                          orientation=np.array([0.0, 0.0, 0.0, 0.0]), stamp=stamp)

    def placed_at(stamp: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        spec = place_unlocked(marker(stamp), "world", buffer, str)
        assert spec is not None and spec.frame == "world"
        return spec.position, spec.orientation

    # At 1.5 s tool is at x=0.2; the marker's +x (0.1 m) points along world +y.
    position, orientation = placed_at((1, 500_000_000))
    np.testing.assert_allclose(position, [0.2, 0.1, 0.05], atol=1e-12)
    np.testing.assert_allclose(orientation, z90, atol=1e-12)  # unset quaternion: identity
    np.testing.assert_allclose(placed_at((0, 0))[0], [0.3, 0.1, 0.05], atol=1e-12)  # latest
    np.testing.assert_allclose(placed_at((9, 0))[0], [0.3, 0.1, 0.05], atol=1e-12)  # future
    assert place_unlocked(marker((1, 0), frame="world"), "world", buffer, str) is None
    assert place_unlocked(marker((1, 0), frame="elsewhere"), "world", buffer, str) is None
