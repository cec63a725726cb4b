"""`slicer-ros2-bridge play`: a bag written by rosbags (not by us, not by ROS) served over
OpenIGTLink, in a process where every ROS import fails.

Issue 45: nothing put a bag into Slicer, and a laptop without ROS could not review one.
Here a rosbags bag with the demo robot's description, /tf, /joint_states and an image
plays into a raw OpenIGTLink reader (protocol/ only): the link poses equal forward
kinematics computed by yourdfpy at the bag's joint states (0.01 mm), the image's bytes are
the bag's; pause, seek and rate work from the Pythonic client, and after a seek the first
pose shown is the one at the seek time."""

from __future__ import annotations

import os
from pathlib import Path
import subprocess
import sys
import threading
import time
from typing import Any, Iterator

import numpy as np
import pytest

import slicer_client
from protocol.messages import Image, Message, PolyData
from protocol.naming import NameKey, device_name_for
from support import Processes, scaled, wait_until

pytest.importorskip("rosbags", reason="the test extra's rosbags writes the bags")
pytest.importorskip("mcap_ros2", reason="the play extra (mcap-ros2-support) reads them")

from bags import NS, RobotBag  # noqa: E402
from play_support import RawReader, expected_link_poses, start_player  # noqa: E402

pytestmark = pytest.mark.integration

@pytest.fixture()
def raw_reader() -> Iterator[list[RawReader]]:
    readers: list[RawReader] = []
    yield readers
    for reader in readers:
        reader.close()


def link_devices(reply: dict[str, Any]) -> dict[str, str]:
    return {link["link"]: link["device"] for link in reply["result"]["links"]}


def assert_poses(reader: RawReader, devices: dict[str, str],
                 expected: dict[str, np.ndarray]) -> None:
    def all_match(_latest: dict[str, Message]) -> bool:
        for link, device in devices.items():
            matrix = reader.poses.get(device)
            if matrix is None or not np.allclose(matrix[:3, 3], expected[link][:3, 3],
                                                 atol=0.01):
                return False
        return True
    try:
        reader.wait(all_match, "every link at its forward-kinematics pose")
    except AssertionError:
        for link, device in devices.items():  # say which link and by how much
            got = reader.poses.get(device)
            got_t = None if got is None else got[:3, 3]
            print(link, got_t, expected[link][:3, 3])
        raise
    for link, device in devices.items():
        matrix = reader.poses[device]
        np.testing.assert_allclose(matrix[:3, :3], expected[link][:3, :3], atol=1e-5)


# ------------------------------------------------------------------ tests


def test_the_no_ros_guard_refuses_rclpy(no_ros: dict[str, str]) -> None:
    """The environment the player runs in below: importing rclpy fails there."""
    done = subprocess.run([sys.executable, "-c", "import rclpy"], capture_output=True,
                          text=True, env={**os.environ, **no_ros}, timeout=scaled(60))
    assert done.returncode != 0
    assert "NO-ROS GUARD: refused import of rclpy" in done.stderr
    assert "ImportError: no ROS here: rclpy" in done.stderr


