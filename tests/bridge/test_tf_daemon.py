"""tf2 through the real daemon: lookups streamed on change, one-shot lookups, broadcasters.

ROS peers are separate rclpy processes (tests/peers/tf_*.py, echo_subscriber.py); clients
are real TCP connections. The daemon of this module is shared, so each test uses its own
frame names (a prefix), and only looks at the frames it made.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import math
import threading
import time
from typing import Any, Iterator

import numpy as np
import pytest

from protocol.conversions import ros_time_from_igtl
from protocol.messages import Message, Status, StatusCode, Transform
from slicer_client.connection import CommandRefusedError, Connection
from support import (Child, Processes, RunningDaemon, pick_free_port, scaled, start_daemon,
                     wait_until)

_prefixes = itertools.count()
HALF = math.sqrt(0.5)


def fresh(stem: str) -> str:
    return f"{stem}{next(_prefixes)}_"


# The chain tf_chain_publisher.py publishes, written out by hand (mm).
WORLD_BASE = np.array([[1, 0, 0, 100], [0, 1, 0, 200], [0, 0, 1, 300], [0, 0, 0, 1]], float)
BASE_LINK1 = np.array([[0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 500], [0, 0, 0, 1]], float)


def link1_tool(x_mm: float = 250.0) -> np.ndarray:
    return np.array([[1, 0, 0, x_mm], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], float)


WORLD_TOOL = WORLD_BASE @ BASE_LINK1 @ link1_tool()
# Composed by hand as well: the tool sits at base (100, 200, 300) + (0, 0, 500) + Rz(250, 0, 0).
assert np.allclose(WORLD_TOOL[:3, 3], [100, 450, 800])


def is_matrix(expected: np.ndarray):
    def check(message: Message) -> bool:
        return isinstance(message.body, Transform) and np.allclose(
            message.body.matrix, expected, atol=1e-3)
    return check


def is_status(message: Message) -> bool:
    return isinstance(message.body, Status)


class Counter:
    """Counts what one connection receives per device (on the receive thread)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.by_device: dict[str, list[Message]] = {}

    def __call__(self, message: Message) -> None:
        with self.lock:
            self.by_device.setdefault(message.device_name, []).append(message)

    def of(self, device: str) -> list[Message]:
        with self.lock:
            return list(self.by_device.get(device, []))


@pytest.fixture
def counted(daemon: RunningDaemon) -> Iterator[tuple[Connection, Counter]]:
    counter = Counter()
    connection = Connection("127.0.0.1", daemon.port, on_message=counter)
    yield connection, counter
    connection.close()


def ros_transforms(echo: Child) -> list[dict[str, Any]]:
    """Every TransformStamped the echo peer printed so far."""
    out = []
    for line in echo.lines():
        if line.startswith("MSG "):
            out.extend(json.loads(line[4:])["transforms"])
    return out


def first_with_child(echo: Child, child: str) -> dict[str, Any] | None:
    return next((t for t in ros_transforms(echo) if t["child_frame_id"] == child), None)


# ---------------------------------------------------------------------------- lookups


