"""Every type pair of the reference, both directions, through the real daemon.

ROS -> Slicer: an rclpy peer process publishes; a TCP client gets the OpenIGTLink message.
Slicer -> ROS: the client publishes (JSON value or OpenIGTLink message); an rclpy peer
process prints what arrives. Lengths are metres on the ROS side, millimetres on the wire.
"""

from __future__ import annotations

import itertools
import json
import math
import socket
import struct
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
import pytest

from protocol.crc64 import crc64
from protocol.framing import Decoder, encode
from protocol.header import HEADER_SIZE, Header
from protocol.messages import Image, Message, PolyData, String, Transform
from slicer_client.connection import CommandRefusedError, Connection
from support import Child, Processes, RunningDaemon, scaled

_topics = itertools.count()
HALF = math.sqrt(0.5)


def fresh_topic(stem: str) -> str:
    return f"/types_{stem}_{next(_topics)}"


def read_ros(child: Child, timeout: float = 20.0) -> dict[str, Any]:
    line = child.wait_for_output("MSG ", timeout=timeout)
    return json.loads(line[line.index("MSG ") + 4:])


def publish_until_received(client: Connection, echo: Child, topic: str, value: Any) -> dict:
    """Publish every 100 ms until the ROS peer prints a message (discovery takes a moment)."""
    deadline = time.monotonic() + scaled(20)
    while time.monotonic() < deadline:
        client.command("publish", {"topic": topic, "value": value})
        if "MSG " in echo.output():
            return read_ros(echo)
        time.sleep(0.1)
    raise AssertionError(f"the ROS peer never received {topic}; output:\n{echo.output()}")


def send_until_received(client: Connection, echo: Child, message: Message) -> dict:
    deadline = time.monotonic() + scaled(20)
    while time.monotonic() < deadline:
        client.send(message)
        if "MSG " in echo.output():
            return read_ros(echo)
        time.sleep(0.1)
    raise AssertionError(f"the ROS peer never received {message.device_name}:\n{echo.output()}")


def text_of(message: Message) -> str:
    assert isinstance(message.body, String), message
    return message.body.text


def pose_matrix(position_mm: tuple[float, float, float], quat_xyzw: tuple) -> np.ndarray:
    x, y, z, w = quat_xyzw
    rotation = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    matrix = np.eye(4)
    matrix[:3, :3] = rotation
    matrix[:3, 3] = position_mm
    return matrix


def assert_matrix(message: Message, expected: np.ndarray) -> None:
    assert isinstance(message.body, Transform), message
    np.testing.assert_allclose(message.body.matrix, expected, atol=1e-5)
    assert message.metadata.get("ros2.units") == "mm"


@dataclass
class Case:
    type: str
    ros_type: str
    ros_fields: dict[str, Any]  # what the ROS peer publishes (metres)
    check_igtl: Callable[[Message], None]  # what a client gets
    value: Any  # what a client publishes (millimetres)
    check_ros: Callable[[dict[str, Any]], None]  # what the ROS peer gets


ROTATED = pose_matrix((3.1415, -20.0, 1000.0), (0.0, 0.0, HALF, HALF))