def test_a_rosbags_bag_plays_into_a_raw_reader_without_ros(
        processes: Processes, no_ros: dict[str, str], robot_bag: RobotBag,
        demo_files: tuple[str, str], raw_reader: list[RawReader]) -> None:
    """Paused 1.2 s in: the robot's links at forward kinematics of the joint state then,
    under the bag's world -> base_link; the image then, byte for byte; the devices named
    as the live daemon names them."""
    player, port = start_player(processes, no_ros, str(robot_bag.mcap), "--paused",
                                "--start", "1.2", "--package-path", demo_files[1])
    reader = RawReader(port)
    raw_reader.append(reader)
    hello = reader.command("hello", {})
    assert hello["ok"] and "seek_playback" in hello["result"]["ops"]
    reply = reader.command("create_robot", {"name": "demo", "fixed_frame": "world"})
    assert reply["ok"], reply
    devices = link_devices(reply)
    assert devices == {link: device_name_for(NameKey.robot_link("demo", link))
                       for link in devices}
    t = robot_bag.times[0] - NS // 100 + int(1.2 * NS)  # T0 + 1.2 s
    index = robot_bag.state_at(t)
    expected = expected_link_poses(robot_bag, index)
    assert set(devices) == set(expected)
    assert_poses(reader, devices, expected)
    # Every visual's mesh came (by the package path), under its link.
    visuals = [v["device"] for v in reply["result"]["visuals"]]
    assert len(visuals) >= 8
    reader.wait(lambda latest: all(isinstance(getattr(latest.get(v), "body", None), PolyData)
                                   for v in visuals), "every mesh")
    # The image at 1.2 s, intact.
    sub = reader.command("create_subscriber", {"topic": "/camera/image",
                                               "type": "sensor_msgs/msg/Image"})
    assert sub["ok"], sub
    device = sub["result"]["device"]
    assert device == device_name_for(NameKey.subscriber("/camera/image"))
    reader.wait(lambda latest: isinstance(getattr(latest.get(device), "body", None), Image),
                "the image at the clock's time")
    image = reader.latest[device]
    pixels = np.asarray(image.body.pixels)
    assert pixels.shape == (1, 48, 64, 3)
    assert pixels.tobytes() == robot_bag.image_at(t)
    assert image.metadata["ros2.type"] == "sensor_msgs/msg/Image"
    # A tf lookup, as the daemon answers it.
    lookup = reader.command("lookup_transform", {"parent": "world", "child": "tool_flange"})
    assert lookup["ok"], lookup
    np.testing.assert_allclose(np.asarray(lookup["result"]["matrix"]),
                               expected["tool_flange"], atol=1e-6)
    # Played to the end at rate 20: the last state shown.
    reader.command("set_playback_rate", {"rate": 20})
    reader.command("resume_playback")
    wait_until(lambda: reader.command("playback_status")["result"]["ended"], timeout=30,
               what="the end of the bag")
    assert_poses(reader, devices, expected_link_poses(robot_bag, len(robot_bag.times) - 1))
    assert "NO-ROS GUARD" not in player.output()
    assert "Traceback" not in player.output()