def test_chain_lookup_streams_the_composed_matrix_in_mm(
        daemon: RunningDaemon, counted: tuple[Connection, Counter],
        processes: Processes) -> None:
    client, counter = counted
    p = fresh("chain")
    created = client.command("create_tf_lookup", {"parent": p + "world", "child": p + "tool"})
    device = created["device"]
    assert created["igtl_type"] == "TRANSFORM" and created["existed"] is False
    assert device.startswith("tf:")  # long frame names get a hashed name (20 bytes max)
    processes.python("chain", "tf_chain_publisher.py", p, "--rate", "50")
    message = client.wait_for(device, is_matrix(WORLD_TOOL), timeout=20)
    assert message.metadata["ros2.parent"] == p + "world"
    assert message.metadata["ros2.child"] == p + "tool"
    assert message.metadata["ros2.frame"] == p + "world"
    assert message.metadata["ros2.units"] == "mm"
    # The IGTL time stamp is the transform's (the publisher's clock: this machine's now).
    sec, _ = ros_time_from_igtl(message.timestamp)
    assert abs(sec - time.time()) < 30
    # The same through a one-shot lookup, with translation in metres and the quaternion.
    one = client.command("lookup_transform", {"parent": p + "world", "child": p + "tool"})
    np.testing.assert_allclose(one["matrix"], WORLD_TOOL, atol=1e-6)
    np.testing.assert_allclose(one["translation"], [0.1, 0.45, 0.8], atol=1e-9)
    rotation = WORLD_TOOL[:3, :3]
    q = one["rotation"]
    assert abs(np.linalg.norm(q) - 1) < 1e-9
    assert one["stamp"]["sec"] > 0
    x, y, z, w = q
    np.testing.assert_allclose(rotation, [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]], atol=1e-9)
    # Creating it again is idempotent; list_bridges shows it and the buffer's frames.
    again = client.command("create_tf_lookup", {"parent": p + "world", "child": p + "tool"})
    assert again["existed"] is True and again["device"] == device
    listed = client.command("list_bridges")
    mine = [b for b in listed["bridges"] if b.get("device") == device]
    assert len(mine) == 1 and mine[0]["kind"] == "tf_lookup"
    assert mine[0]["state"] == "streaming"
    buffer_info = listed["tf_buffer"]
    assert {p + f for f in ("world", "base", "link1", "tool")} <= set(buffer_info["frames"])
    # A client that asks for it later gets the latest value at once (the client's bridge
    # streams only to those that hold it: docs/security.md, "Who owns a bridge").
    with daemon.connect() as late:
        assert late.command("create_tf_lookup", {"parent": p + "world",
                                                 "child": p + "tool"})["existed"] is True
        late.wait_for(device, is_matrix(WORLD_TOOL), timeout=scaled(5))
    client.command("remove_tf_lookup", {"parent": p + "world", "child": p + "tool"})
    with pytest.raises(CommandRefusedError) as gone:
        client.command("remove_tf_lookup", {"parent": p + "world", "child": p + "tool"})
    assert gone.value.error.code.name == "NOT_FOUND"


def test_lookup_is_sent_only_when_the_transform_changes(
        daemon: RunningDaemon, counted: tuple[Connection, Counter],
        processes: Processes) -> None:
    client, counter = counted
    p = fresh("quiet")
    device = client.command("create_tf_lookup",
                            {"parent": p + "world", "child": p + "tool"})["device"]
    processes.python("chain", "tf_chain_publisher.py", p, "--rate", "100",
                     "--count", "150", "--then-step")
    client.wait_for(device, is_matrix(WORLD_TOOL), timeout=20)
    # 150 /tf messages with new stamps and the same values, then a 10 mm step: one
    # TRANSFORM for the 150, none repeated (the reference re-sends every 20 ms whatever
    # happens), then the step's. The step comes last from the same writer, so once it is
    # here every message before it was read: the count is not a matter of waiting long.
    stepped = WORLD_BASE @ BASE_LINK1 @ link1_tool(260.0)
    wait_until(lambda: any(is_matrix(stepped)(m) for m in counter.of(device)), timeout=20,
               what="the step's TRANSFORM")
    assert [is_matrix(WORLD_TOOL)(m) for m in counter.of(device)] == [True, False], \
        [m.type_name for m in counter.of(device)]


