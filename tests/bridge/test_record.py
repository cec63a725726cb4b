"""Recording a session as a standard ROS 2 bag (issue 45, the record half).

The bags are read back by rosbags, a reader independent of the writer (Foxglove's mcap),
and checked against what a plain rclpy subscriber in another process received in the same
window, byte for byte (`tests/peers/raw_recorder_witness.py`)."""

from __future__ import annotations

import base64
import json
import os
import re
import signal
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest

from protocol.commands import ErrorCode
from tests.support import (Child, Processes, RunningDaemon, refused, scaled, start_daemon,
                           wait_until)

pytestmark = pytest.mark.ros

rosbags = pytest.importorskip("rosbags", reason="the test extra's rosbags reads the bags")
from rosbags.highlevel import AnyReader  # noqa: E402
from mcap.reader import make_reader  # noqa: E402

import slicer_client  # noqa: E402

TF = "tf2_msgs/msg/TFMessage"


def bag_messages(path: Path) -> tuple[dict[str, list[bytes]], dict[str, Any], AnyReader]:
    """topic -> raw messages in order, topic -> connection (rosbags)."""
    found: dict[str, list[bytes]] = defaultdict(list)
    with AnyReader([path]) as reader:
        connections = {c.topic: c for c in reader.connections}
        for connection, _, raw in reader.messages():
            found[connection.topic].append(bytes(raw))
    return found, connections, reader


def witnessed(path: Path) -> dict[str, list[bytes]]:
    seen: dict[str, list[bytes]] = defaultdict(list)
    for line in path.read_text().splitlines():
        entry = json.loads(line)
        seen[entry["topic"]].append(base64.b64decode(entry["data"]))
    return seen


def image_numbers(bag: Path) -> list[int]:
    """The numbers of stream_publisher.py's images in a bag cut short by a full disk (read
    with rosbags): at least 5, consecutive (none lost inside)."""
    with AnyReader([bag]) as reader:
        frames = [reader.deserialize(raw, connection.msgtype).header.frame_id
                  for connection, _, raw in reader.messages()]
    numbers = [int(f.split(":")[1]) for f in frames]
    assert len(numbers) >= 5 and numbers == list(range(numbers[0], numbers[0] + len(numbers)))
    return numbers


def unpadded(data: bytes) -> bytes:
    """A payload without its trailing zeros (padding, and a string's terminator): two
    payloads equal but for padding compare equal."""
    return data.rstrip(b"\0")


def counts(child: Child) -> dict[str, int]:
    latest: dict[str, int] = {}
    for topic, n in re.findall(r"COUNT (\S+) (\d+)", child.output()):
        latest[topic] = int(n)
    return latest


def recorded(status: dict[str, Any]) -> dict[str, int]:
    return {t["topic"]: t["messages"] for t in status["topics"]}


def start_demo(processes: Processes) -> RunningDaemon:
    child = processes.bridge("demo", "--port", "0")
    line = child.wait_for_output(" (OpenIGTLink); ROS node", timeout=90)
    listening = re.search(r"listening on \S+:(\d+) \(OpenIGTLink\)", line)
    assert listening, line
    child.wait_for_output("Stop with Ctrl-C", timeout=90)
    return RunningDaemon(child, int(listening.group(1)))