CASES = [
    Case("Empty", "std_msgs/msg/Empty", {},
         lambda m: text_of(m) == "" or pytest.fail(text_of(m)),
         None, lambda r: r == {} or pytest.fail(str(r))),
    Case("String", "std_msgs/msg/String", {"data": "héllo ✓ ROS"},
         lambda m: _eq(text_of(m), "héllo ✓ ROS"),
         "from Slicer ✓", lambda r: _eq(r["data"], "from Slicer ✓")),
    Case("Bool", "std_msgs/msg/Bool", {"data": True},
         lambda m: _eq(text_of(m), "true"),
         False, lambda r: _eq(r["data"], False)),
    Case("Int64", "std_msgs/msg/Int64", {"data": -9007199254740993},
         lambda m: _eq(text_of(m), "-9007199254740993"),
         2 ** 62 + 1, lambda r: _eq(r["data"], 2 ** 62 + 1)),
    Case("Float64", "std_msgs/msg/Float64", {"data": 2.5},
         lambda m: _eq(float(text_of(m)), 2.5),
         0.1, lambda r: _eq(r["data"], 0.1)),
    Case("IntArray", "std_msgs/msg/Int64MultiArray", {"data": [1, -2, 3]},
         lambda m: _eq(json.loads(text_of(m)), [1, -2, 3]),
         [4, 5], lambda r: _eq(r["data"], [4, 5])),
    Case("DoubleTable", "std_msgs/msg/Float64MultiArray",
         {"layout": {"dim": [{"label": "rows", "size": 2, "stride": 6},
                             {"label": "cols", "size": 3, "stride": 3}]},
          "data": [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]},
         lambda m: (_eq(json.loads(text_of(m)), [[1, 2, 3], [4, 5, 6]]),
                    _eq(m.metadata["ros2.shape"], "2x3")),
         [[1.5, 2.0], [3.0, 4.0]],
         lambda r: (_eq(r["data"], [1.5, 2.0, 3.0, 4.0]),
                    _eq([d["size"] for d in r["layout"]["dim"]], [2, 2]))),
    Case("PoseStamped", "geometry_msgs/msg/PoseStamped",
         {"header": {"frame_id": "world"},
          "pose": {"position": {"x": 0.0031415, "y": -0.02, "z": 1.0},
                   "orientation": {"z": HALF, "w": HALF}}},
         lambda m: (assert_matrix(m, ROTATED), _eq(m.metadata["ros2.frame"], "world")),
         ROTATED.tolist(),
         lambda r: (_close([r["pose"]["position"][k] for k in "xyz"], [0.0031415, -0.02, 1.0]),
                    _close([r["pose"]["orientation"][k] for k in "xyzw"], [0, 0, HALF, HALF]))),
    Case("Pose", "geometry_msgs/msg/Pose",
         {"position": {"x": 0.0031415, "y": -0.02, "z": 1.0},
          "orientation": {"z": HALF, "w": HALF}},
         lambda m: assert_matrix(m, ROTATED),
         ROTATED.tolist(),
         lambda r: _close([r["position"][k] for k in "xyz"], [0.0031415, -0.02, 1.0])),
    Case("TransformStamped", "geometry_msgs/msg/TransformStamped",
         {"header": {"frame_id": "base"}, "child_frame_id": "tool",
          "transform": {"translation": {"x": 0.0031415, "y": -0.02, "z": 1.0},
                        "rotation": {"z": HALF, "w": HALF}}},
         lambda m: assert_matrix(m, ROTATED),
         ROTATED.tolist(),
         lambda r: _close([r["transform"]["translation"][k] for k in "xyz"],
                          [0.0031415, -0.02, 1.0])),
    Case("WrenchStamped", "geometry_msgs/msg/WrenchStamped",
         {"wrench": {"force": {"x": 1.0, "y": 2.0, "z": 3.0},
                     "torque": {"x": 0.4, "y": 0.5, "z": 0.6}}},
         lambda m: _close(json.loads(text_of(m)), [1, 2, 3, 0.4, 0.5, 0.6]),
         [6.0, 5.0, 4.0, 0.3, 0.2, 0.1],
         lambda r: (_close([r["wrench"]["force"][k] for k in "xyz"], [6, 5, 4]),
                    _close([r["wrench"]["torque"][k] for k in "xyz"], [0.3, 0.2, 0.1]))),
    Case("PoseArray", "geometry_msgs/msg/PoseArray",
         {"header": {"frame_id": "map"},
          "poses": [{"position": {"x": 0.001}, "orientation": {"w": 1.0}},
                    {"position": {"x": 0.0031415, "y": -0.02, "z": 1.0},
                     "orientation": {"z": HALF, "w": HALF}}]},
         lambda m: (_close(json.loads(text_of(m))[0], pose_matrix((1, 0, 0), (0, 0, 0, 1))),
                    _close(json.loads(text_of(m))[1], ROTATED)),
         [ROTATED.tolist(), np.eye(4).tolist()],
         lambda r: (_eq(len(r["poses"]), 2),
                    _close([r["poses"][0]["position"][k] for k in "xyz"],
                           [0.0031415, -0.02, 1.0]))),
    Case("JointState", "sensor_msgs/msg/JointState",
         {"name": ["shoulder", "elbow"], "position": [0.5, -1.25], "velocity": [0.1, 0.2]},
         lambda m: (_eq(json.loads(text_of(m))["name"], ["shoulder", "elbow"]),
                    _close(json.loads(text_of(m))["position"], [0.5, -1.25])),
         {"name": ["wrist"], "position": [0.75]},
         lambda r: (_eq(r["name"], ["wrist"]), _close(r["position"], [0.75]))),
    Case("Joy", "sensor_msgs/msg/Joy", {"axes": [0.5, -1.0], "buttons": [1, 0, 1]},
         lambda m: (_close(json.loads(text_of(m))["axes"], [0.5, -1.0]),
                    _eq(json.loads(text_of(m))["buttons"], [1, 0, 1])),
         {"axes": [0.25], "buttons": [0, 1]},
         lambda r: (_close(r["axes"], [0.25]), _eq(r["buttons"], [0, 1]))),
    # Any other installed type: the whole message as JSON, both ways.
    Case("sensor_msgs/msg/NavSatFix", "sensor_msgs/msg/NavSatFix",
         {"latitude": 48.85, "longitude": 2.35, "altitude": 35.5,
          "status": {"status": 2, "service": 1}},
         lambda m: (_close(json.loads(text_of(m))["latitude"], 48.85),
                    _eq(json.loads(text_of(m))["status"]["status"], 2)),
         {"latitude": -33.9, "longitude": 151.2, "position_covariance_type": 2},
         lambda r: (_close(r["latitude"], -33.9), _eq(r["position_covariance_type"], 2))),
]