def test_a_moving_chain_streams_every_change_and_a_rate_cap_holds(
        daemon: RunningDaemon, counted: tuple[Connection, Counter],
        processes: Processes) -> None:
    client, counter = counted
    p = fresh("moving")
    device = client.command("create_tf_lookup",
                            {"parent": p + "world", "child": p + "tool"})["device"]
    capped = client.command("create_tf_lookup",
                            {"parent": p + "base", "child": p + "tool", "rate_hz": 4})["device"]
    chain = processes.python("chain", "tf_chain_publisher.py", p, "--rate", "100",
                             "--count", "200", "--moving")
    last = WORLD_BASE @ BASE_LINK1 @ link1_tool(250.0 + 200 * 0.1)
    client.wait_for(device, is_matrix(last), timeout=30)
    chain.wait_for_output("DONE", timeout=20)
    client.wait_for(capped, is_matrix(BASE_LINK1 @ link1_tool(270.0)), timeout=scaled(5))
    seen = len(counter.of(device))
    # Each tick moves the tool by 0.1 mm: most ticks reach the client (coalescing may merge
    # a few when the loop is busy, never invent any).
    assert 100 <= seen <= 200, seen
    # 2 s of motion at <= 4 per second, plus the first value and the final held one.
    assert 2 <= len(counter.of(capped)) <= 12, len(counter.of(capped))


def test_interpolation_at_the_midpoint_of_two_samples(
        daemon: RunningDaemon, client: Connection, processes: Processes) -> None:
    p = fresh("interp")
    sec = 1_000_000
    processes.python("samples", "tf_samples_publisher.py", p + "a", p + "b", str(sec))
    # The reply waits (timeout) until both samples are in: without the second one, the
    # midpoint is an extrapolation.
    mid = client.command("lookup_transform", {
        "parent": p + "a", "child": p + "b", "time": {"sec": sec, "nanosec": 500_000_000},
        "timeout": 15}, timeout=20)
    # Translation linear: (0.5, 1.0, 0) m; rotation slerp: 45 degrees about z.
    np.testing.assert_allclose(mid["translation"], [0.5, 1.0, 0.0], atol=1e-9)
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    np.testing.assert_allclose(mid["matrix"], [[c, -s, 0, 500], [s, c, 0, 1000], [0, 0, 1, 0],
                                               [0, 0, 0, 1]], atol=1e-9)
    assert mid["stamp"] == {"sec": sec, "nanosec": 500_000_000}
    end = client.command("lookup_transform", {"parent": p + "a", "child": p + "b",
                                              "time": {"sec": sec + 1}})
    np.testing.assert_allclose(end["translation"], [1.0, 2.0, 0.0], atol=1e-12)
    latest = client.command("lookup_transform", {"parent": p + "a", "child": p + "b"})
    assert latest["stamp"] == {"sec": sec + 1, "nanosec": 0}
    # Far in the future: an error reply in tf2's words, with the TF2Error code.
    with pytest.raises(CommandRefusedError) as future:
        client.command("lookup_transform", {"parent": p + "a", "child": p + "b",
                                            "time": {"sec": sec + 1000}})
    error = future.value.error
    assert error.code.name == "TRANSFORM_UNAVAILABLE" and error.field == "time"
    assert "Lookup would require extrapolation into the future.  Requested time " \
           f"{sec + 1000}.000000000 but the latest data is at time {sec + 1}.000000000" \
           in error.message
    assert "TF2Error 3 EXTRAPOLATION_ERROR" in error.message
    with pytest.raises(CommandRefusedError) as past:
        client.command("lookup_transform", {"parent": p + "a", "child": p + "b",
                                            "time": {"sec": sec - 5}})
    assert "extrapolation into the past" in past.value.error.message