def test_a_demo_session_recorded_by_the_daemon_holds_what_a_subscriber_saw(
        processes: Processes, tmp_path: Path) -> None:
    demo = start_demo(processes)
    poses = processes.python("poses", "stream_publisher.py", "/tool_pose", "200")
    poses.wait_for_output("READY")
    bag = tmp_path / "session.mcap"
    with slicer_client.connect("127.0.0.1", demo.port) as ros:
        ros.subscribe("/tool_pose", "PoseStamped")  # a stream Slicer receives
        to_ros = ros.publisher("/slicer_notes", "String")  # what Slicer sends to ROS
        wait_until(lambda: "demo" in str(ros.command("list_robots")), what="the demo robot")
        rec = ros.record(str(bag))
        wanted = {"/tf", "/tf_static", "/joint_states", "/robot_description", "/tool_pose",
                  "/slicer_notes"}
        wait_until(lambda: wanted <= set(rec.counts), timeout=30,
                   what=f"the recording to take {sorted(wanted)}")
        witness = processes.python(
            "witness", "raw_recorder_witness.py", str(tmp_path / "witness.jsonl"),
            f"/tf={TF}", f"/tf_static={TF}", "/joint_states=sensor_msgs/msg/JointState",
            "/robot_description=std_msgs/msg/String",
            "/tool_pose=geometry_msgs/msg/PoseStamped", "/slicer_notes=std_msgs/msg/String",
            "--latched", "/tf_static", "/robot_description")
        witness.wait_for_output("READY", timeout=30)
        sent = 0

        def noted() -> bool:
            nonlocal sent
            sent += 1
            to_ros.publish(f"note {sent}")
            return counts(witness).get("/slicer_notes", 0) >= 5
        wait_until(noted, timeout=30, what="the witness to see Slicer's notes")
        wait_until(lambda: all(counts(witness).get(t, 0) >= 100
                               for t in ("/tf", "/tool_pose", "/joint_states")),
                   timeout=60, what="the witness to see 100 of each stream")
        wait_until(lambda: {"/tf_static", "/robot_description"} <= set(counts(witness)),
                   what="the latched topics at the witness")
        witness.stop()
        # What the witness saw last is in flight to the recorder too: the streams go on
        # until each has grown past where it was.
        at_stop = recorded(rec.status())
        wait_until(lambda: all(recorded(rec.status())[t] > at_stop[t] + 20
                               for t in ("/tf", "/tool_pose", "/joint_states")),
                   what="the recording to go past the witness's window")
        final = rec.stop()
        assert not rec.running and final["dropped"] == 0 and "error" not in final
        assert ros.command("list_topics")  # the daemon serves on

    in_bag, connections, _ = bag_messages(bag)
    seen = witnessed(tmp_path / "witness.jsonl")
    assert set(seen) == wanted
    for topic, messages in seen.items():
        # What the daemon publishes reaches its own recorder inside its participant, without
        # the zeros Fast DDS pads a payload with on the wire to a multiple of 4 bytes (the
        # witness gets those): the same CDR message; every other topic is byte-equal.
        same = unpadded if topic == "/slicer_notes" else bytes
        kept = {same(m) for m in in_bag[topic]}
        missing = [m for m in messages if same(m) not in kept]
        assert not missing, f"{topic}: {len(missing)} of {len(messages)} not in the bag"
    assert {t: c.msgtype for t, c in connections.items() if t in wanted} == {
        "/tf": TF, "/tf_static": TF, "/joint_states": "sensor_msgs/msg/JointState",
        "/robot_description": "std_msgs/msg/String",
        "/tool_pose": "geometry_msgs/msg/PoseStamped", "/slicer_notes": "std_msgs/msg/String"}
    assert final["messages"] == sum(len(m) for m in in_bag.values())
    # The publishers' QoS, as rosbag2 keeps it: a player latches /tf_static again.
    latched = connections["/tf_static"].ext.offered_qos_profiles
    assert latched and {q.durability.name for q in latched} == {"TRANSIENT_LOCAL"}

    # Its schemas decode it (rosbags builds the types from the bag's own definitions).
    with AnyReader([bag]) as reader:
        values: dict[str, Any] = {}
        for connection, _, raw in reader.messages():
            values.setdefault(connection.topic, reader.deserialize(raw, connection.msgtype))
    assert values["/slicer_notes"].data.startswith("note ")
    assert "<robot" in values["/robot_description"].data
    assert values["/tool_pose"].pose.position.x > 0
    assert values["/tf"].transforms[0].child_frame_id

    # A standard ROS 2 MCAP: profile, encodings, full definitions, the meshes attached.
    with bag.open("rb") as stream:
        reader = make_reader(stream)
        header = reader.get_header()
        summary = reader.get_summary()
        attachments = {a.name: a.data for a in reader.iter_attachments()}
    assert header.profile == "ros2"
    assert summary is not None
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
    pose_schema = next(s for s in summary.schemas.values()
                       if s.name == "geometry_msgs/msg/PoseStamped").data.decode()
    assert "MSG: geometry_msgs/Pose\n" in pose_schema and "MSG: std_msgs/Header\n" in pose_schema
    meshes = {name for name in attachments if name.endswith((".stl", ".obj", ".dae"))}
    assert meshes == {f"package://slicer_ros2_bridge_demo/meshes/{name}" for name in
                      ("shoulder.stl", "upper_arm.obj", "forearm.dae", "wrist_2.stl")}
    assert all(attachments[name] for name in meshes)