def test_pause_seek_and_rate_from_the_pythonic_client(
        processes: Processes, no_ros: dict[str, str], robot_bag: RobotBag,
        demo_files: tuple[str, str]) -> None:
    """After a seek the first pose shown is the one at the seek time; pause holds the
    clock; the rate moves it that many times faster; the clock is the bag's."""
    player, port = start_player(processes, no_ros, str(robot_bag.mcap), "--paused",
                                "--package-path", demo_files[1])
    poses: list[tuple[float, np.ndarray]] = []
    lock = threading.Lock()

    def on_link(kind: str, link: str, value: Any) -> None:
        if kind == "transform" and link == "tool_flange":
            with lock:
                poses.append((time.monotonic(), np.array(value)))

    with slicer_client.connect("127.0.0.1", port) as ros:
        status = ros.playback()
        assert status.paused and status.offset == 0.0 and status.duration == pytest.approx(2.0)
        assert (status.start.sec, status.start.nanosec) == divmod(robot_bag.times[0]
                                                                  - NS // 100, NS)
        robot = ros.robot("demo", fixed_frame="world", callback=on_link)
        wait_until(lambda: robot.state == "loaded", timeout=30, what="the robot")
        assert robot.transforms == {}  # at the bag's start: no joint state yet, no pose
        for offset in (1.5, 0.3, 1.93):
            with lock:
                poses.clear()
            after = ros.seek(offset)
            assert after.paused and after.offset == pytest.approx(offset)
            t = robot_bag.times[0] - NS // 100 + int(round(offset * NS))
            want = expected_link_poses(robot_bag, robot_bag.state_at(t))["tool_flange"]
            wait_until(lambda: bool(poses), timeout=30, what="a pose after the seek")
            with lock:
                first = poses[0][1]
            np.testing.assert_allclose(first[:3, 3], want[:3, 3], atol=0.01)
        # Paused: the clock holds (read twice, the bag's topics listed between).
        held = ros.playback().offset
        assert {t["topic"] for t in ros.list_topics()} >= {"/tf", "/joint_states"}
        assert ros.playback().offset == held
        # Running at rate 2, the bag's clock moves twice as fast as the wall clock: each
        # status is read between two clock readings here, which bound the ratio.
        ros.seek(0.0)
        ros.set_rate(2.0)
        ros.resume()
        a0 = time.monotonic()
        first = ros.playback()
        a1 = time.monotonic()
        wait_until(lambda: ros.playback().offset >= 0.4, timeout=30,
                   what="0.4 s of bag time")
        b0 = time.monotonic()
        second = ros.playback()
        b1 = time.monotonic()
        assert second.offset < second.duration  # not held at the end: the bracket holds
        moved = second.offset - first.offset
        assert 2.0 * (b0 - a1) - 1e-3 <= moved <= 2.0 * (b1 - a0) + 1e-3, (moved, b0 - a1,
                                                                          b1 - a0)
        # A seek while running: by its reply the robot is at the seek time (its state then,
        # or one played since), never where it was before.
        after = ros.seek(0.3)
        assert not after.paused
        pose = robot.transforms["tool_flange"]
        seek_t = robot_bag.times[0] - NS // 100 + int(0.3 * NS)
        first = robot_bag.state_at(seek_t)
        later = robot_bag.state_at(seek_t + int((after.offset - 0.3 + 0.5) * NS))
        assert any(np.allclose(pose[:3, 3], expected_link_poses(robot_bag, k)["tool_flange"]
                               [:3, 3], atol=0.01) for k in range(first, later + 1))
        paused = ros.pause()
        assert paused.paused and paused.rate == 2.0
        assert (paused.time.sec * NS + paused.time.nanosec
                == robot_bag.times[0] - NS // 100 + int(round(paused.offset * NS)))
    assert "NO-ROS GUARD" not in player.output()


def test_the_live_daemons_refusal_names_the_player() -> None:
    """On the live daemon the playback ops are refused, saying where they belong."""
    from bridge.playback.refusals import LiveRefusals
    from protocol import commands as c
    from protocol.commands import CommandFailedError, ErrorCode

    handlers = LiveRefusals().handlers()
    assert set(handlers) == set(c.player_ops()) and c.SeekPlayback in handlers
    with pytest.raises(CommandFailedError) as refused:
        handlers[c.SeekPlayback](c.SeekPlayback(offset=1.0), None)
    assert refused.value.error_code == ErrorCode.NOT_SUPPORTED
    assert "slicer-ros2-bridge play" in str(refused.value)


def test_point_clouds_and_text_play_as_the_daemon_sends_them(
        processes: Processes, no_ros: dict[str, str], tmp_path: Path,
        raw_reader: list[RawReader]) -> None:
    """A rosbags bag with a sensor_msgs/PointCloud2 and a std_msgs/String: the cloud as
    POLYDATA points in mm, the text as STRING, on the daemon's device names."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from bags import T0, typestore

    ts = typestore()
    T = ts.types
    points = np.array([[0.1, 0.2, 0.3], [-0.5, 0.0, 1.25], [2.0, -1.0, 0.004]], np.float32)
    fields = [T["sensor_msgs/msg/PointField"](name=name, offset=4 * i, datatype=7, count=1)
              for i, name in enumerate("xyz")]
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
        sec=T0 // NS, nanosec=0), frame_id="world")
    cloud = T["sensor_msgs/msg/PointCloud2"](
        header=header, height=1, width=len(points), fields=fields, is_bigendian=False,
        point_step=12, row_step=12 * len(points),
        data=np.frombuffer(points.tobytes(), np.uint8), is_dense=True)
    folder = tmp_path / "cloud"
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        c1 = writer.add_connection("/cloud", "sensor_msgs/msg/PointCloud2", typestore=ts)
        c2 = writer.add_connection("/note", "std_msgs/msg/String", typestore=ts)
        writer.write(c1, T0, ts.serialize_cdr(cloud, "sensor_msgs/msg/PointCloud2"))
        writer.write(c2, T0 + 1, ts.serialize_cdr(T["std_msgs/msg/String"](data="incision"),
                                                  "std_msgs/msg/String"))
    player, port = start_player(processes, no_ros, str(folder), "--paused", "--start", "1")
    reader = RawReader(port)
    raw_reader.append(reader)
    devices = {}
    for topic, type_name in (("/cloud", "PointCloud2"), ("/note", "String")):
        reply = reader.command("create_subscriber", {"topic": topic, "type": type_name})
        assert reply["ok"], reply
        devices[topic] = reply["result"]["device"]
        assert devices[topic] == device_name_for(NameKey.subscriber(topic))
    reader.wait(lambda latest: all(d in latest for d in devices.values()), "both messages")
    polydata = reader.latest[devices["/cloud"]].body
    assert isinstance(polydata, PolyData)
    np.testing.assert_allclose(np.asarray(polydata.points), points * 1000.0, rtol=1e-6)
    text = reader.latest[devices["/note"]]
    assert text.body.text == "incision"
    assert text.metadata["ros2.type"] == "std_msgs/msg/String"
    assert "Traceback" not in player.output() and "NO-ROS GUARD" not in player.output()


def test_loop_starts_again_at_the_end(processes: Processes, no_ros: dict[str, str],
                                      robot_bag: RobotBag) -> None:
    """--loop: at the end the clock goes back to the start and plays on, never ended."""
    player, port = start_player(processes, no_ros, str(robot_bag.mcap), "--loop",
                                "--rate", "20")
    with slicer_client.connect("127.0.0.1", port) as ros:
        seen: list[float] = []

        def wrapped() -> bool:
            status = ros.playback()
            assert status.loop and not status.ended
            seen.append(status.offset)
            return len(seen) > 1 and seen[-1] < seen[-2]
        wait_until(wrapped, timeout=30, what="the clock going back to the start")
    assert "played to the end" not in player.output()


def test_markers_play_as_the_daemon_shows_them(processes: Processes, no_ros: dict[str, str],
                                               tmp_path: Path) -> None:
    """A rosbags bag with a MarkerArray (a cube, frame-locked to base_link) and /tf moving
    base_link: the marker's model comes in mm in its frame and its frame's pose with it,
    so the cube sits where tf put base_link then, 100 mm above it."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from bags import T0, base_translation, tf_message, typestore

    ts = typestore()
    T = ts.types
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
        sec=T0 // NS, nanosec=0), frame_id="base_link")
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.1),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    cube = T["visualization_msgs/msg/Marker"](
        header=header, ns="tools", id=1, type=1, action=0, pose=pose,
        scale=T["geometry_msgs/msg/Vector3"](x=0.02, y=0.02, z=0.02),
        color=T["std_msgs/msg/ColorRGBA"](r=1.0, g=0.0, b=0.0, a=1.0),
        lifetime=T["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=True,
        points=[], colors=[], texture_resource="",
        texture=T["sensor_msgs/msg/CompressedImage"](header=header, format="",
                                                    data=np.zeros(0, np.uint8)),
        uv_coordinates=[], text="", mesh_resource="",
        mesh_file=T["visualization_msgs/msg/MeshFile"](filename="",
                                                       data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False)
    folder = tmp_path / "markers"
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
        markers = writer.add_connection("/markers", "visualization_msgs/msg/MarkerArray",
                                        typestore=ts)
        for k in range(10):
            t = T0 + k * NS // 10
            writer.write(tf, t, ts.serialize_cdr(tf_message(ts, t, "world", "base_link",
                                                            base_translation(k)),
                                                 "tf2_msgs/msg/TFMessage"))
        writer.write(markers, T0 + 1, ts.serialize_cdr(
            T["visualization_msgs/msg/MarkerArray"](markers=[cube]),
            "visualization_msgs/msg/MarkerArray"))
    player, port = start_player(processes, no_ros, str(folder), "--paused", "--start", "0.55")
    with slicer_client.connect("127.0.0.1", port) as ros:
        shown = ros.markers("/markers", "MarkerArray", "world")
        shown.wait_for_markers(lambda m: len(m) == 1, timeout=30)
        item = shown.find("tools", 1)
        assert item is not None and item.kind == "cube"
        points = shown.points_in_fixed_frame(item)
        assert points is not None
        want = np.array(base_translation(5)) * 1000.0 + [0.0, 0.0, 100.0]
        np.testing.assert_allclose(points.mean(axis=0), want, atol=0.01)
        np.testing.assert_allclose(points.max(axis=0) - points.min(axis=0), [20.0] * 3,
                                   atol=1e-3)
    assert "Traceback" not in player.output() and "NO-ROS GUARD" not in player.output()


def test_tf_in_another_cdr_encoding_is_read_by_the_bags_decoder(
        processes: Processes, no_ros: dict[str, str], tmp_path: Path) -> None:
    """/tf goes through the daemon's own reader of plain little-endian CDR; a bag whose tf
    is big-endian CDR (rosbags writes it so on request) is read by mcap-ros2-support from
    the bag's schema instead, with the same values."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from bags import T0, tf_message, typestore

    ts = typestore()
    folder = tmp_path / "big_endian"
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
        for k in range(3):
            writer.write(tf, T0 + k * NS // 10, bytes(ts.serialize_cdr(
                tf_message(ts, T0 + k * NS // 10, "world", "probe", (0.1 * k, -0.25, 1.5),
                           (0.0, 0.0, 0.6, 0.8)),
                "tf2_msgs/msg/TFMessage", little_endian=False)))
    player, port = start_player(processes, no_ros, str(folder), "--paused", "--start", "0.15")
    with slicer_client.connect("127.0.0.1", port) as ros:
        matrix = ros.lookup_transform("world", "probe", timeout=10)
    np.testing.assert_allclose(matrix[:3, 3], [100.0, -250.0, 1500.0], atol=1e-6)
    np.testing.assert_allclose(matrix[:3, :3], [[0.28, -0.96, 0], [0.96, 0.28, 0], [0, 0, 1]],
                               atol=1e-9)
    assert "Traceback" not in player.output() and "skipped" not in player.output()


def test_beyond_loopback_only_loopback_clients_move_the_clock(robot_bag: RobotBag,
                                                              tmp_path: Path) -> None:
    """The daemon's rule for writers holds in the player: listening on every address, a
    client from another machine may read but not pause, seek or set the rate."""
    import asyncio

    from bridge.playback.bag import open_bag
    from bridge.playback.player import Player, PlayOptions
    from protocol import commands as c

    async def grants() -> tuple[bool, bool, bool]:
        bag = open_bag(robot_bag.mcap)
        player = Player(PlayOptions(bag=robot_bag.mcap, host="0.0.0.0", port=0), bag,
                        asyncio.get_running_loop(), tmp_path)
        try:
            remote = player.policy.grant_at_accept("192.0.2.7")
            local = player.policy.grant_at_accept("127.0.0.1")
            seek = c.parse_request("seek_playback", '{"offset": 1}')
            return remote.writes, local.writes, type(seek).writes
        finally:
            player.dispatcher.close()
            player.heavy.close()
            bag.close()
    assert asyncio.run(grants()) == (False, True, True)


def test_the_reference_facade_reads_a_played_bag(processes: Processes, no_ros: dict[str, str],
                                                robot_bag: RobotBag,
                                                demo_files: tuple[str, str]) -> None:
    """SlicerROS2's API (the CamelCase facade) against a player as against the daemon: a
    subscriber node gets the bag's image, a tf lookup node the pose at the clock's time."""
    player, port = start_player(processes, no_ros, str(robot_bag.mcap), "--paused",
                                "--start", "1.0", "--package-path", demo_files[1])
    ros = slicer_client.connect("127.0.0.1", port)
    try:
        ros_logic = ros.logic
        ros_node = ros_logic.GetDefaultROS2Node()
        sub = ros_node.CreateAndAddSubscriberNode("Image", "/camera/image")
        lookup = ros_node.CreateAndAddTf2LookupNode("world", "tool_flange")

        t = robot_bag.times[0] - NS // 100 + NS
        want = expected_link_poses(robot_bag, robot_bag.state_at(t))["tool_flange"]

        def looked_up() -> np.ndarray:
            matrix = lookup.GetMatrixTransformToParent()
            if matrix is None:
                return np.zeros(3)
            return np.array([matrix.GetElement(i, 3) for i in range(3)])

        def arrived() -> bool:  # the lookup's node holds the identity until its first value
            ros_logic.Spin()
            return bool(sub.GetNumberOfMessages()) and np.allclose(looked_up(), want[:3, 3],
                                                                   atol=0.01)
        wait_until(arrived, timeout=30, what=f"the image and the flange at {want[:3, 3]}")
        pixels = np.asarray(sub.GetLastMessage())
        assert pixels.tobytes() == robot_bag.image_at(t)
    finally:
        ros.close()
    assert "NO-ROS GUARD" not in player.output() and "Traceback" not in player.output()