def test_unknown_frame_is_pending_and_a_late_static_publisher_completes_the_chain(
        daemon: RunningDaemon, counted: tuple[Connection, Counter],
        processes: Processes) -> None:
    """Dynamic links first, the static world -> base later: the lookup waits, then streams.
    The static peer publishes once at start-up, before discovery: only transient local
    durability brings it to the daemon."""
    client, counter = counted
    p = fresh("late")
    device = client.command("create_tf_lookup",
                            {"parent": p + "world", "child": p + "tool"})["device"]
    processes.python("dynamic", "tf_chain_publisher.py", p, "--rate", "50", "--no-static")
    # The dynamic part alone is there: base -> tool resolves, world is unknown.
    client.command("lookup_transform", {"parent": p + "base", "child": p + "tool",
                                        "timeout": 15}, timeout=20)
    with pytest.raises(CommandRefusedError) as unknown:
        client.command("lookup_transform", {"parent": p + "world", "child": p + "tool"})
    assert unknown.value.error.field == "parent"
    assert f'"{p}world" passed to lookupTransform argument target_frame does not exist' \
        in unknown.value.error.message
    assert "TF2Error 1 LOOKUP_ERROR" in unknown.value.error.message
    listed = [b for b in client.command("list_bridges")["bridges"] if b.get("device") == device]
    assert listed[0]["state"] == "pending"
    assert counter.of(device) == []  # pending: nothing sent, not even a STATUS
    static = processes.python("static", "tf_chain_publisher.py", p, "--static-only")
    static.wait_for_output("READY")
    client.wait_for(device, is_matrix(WORLD_TOOL), timeout=20)
    assert all(isinstance(m.body, Transform) for m in counter.of(device))


def test_disconnected_trees_report_one_status_not_one_per_update(
        daemon: RunningDaemon, counted: tuple[Connection, Counter],
        processes: Processes) -> None:
    client, counter = counted
    p, q = fresh("tree"), fresh("tree")
    processes.python("tree1", "tf_chain_publisher.py", p, "--rate", "50", "--no-static",
                     "--moving")
    processes.python("tree2", "tf_chain_publisher.py", q, "--rate", "50", "--no-static")
    for prefix in (p, q):
        client.command("lookup_transform", {"parent": prefix + "base", "child": prefix + "tool",
                                            "timeout": 15}, timeout=20)
    device = client.command("create_tf_lookup",
                            {"parent": p + "tool", "child": q + "tool"})["device"]
    status = client.wait_for(device, is_status, timeout=10)
    assert status.body.code == StatusCode.NOT_FOUND
    assert status.body.subcode == 2 and status.body.error_name == "CONNECTIVITY_ERROR"
    assert status.body.text == (
        f"Could not find a connection between '{p}tool' and '{q}tool' because they are not"
        " part of the same tree.Tf has two or more unconnected trees.")
    assert status.metadata["ros2.parent"] == p + "tool"
    # Both trees keep updating at 50 Hz: still that one STATUS. A lookup within the moving
    # tree witnesses the updates the daemon has read since (each moves its tool).
    witness = client.command("create_tf_lookup",
                             {"parent": p + "base", "child": p + "tool"})["device"]
    client.wait_for(witness, timeout=10)
    seen = len(counter.of(witness))
    wait_until(lambda: len(counter.of(witness)) >= seen + 25, timeout=20,
               what="25 more updates of the moving tree")
    assert len(counter.of(device)) == 1
    listed = [b for b in client.command("list_bridges")["bridges"] if b.get("device") == device]
    assert listed[0]["state"] == "error" and "unconnected trees" in listed[0]["error"]
    with pytest.raises(CommandRefusedError) as refused:
        client.command("lookup_transform", {"parent": p + "tool", "child": q + "tool"})
    assert "TF2Error 2 CONNECTIVITY_ERROR" in refused.value.error.message


def test_static_data_published_before_the_daemon_started_reaches_it(
        processes: Processes) -> None:
    """Transient local both ways, and a namespaced daemon still listens on /tf_static."""
    p = fresh("early")
    static = processes.python("static", "tf_chain_publisher.py", p, "--static-only")
    static.wait_for_output("READY")
    late_daemon = start_daemon(processes, "--namespace", "tfns", "--node-name", "tf_late")
    with late_daemon.connect() as client:
        reply = client.command("lookup_transform", {"parent": p + "world", "child": p + "base",
                                                    "timeout": 15}, timeout=20)
        np.testing.assert_allclose(reply["matrix"], WORLD_BASE, atol=1e-9)
        assert reply["stamp"] == {"sec": 0, "nanosec": 0}  # static data holds at every time
        topics = client.command("list_bridges")["tf_buffer"]["topics"]
        assert topics == ["/tf", "/tf_static"]