def _eq(got: Any, expected: Any) -> None:
    assert got == expected, f"expected {expected!r}, got {got!r}"


def _close(got: Any, expected: Any) -> None:
    np.testing.assert_allclose(np.asarray(got, dtype=float), np.asarray(expected, dtype=float),
                               atol=1e-6)


@pytest.mark.parametrize("case", CASES, ids=[case.type for case in CASES])
def test_ros_to_slicer(case: Case, daemon: RunningDaemon, client: Connection,
                       processes: Processes) -> None:
    topic = fresh_topic(case.type.replace("/", "_"))
    created = client.command("create_subscriber", {"topic": topic, "type": case.type})
    assert created["type"] == case.ros_type
    processes.python("publisher", "publish_json.py", topic, case.ros_type,
                     json.dumps(case.ros_fields))
    message = client.wait_for(created["device"], timeout=20)
    assert message.metadata["ros2.topic"] == topic
    assert message.metadata["ros2.type"] == case.ros_type
    if case.ros_type.startswith("std_msgs/"):  # no lengths in them: no length unit
        assert "ros2.units" not in message.metadata, message.metadata
    case.check_igtl(message)
    last = client.command("get_last_message", {"topic": topic, "format": "json"})
    assert last["received"] and last["count"] >= 1


@pytest.mark.parametrize("case", CASES, ids=[case.type for case in CASES])
def test_slicer_to_ros(case: Case, daemon: RunningDaemon, client: Connection,
                       processes: Processes) -> None:
    topic = fresh_topic(case.type.replace("/", "_"))
    created = client.command("create_publisher", {"topic": topic, "type": case.type})
    assert created["type"] == case.ros_type
    echo = processes.python("echo", "echo_subscriber.py", topic, case.ros_type, "--count", "1")
    echo.wait_for_output("READY")
    case.check_ros(publish_until_received(client, echo, topic, case.value))