def test_the_op_is_a_write_and_bad_paths_are_refused_by_type(
        processes: Processes, tmp_path: Path) -> None:
    key = tmp_path / "writers.key"
    assert processes.bridge("keygen", str(key)).popen.wait(scaled(30)) == 0
    # /sys: a record folder the daemon may not write in (even as root).
    daemon = start_daemon(processes, "--key-file", str(key), "--record-dir", str(tmp_path),
                          "--record-dir", "/sys")
    poses = processes.python("poses", "stream_publisher.py", "/rec_pose", "100")
    poses.wait_for_output("READY")
    target = tmp_path / "a.mcap"
    with slicer_client.connect("127.0.0.1", daemon.port) as reader:
        error = refused(lambda: reader.record(str(target), ["/rec_pose"]))
        assert error.code == ErrorCode.FORBIDDEN and not target.exists()
        assert reader.list_topics()  # served on
    with slicer_client.connect("127.0.0.1", daemon.port, key_file=str(key)) as ros:
        cases = {
            str(tmp_path / "no_such_folder" / "a.mcap"): ErrorCode.NOT_FOUND,
            "/sys/a.mcap": ErrorCode.FORBIDDEN,  # not writable (even for root)
            "/var/tmp/a.mcap": ErrorCode.FORBIDDEN,  # outside the record folders
            "relative.mcap": ErrorCode.OUT_OF_RANGE,
            str(tmp_path / "a.bag"): ErrorCode.OUT_OF_RANGE,
        }
        existing = tmp_path / "kept.mcap"
        existing.write_bytes(b"precious")
        cases[str(existing)] = ErrorCode.ALREADY_EXISTS
        for path, code in cases.items():
            error = refused(lambda p=path: ros.record(p, ["/rec_pose"]))
            assert (error.code, error.field) == (code, "path"), (path, str(error))
        assert existing.read_bytes() == b"precious"
        with ros.record(str(target), ["/rec_pose"]) as rec:
            error = refused(lambda: ros.record(str(target), ["/rec_pose"]))
            assert error.code == ErrorCode.ALREADY_EXISTS  # one recording per file
            wait_until(lambda: rec.messages >= 50, what="50 poses recorded")
            listed = ros.list_bridges()["recordings"]
            assert [(r["path"], r["running"]) for r in listed] == [(str(target), True)]
        assert rec.status()["running"] is False
        again = ros.record(str(existing), ["/rec_pose"], overwrite=True)
        wait_until(lambda: again.messages >= 1, what="a pose in the overwritten bag")
        final = again.stop()
        error = refused(lambda: ros.command("stop_recording", {"path": str(existing)}))
        assert error.code == ErrorCode.NOT_FOUND
    in_bag, connections, _ = bag_messages(target)
    assert len(in_bag["/rec_pose"]) == rec.stop()["messages"] >= 50
    assert connections["/rec_pose"].msgtype == "geometry_msgs/msg/PoseStamped"
    assert len(bag_messages(existing)[0]["/rec_pose"]) == final["messages"]