# ---------------------------------------------------------------------------- broadcasters


def test_broadcast_reaches_ros_in_metres_with_a_stamp(
        daemon: RunningDaemon, client: Connection, processes: Processes) -> None:
    p = fresh("bcast")
    echo = processes.python("echo", "echo_subscriber.py", "/tf", "tf2_msgs/msg/TFMessage")
    echo.wait_for_output("READY")
    created = client.command("create_tf_broadcaster", {"parent": p + "world",
                                                       "child": p + "needle"})
    assert created["device"].startswith("tfb:") and created["topic"] == "/tf"
    matrix = [[0, -1, 0, 3.1415], [1, 0, 0, -20], [0, 0, 1, 1000], [0, 0, 0, 1]]
    deadline = time.monotonic() + scaled(20)
    received = None
    while received is None and time.monotonic() < deadline:
        reply = client.command("broadcast_transform", {"parent": p + "world",
                                                       "child": p + "needle", "matrix": matrix})
        assert reply["topic"] == "/tf"
        time.sleep(0.1)
        received = first_with_child(echo, p + "needle")
    assert received is not None, echo.output()[-2000:]
    assert received["header"]["frame_id"] == p + "world"
    t = received["transform"]["translation"]
    np.testing.assert_allclose([t["x"], t["y"], t["z"]], [0.0031415, -0.02, 1.0], atol=1e-12)
    r = received["transform"]["rotation"]
    np.testing.assert_allclose([r["x"], r["y"], r["z"], r["w"]], [0, 0, HALF, HALF], atol=1e-9)
    stamp = received["header"]["stamp"]
    assert stamp["sec"] > 1_600_000_000  # the reference sends no stamp at all
    assert abs(stamp["sec"] - time.time()) < 30
    # The daemon's own buffer has it at once (and hears its own /tf).
    back = client.command("lookup_transform", {"parent": p + "world", "child": p + "needle"})
    np.testing.assert_allclose(back["matrix"], matrix, atol=1e-9)
    # An explicit stamp is kept.
    client.command("broadcast_transform", {"parent": p + "world", "child": p + "needle",
                                           "matrix": np.eye(4).tolist(),
                                           "stamp": {"sec": 1_800_000_000, "nanosec": 7}})
    wait_until(lambda: any(t["child_frame_id"] == p + "needle"
                           and t["header"]["stamp"] == {"sec": 1_800_000_000, "nanosec": 7}
                           for t in ros_transforms(echo)), timeout=10, what="stamped broadcast")


def test_static_broadcasts_reach_a_subscriber_started_after_them(
        daemon: RunningDaemon, client: Connection, processes: Processes) -> None:
    p = fresh("sbcast")
    for child, x in (("needle", 3.1415), ("probe", 50.0)):
        created = client.command("create_tf_broadcaster", {"parent": p + "world",
                                                           "child": p + child, "static": True})
        assert created["topic"] == "/tf_static" and created["static"] is True
        client.command("broadcast_transform", {
            "parent": p + "world", "child": p + child,
            "matrix": [[1, 0, 0, x], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]})
    # Started after both broadcasts: the one latched message holds both transforms.
    echo = processes.python("echo", "echo_subscriber.py", "/tf_static", "tf2_msgs/msg/TFMessage",
                            "--transient-local")
    echo.wait_for_output("READY")

    def both() -> bool:
        for line in echo.lines():
            if line.startswith("MSG "):
                children = {t["child_frame_id"]: t for t in json.loads(line[4:])["transforms"]}
                if p + "needle" in children and p + "probe" in children:
                    return True
        return False

    wait_until(both, timeout=20, what="one latched /tf_static message with both transforms")
    needle = first_with_child(echo, p + "needle")
    assert needle is not None
    assert needle["transform"]["translation"]["x"] == pytest.approx(0.0031415, abs=1e-12)
    assert needle["header"]["stamp"]["sec"] > 1_600_000_000
    # A static broadcaster cannot become a dynamic one under the same frames.
    with pytest.raises(CommandRefusedError) as clash:
        client.command("create_tf_broadcaster", {"parent": p + "world", "child": p + "needle"})
    assert clash.value.error.code.name == "ALREADY_EXISTS" and clash.value.error.field == "static"