def test_transform_message_to_publisher_device(daemon: RunningDaemon, client: Connection,
                                               processes: Processes) -> None:
    """3D Slicer sends a linear transform node as TRANSFORM: it is published in metres."""
    topic = fresh_topic("igtl_pose")
    device = client.command("create_publisher", {"topic": topic, "type": "PoseStamped"})["device"]
    echo = processes.python("echo", "echo_subscriber.py", topic, "geometry_msgs/msg/PoseStamped",
                            "--count", "1")
    echo.wait_for_output("READY")
    received = send_until_received(client, echo, Message(device, Transform(matrix=ROTATED),
                                                         metadata={"ros2.frame": "slicer"}))
    _close([received["pose"]["position"][k] for k in "xyz"], [0.0031415, -0.02, 1.0])
    _close([received["pose"]["orientation"][k] for k in "xyzw"], [0, 0, HALF, HALF])
    assert received["header"]["frame_id"] == "slicer"
    assert received["header"]["stamp"]["sec"] > 1_600_000_000


def test_string_message_to_publisher_device(daemon: RunningDaemon, client: Connection,
                                            processes: Processes) -> None:
    topic = fresh_topic("igtl_string")
    device = client.command("create_publisher", {"topic": topic, "type": "String"})["device"]
    echo = processes.python("echo", "echo_subscriber.py", topic, "std_msgs/msg/String",
                            "--count", "1")
    echo.wait_for_output("READY")
    received = send_until_received(client, echo, Message(device, String(text="text node ✓")))
    assert received["data"] == "text node ✓"


def test_image_rgb8_both_ways(daemon: RunningDaemon, client: Connection,
                              processes: Processes) -> None:
    height, width = 3, 4
    pixels = np.arange(height * width * 3, dtype=np.uint8).reshape(height, width, 3)
    topic = fresh_topic("image")
    device = client.command("create_subscriber", {"topic": topic, "type": "Image"})["device"]
    processes.python("camera", "publish_json.py", topic, "sensor_msgs/msg/Image", json.dumps({
        "header": {"frame_id": "camera"}, "height": height, "width": width,
        "encoding": "rgb8", "step": width * 3, "data": pixels.reshape(-1).tolist()}))
    message = client.wait_for(device, timeout=20)
    assert isinstance(message.body, Image)
    got = message.body.pixels
    assert got.shape == (1, height, width, 3) and got.dtype == np.uint8
    # Either row order is a valid picture convention; the pixels must be the same set of rows.
    rows = [got[0, j].tolist() for j in range(height)]
    assert rows in ([pixels[j].tolist() for j in range(height)],
                    [pixels[j].tolist() for j in reversed(range(height))])

    back = fresh_topic("image_back")
    out_device = client.command("create_publisher", {"topic": back, "type": "Image"})["device"]
    echo = processes.python("echo", "echo_subscriber.py", back, "sensor_msgs/msg/Image",
                            "--count", "1")
    echo.wait_for_output("READY")
    received = send_until_received(client, echo, Message(out_device, message.body))
    assert (received["height"], received["width"], received["encoding"]) == (height, width,
                                                                             "rgb8")
    assert bytes(received["data"]) == pixels.tobytes()


def test_point_cloud2_to_polydata_in_mm(daemon: RunningDaemon, client: Connection,
                                        processes: Processes) -> None:
    rng = np.random.default_rng(7)
    points = rng.uniform(-1, 1, size=(500, 3)).astype(np.float32)
    topic = fresh_topic("cloud")
    device = client.command("create_subscriber", {"topic": topic,
                                                  "type": "PointCloud2"})["device"]
    fields = [{"name": n, "offset": 4 * i, "datatype": 7, "count": 1} for i, n in enumerate("xyz")]
    processes.python("lidar", "publish_json.py", topic, "sensor_msgs/msg/PointCloud2", json.dumps({
        "header": {"frame_id": "lidar"}, "height": 1, "width": len(points), "fields": fields,
        "is_bigendian": False, "point_step": 12, "row_step": 12 * len(points),
        "data": list(points.tobytes()), "is_dense": True}))
    message = client.wait_for(device, timeout=20)
    assert isinstance(message.body, PolyData)
    np.testing.assert_allclose(message.body.points, points * 1000.0, rtol=1e-6, atol=1e-3)