def test_the_command_line_recorder_and_a_full_disk(processes: Processes,
                                                   tmp_path: Path) -> None:
    images = processes.python("images", "stream_publisher.py", "/rec_image", "30",
                              "--image", "320x240")
    images.wait_for_output("READY")
    bag = tmp_path / "images.mcap"
    limit = 3 * 1024 * 1024  # about 13 images: RLIMIT_FSIZE stands for a full disk
    recorder = processes.start("record", ["prlimit", f"--fsize={limit}", "--",
                                          *_bridge("record", str(bag), "/rec_image",
                                                   "/not_there")])
    code = recorder.popen.wait(scaled(60))
    output = recorder.output()
    assert code == 1, output
    assert "recording stopped: the file size limit (RLIMIT_FSIZE) is reached" in output
    assert "the bag is closed and readable" in output
    assert "/not_there: not recorded: no publisher yet" in output or \
        "/not_there: not recorded: not in the ROS graph yet" in output
    assert os.path.getsize(bag) <= limit
    numbers = image_numbers(bag)
    # The summary counts what is in the bag; what the disk refused is counted as dropped.
    counted = re.search(r"/rec_image \[sensor_msgs/msg/Image\]: (\d+) messages, (\d+) "
                        r"dropped", output)
    assert counted and int(counted.group(1)) == len(numbers) and int(counted.group(2)) >= 1

    # Without a limit nor topics (every topic of the graph): Ctrl-C ends it with the bag
    # finished (its summary written).
    whole = tmp_path / "whole.mcap"
    recorder = processes.start("record", _bridge("record", str(whole)))
    recorder.wait_for_output("recording /rec_image", timeout=30)
    wait_until(lambda: whole.stat().st_size > 2_000_000, timeout=30,
               what="a few images on disk while recording")
    recorder.popen.send_signal(signal.SIGINT)
    assert recorder.popen.wait(scaled(30)) == 0, recorder.output()
    with whole.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics is not None
    written = re.search(r"/rec_image \[sensor_msgs/msg/Image\]: (\d+) messages",
                        recorder.output())
    assert written and int(written.group(1)) >= 10
    in_summary = {c.topic: summary.statistics.channel_message_counts.get(i, 0)
                  for i, c in summary.channels.items()}
    assert in_summary["/rec_image"] == int(written.group(1))
    assert summary.statistics.message_count == int(re.search(
        r"whole\.mcap: (\d+) messages", recorder.output()).group(1))
    refusal = processes.start("record", _bridge("record", str(whole), "/rec_image"))
    assert refusal.popen.wait(scaled(30)) == 2
    assert "exists" in refusal.output() and "overwrite" in refusal.output()


def _bridge(*args: str) -> list[str]:
    import sys

    return [sys.executable, "-u", "-m", "bridge.console", *args]


def test_a_full_disk_stops_the_daemon_s_recording_readable_and_it_serves_on(
        processes: Processes, tmp_path: Path) -> None:
    """A real full file system (a 3 MiB tmpfs mounted here, as root): the recording stops
    with an error in its status, the bag stays readable, the daemon serves on."""
    import subprocess

    disk = tmp_path / "small-disk"
    disk.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(disk)],
                             capture_output=True, text=True)
    if mounted.returncode != 0:
        pytest.skip(f"needs to mount a small tmpfs (root): {mounted.stderr.strip()}")
    try:
        daemon = start_daemon(processes)
        images = processes.python("images", "stream_publisher.py", "/full_image", "30",
                                  "--image", "320x240")
        images.wait_for_output("READY")
        bag = disk / "full.mcap"
        with slicer_client.connect("127.0.0.1", daemon.port) as ros:
            rec = ros.record(str(bag), ["/full_image"])
            wait_until(lambda: not rec.status()["running"], timeout=60,
                       what="the disk to fill up")
            status = rec.status()
            assert status["error"].startswith("recording stopped: the disk is full")
            assert ros.list_topics() and ros.command("hello")["ops"]  # served on
            final = rec.stop()
            assert final["error"] == status["error"]
        numbers = image_numbers(bag)
        assert final["messages"] == len(numbers) and final["dropped"] >= 1
    finally:
        subprocess.run(["umount", "-l", str(disk)], check=False)