def test_transform_sent_to_a_broadcaster_device_is_published(
        daemon: RunningDaemon, client: Connection, processes: Processes) -> None:
    p = fresh("igtl")
    echo = processes.python("echo", "echo_subscriber.py", "/tf", "tf2_msgs/msg/TFMessage")
    echo.wait_for_output("READY")
    device = client.command("create_tf_broadcaster", {"parent": p + "world",
                                                      "child": p + "pointer"})["device"]
    matrix = np.array([[1, 0, 0, 3.1415], [0, 0, -1, 0], [0, 1, 0, -7], [0, 0, 0, 1]], float)
    deadline = time.monotonic() + scaled(20)
    received = None
    while received is None and time.monotonic() < deadline:
        client.send(Message(device, Transform(matrix=matrix)))
        time.sleep(0.1)
        received = first_with_child(echo, p + "pointer")
    assert received is not None, echo.output()[-2000:]
    t = received["transform"]["translation"]
    np.testing.assert_allclose([t["x"], t["y"], t["z"]], [0.0031415, 0.0, -0.007], atol=1e-7)
    assert received["header"]["stamp"]["sec"] > 1_600_000_000
    listed = [b for b in client.command("list_bridges")["bridges"] if b.get("device") == device]
    assert listed[0]["messages"] >= 1

    # A scaled (non-orthonormal) matrix: a STATUS naming the field, nothing published.
    sent = listed[0]["messages"]
    stretched = matrix.copy()
    stretched[:3, :3] *= 2.0
    client.send(Message(device, Transform(matrix=stretched)))
    status = client.wait_for(device, is_status, timeout=10)
    assert status.body.code == StatusCode.CONFIG_ERROR
    assert "not broadcast on /tf" in status.body.text
    assert "TRANSFORM matrix rotation" in status.body.text
    listed = [b for b in client.command("list_bridges")["bridges"] if b.get("device") == device]
    assert listed[0]["messages"] == sent


def test_bad_broadcast_requests_get_error_replies_naming_the_field(
        daemon: RunningDaemon, client: Connection) -> None:
    p = fresh("badb")
    with pytest.raises(CommandRefusedError) as missing:
        client.command("broadcast_transform", {"parent": p + "a", "child": p + "b",
                                               "matrix": np.eye(4).tolist()})
    assert missing.value.error.code.name == "NOT_FOUND"
    client.command("create_tf_broadcaster", {"parent": p + "a", "child": p + "b"})
    sheared = np.eye(4)
    sheared[0, 1] = 0.5
    with pytest.raises(CommandRefusedError) as shear:
        client.command("broadcast_transform", {"parent": p + "a", "child": p + "b",
                                               "matrix": sheared.tolist()})
    assert shear.value.error.code.name == "OUT_OF_RANGE"
    assert shear.value.error.field == "matrix rotation"
    not_a_number = [[1, 0, 0, None]] + np.eye(4)[1:].tolist()  # JSON has no NaN: null
    with pytest.raises(CommandRefusedError) as nan:
        client.command("broadcast_transform", {"parent": p + "a", "child": p + "b",
                                               "matrix": not_a_number})
    assert nan.value.error.field == "matrix[0][3]"
    with pytest.raises(CommandRefusedError) as three:
        client.command("broadcast_transform", {"parent": p + "a", "child": p + "b",
                                               "matrix": np.eye(3).tolist()})
    assert three.value.error.field == "matrix"
    with pytest.raises(CommandRefusedError) as same:
        client.command("create_tf_broadcaster", {"parent": p + "a", "child": p + "a"})
    assert same.value.error.field == "child"
    assert client.command("remove_tf_broadcaster", {"parent": p + "a", "child": p + "b"})
    assert client.command("hello")["schema"] == 1