def test_bad_requests_get_error_replies_naming_the_problem(daemon: RunningDaemon,
                                                           client: Connection) -> None:
    topic = fresh_topic("errors")
    client.command("create_subscriber", {"topic": topic, "type": "String"})
    with pytest.raises(CommandRefusedError) as clash:
        client.command("create_subscriber", {"topic": topic, "type": "PoseStamped"})
    assert clash.value.error.field == "type" and "std_msgs/msg/String" in str(clash.value)
    with pytest.raises(CommandRefusedError) as unknown:
        client.command("create_subscriber", {"topic": topic + "x", "type": "no_pkg/msg/Nope"})
    assert unknown.value.error.field == "type" and "no_pkg/msg/Nope" in str(unknown.value)
    with pytest.raises(CommandRefusedError) as invalid:
        client.command("create_subscriber", {"topic": "/bad topic", "type": "String"})
    assert invalid.value.error.field == "topic"
    pose_topic = fresh_topic("bad_pose")
    client.command("create_publisher", {"topic": pose_topic, "type": "PoseStamped"})
    with pytest.raises(CommandRefusedError) as three_by_three:
        client.command("publish", {"topic": pose_topic, "value": np.eye(3).tolist()})
    assert three_by_three.value.error.field.startswith("value")
    nan_pose = np.eye(4)
    nan_pose[0, 3] = math.nan
    with pytest.raises(CommandRefusedError) as nan:
        client.command("publish", {"topic": pose_topic, "value": np.where(
            np.isnan(nan_pose), None, nan_pose).tolist()})
    assert nan.value.error.field.startswith("value")
    with pytest.raises(CommandRefusedError) as unknown_op:
        client.command("no_such_op", {})
    assert unknown_op.value.error.code.name == "UNKNOWN_OP"
    # The daemon kept serving this client throughout.
    assert client.command("hello")["schema"] == 1


def test_bad_igtl_data_for_a_publisher_gets_a_status_and_nothing_is_published(
        daemon: RunningDaemon, client: Connection) -> None:
    topic = fresh_topic("bad_image")
    device = client.command("create_publisher", {"topic": topic, "type": "Image"})["device"]
    client.send(Message(device, String(text="not an image")))
    status = client.wait_for(device, timeout=10)
    assert status.type_name == "STATUS" and "not published" in status.body.text
    listed = {b["topic"]: b for b in client.command("list_bridges")["bridges"]
              if b["kind"] in ("subscriber", "publisher")}
    assert listed[topic]["messages"] == 0


def test_nan_transform_from_a_client_is_refused(daemon: RunningDaemon, client: Connection) -> None:
    """A foreign peer's TRANSFORM with NaN (our own encoder refuses to write one)."""
    topic = fresh_topic("nan_pose")
    device = client.command("create_publisher", {"topic": topic, "type": "PoseStamped"})["device"]
    body = bytearray(encode(Message(device, Transform(matrix=np.eye(4))))[HEADER_SIZE:])
    body[40:44] = struct.pack(">f", math.nan)  # TY
    header = Header(1, "TRANSFORM", device, 0, len(body), crc64(bytes(body)))
    decoder = Decoder()
    with socket.create_connection(("127.0.0.1", daemon.port), timeout=10) as raw:
        raw.sendall(header.pack() + bytes(body))
        status = None
        while status is None:
            decoder.feed(raw.recv(65536))
            for message in decoder.messages():
                if message.type_name == "STATUS" and message.device_name == device:
                    status = message
    assert "not published" in status.body.text and "finite" in status.body.text
    listed = {b["topic"]: b for b in client.command("list_bridges")["bridges"]
              if b["kind"] in ("subscriber", "publisher")}
    assert listed[topic]["messages"] == 0


def test_bulk_types_keep_one_message_and_a_large_last_message_is_not_kept(
        daemon: RunningDaemon, client: Connection, processes: Processes) -> None:
    """Images and point clouds get a history of 1 unless the client says otherwise (the
    bridge sends only the newest anyway), and a message above 8 MiB streams but is not kept
    for get_last_message, which says so."""
    string_topic = fresh_topic("small")
    small = client.command("create_subscriber", {"topic": string_topic, "type": "String"})
    assert small["qos"]["depth"] == 10
    chosen = client.command("create_subscriber", {"topic": fresh_topic("deep"), "type": "Image",
                                                  "qos": {"depth": 4}})
    assert chosen["qos"]["depth"] == 4
    topic = fresh_topic("large_image")
    created = client.command("create_subscriber", {"topic": topic, "type": "Image"})
    assert created["qos"]["depth"] == 1
    # 2000 x 1600 rgb8: 9.6 MB, above the 8 MiB kept for get_last_message.
    processes.python("camera", "stream_publisher.py", topic, "5", "--image", "2000x1600",
                     "--count", "2")
    message = client.wait_for(created["device"], timeout=scaled(30))
    assert isinstance(message.body, Image) and message.body.pixels.shape == (1, 1600, 2000, 3)
    with pytest.raises(CommandRefusedError) as refused:
        client.command("get_last_message", {"topic": topic})
    assert refused.value.field == "topic"
    assert "at most 8388608 bytes" in str(refused.value)
    assert "9600" in str(refused.value)  # the size it had (9,600,0xx bytes serialized)
    # Nor does the daemon keep the image for clients that connect later (a late ROS
    # subscriber of a volatile topic gets nothing either); a small stream's value it keeps.
    small_device = small["device"]
    processes.python("talker", "publish_json.py", string_topic, "std_msgs/msg/String",
                     json.dumps({"data": "kept"}))
    client.wait_for(small_device, timeout=scaled(30))
    with Connection("127.0.0.1", daemon.port) as late:
        # It asks for both (a client's bridge streams only to those that hold it): what the
        # daemon gives it then comes before the reply.
        for asked, ros_type in ((string_topic, "String"), (topic, "Image")):
            assert late.command("create_subscriber", {"topic": asked, "type": ros_type}
                                )["existed"] is True
        late.command("list_bridges")
        assert late.latest(created["device"]) is None
        kept = late.latest(small_device)
        assert kept is not None and kept.body.text == "kept"


def test_short_names_resolve_for_installed_types_and_a_misspelt_one_says_the_closest(
        daemon: RunningDaemon, client: Connection) -> None:
    """Issue 43, item 10: `Float64` was accepted and `Float32` not (a request's parse knew
    only the reference's short names, before the daemon could look installed packages up);
    a misspelt type got OUT_OF_RANGE and no "did you mean"."""
    for op in ("create_subscriber", "create_publisher"):
        topic = fresh_topic("float32")
        created = client.command(op, {"topic": topic, "type": "Float32"})
        assert created["type"] == "std_msgs/msg/Float32"
    for given, closest in (("PoseStampd", "PoseStamped"),
                           ("geometry_msgs/msg/PoseStampd", "geometry_msgs/msg/PoseStamped")):
        with pytest.raises(CommandRefusedError) as refused:
            client.command("create_subscriber", {"topic": fresh_topic("typo"), "type": given})
        assert (refused.value.code.name, refused.value.field) == ("UNKNOWN_ROS_TYPE", "type")
        assert str(refused.value).endswith(f"got {given!r} (did you mean {closest}?))"), \
            str(refused.value)
    with pytest.raises(CommandRefusedError) as malformed:  # no look-up could make it a type
        client.command("create_subscriber", {"topic": fresh_topic("bad"), "type": "pose stamped"})
    assert (malformed.value.code.name, malformed.value.field) == ("UNKNOWN_ROS_TYPE", "type")