# ---------------------------------------------------------------------------- prefix


def test_frame_prefix_maps_relative_frames_and_leaves_absolute_ones() -> None:
    """The tf_prefix-style option (in process: the CLI does not expose it yet)."""
    from bridge.core.hub import Hub
    from bridge.ros.ros_node import RosNode, RosOptions
    from bridge.tf.capability import TfBridges
    from protocol.commands import CreateTfLookup, TfLookupBridge
    from protocol.naming import DeviceNameRegistry

    loop = asyncio.new_event_loop()
    ros = RosNode(RosOptions(node_name="tf_prefix_test", namespace="/robot1"))
    try:
        tf = TfBridges(ros, Hub(loop), DeviceNameRegistry(), frame_prefix="robot1/")
        assert tf.resolve_frame("base") == "robot1/base"
        assert tf.resolve_frame("/world") == "world"

        async def create() -> TfLookupBridge:  # mapped as the dispatcher maps it
            request = CreateTfLookup(parent="/world", child="tool")
            return tf.create_lookup(request.with_frames(tf.resolve_client_frame)).reply

        created = loop.run_until_complete(create())
        assert (created.parent, created.child) == ("world", "robot1/tool")
        tf.close()
    finally:
        ros.stop()
        loop.close()


@pytest.mark.parametrize("rclpy_take", [False, True], ids=["rcl reader", "rclpy take"])
@pytest.mark.parametrize("pure_python", [False, True], ids=["compiled store", "Python store"])
def test_a_daemon_serves_lookups_on_either_tf_store(processes: Processes, pure_python: bool,
                                                    rclpy_take: bool) -> None:
    """The daemon reads /tf on whichever store its TfBuffer runs: the compiled one reads the
    CDR itself, the pure Python one (where the compiled store was not built) lets the
    capability read it; and takes /tf either way: without the interpreter's lock (the rcl
    reader) or through rclpy. All stream the same composed lookup."""
    from bridge.ros.raw_reader import _rcl_reader
    from bridge.tf.buffer import CompiledFrameStore

    if not pure_python and CompiledFrameStore is None:
        pytest.skip("the compiled tf store was not built (no C compiler or Cython at install)")
    if not rclpy_take and _rcl_reader is None:
        pytest.skip("the rcl reader was not built (no rcl headers, C compiler or Cython)")
    paths = ["--tf-store", "python" if pure_python else "compiled",
             "--ros-take", "rclpy" if rclpy_take else "rcl"]
    port = pick_free_port()
    daemon = processes.bridge("run", "--port", str(port), *paths)
    daemon.wait_for_output("tf buffer on the", timeout=30)  # logged after "listening on"
    expected = "pure Python" if pure_python else "compiled"
    assert f"tf buffer on the {expected} store" in daemon.output()
    taken = ("/tf taken through rclpy" if rclpy_take
             else "/tf taken without the interpreter's lock (rcl reader)")
    assert taken in daemon.output()
    p = fresh("store")
    with Connection("127.0.0.1", port) as client:
        device = client.command("create_tf_lookup",
                                {"parent": p + "world", "child": p + "tool"})["device"]
        processes.python("chain", "tf_chain_publisher.py", p, "--rate", "50")
        message = client.wait_for(device, is_matrix(WORLD_TOOL), timeout=20)
        assert message.metadata["ros2.child"] == p + "tool"
        one = client.command("lookup_transform", {"parent": p + "world", "child": p + "tool"})
        np.testing.assert_allclose(one["matrix"], WORLD_TOOL, atol=1e-6)
