"""`slicer-ros2-bridge play` on bad bags: each problem is a clear error or a named skip,
nothing crashes, and the good parts play (issue 45). Also meshes carried in the bag as
MCAP attachments (no --package-path).

The damaged bags are made from a rosbags bag with Foxglove's own MCAP writer (chunks,
zstd, attachments, a channel without schema, one whose schema does not parse), then cut
or patched byte-wise where the damage is the point."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np
import pytest

import slicer_client
from protocol.commands import ErrorCode
from support import Processes, refused, wait_until

pytest.importorskip("rosbags", reason="the test extra's rosbags writes the bags")
pytest.importorskip("mcap_ros2", reason="the play extra (mcap-ros2-support) reads them")

from bags import NS, RobotBag, write_robot_bag  # noqa: E402
from play_support import expected_link_poses, start_player  # noqa: E402

pytestmark = pytest.mark.integration

DEMO_MESHES = "package://slicer_ros2_bridge_demo/meshes/"


def rewrite(source: Path, target: Path, *, chunk_size: int = 1 << 20,
            extra: Optional[Callable[[Any], None]] = None, leave_out: str = "") -> Path:
    """``source``'s schemas, channels and messages written again by mcap's writer (zstd
    chunks of ``chunk_size``), with what ``extra(writer)`` adds, without topic
    ``leave_out``."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with source.open("rb") as f_in, target.open("wb") as f_out:
        reader = make_reader(f_in)
        writer = Writer(f_out, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        writer.start(profile="ros2", library="test")
        summary = reader.get_summary()
        assert summary is not None
        schemas = {sid: writer.register_schema(s.name, s.encoding, s.data)
                   for sid, s in summary.schemas.items()}
        channels = {cid: writer.register_channel(ch.topic, ch.message_encoding,
                                                 schemas[ch.schema_id])
                    for cid, ch in summary.channels.items() if ch.topic != leave_out}
        if extra is not None:
            extra(writer)
        for _, channel, message in reader.iter_messages(log_time_order=True):
            if channel.id in channels:
                writer.add_message(channels[channel.id], message.log_time, message.data,
                                   message.publish_time)
        writer.finish()
    return target


def with_meshes_and_bad_topics(mesh_folder: Path) -> Callable[[Any], None]:
    def extra(writer: Any) -> None:
        for path in sorted(mesh_folder.iterdir()):
            writer.add_attachment(0, 0, DEMO_MESHES + path.name, "application/octet-stream",
                                  path.read_bytes())
        no_schema = writer.register_channel("/no_schema", "cdr", 0)
        broken = writer.register_channel("/broken", "cdr", writer.register_schema(
            "pkg/msg/Broken", "ros2msg", b"this is ][ not a message definition"))
        for k in range(3):
            writer.add_message(no_schema, 1_700_000_000 * NS + k * NS // 2, b"\0\1\0\0", 0)
            writer.add_message(broken, 1_700_000_000 * NS + k * NS // 2, b"\0\1\0\0", 0)
    return extra


def play_to_end(ros: slicer_client.Client) -> None:
    ros.set_rate(50.0)
    ros.resume()
    wait_until(lambda: ros.playback().ended, timeout=60, what="the end of the bag")


def tool_pose(robot: Any) -> np.ndarray:
    return robot.transforms["tool_flange"]


def test_meshes_from_attachments_and_topics_without_a_readable_schema(
        processes: Processes, no_ros: dict[str, str], robot_bag: RobotBag,
        demo_files: tuple[str, str], tmp_path: Path) -> None:
    """Meshes come from the bag itself; a channel without schema and one whose schema does
    not parse are each named once and skipped; the robot plays to its last pose."""
    mesh_folder = Path(demo_files[1].split("=", 1)[1]) / "meshes"
    bag = rewrite(robot_bag.mcap, tmp_path / "attached.mcap",
                  extra=with_meshes_and_bad_topics(mesh_folder))
    player, port = start_player(processes, no_ros, str(bag), "--paused")
    with slicer_client.connect("127.0.0.1", port) as ros:
        robot = ros.robot("demo", fixed_frame="world")
        wait_until(lambda: robot.state == "loaded", timeout=30, what="the robot")
        assert robot.warnings == []  # every mesh found, in the bag
        wait_until(lambda: robot.progress()[0] == robot.progress()[1], timeout=30,
                   what="every mesh")
        assert robot.mesh_count() >= 8
        play_to_end(ros)
        want = expected_link_poses(robot_bag, len(robot_bag.times) - 1)["tool_flange"]
        wait_until(lambda: np.allclose(tool_pose(robot)[:3, 3], want[:3, 3], atol=0.01),
                   timeout=30, what="the last pose")
    out = player.output()
    assert out.count("topic /no_schema skipped: it has no schema in the bag") == 1
    assert out.count("topic /broken skipped: it has a schema that does not parse") == 1
    assert "Traceback" not in out and "NO-ROS GUARD" not in out


def _chunk_compressions(data: bytes) -> list[int]:
    """Offsets of the compression strings of the chunks, then of their index records."""
    needle = b"\x04\x00\x00\x00zstd"
    found, at = [], data.find(needle)
    while at >= 0:
        found.append(at + 4)
        at = data.find(needle, at + 1)
    return found


def test_an_unknown_compression_and_a_corrupt_chunk_skip_their_messages_only(
        processes: Processes, no_ros: dict[str, str], robot_bag: RobotBag,
        demo_files: tuple[str, str], tmp_path: Path) -> None:
    bag = rewrite(robot_bag.mcap, tmp_path / "chunked.mcap", chunk_size=24 * 1024)
    data = bytearray(bag.read_bytes())
    names = _chunk_compressions(bytes(data))
    chunks = len(names) // 2
    assert chunks >= 6, chunks
    # Chunk 2 "compressed" with a compression nobody knows (its record and its index).
    for offset in (names[2], names[chunks + 2]):
        data[offset:offset + 4] = b"zstx"
    # Chunk 4's compressed bytes overwritten (after its compression and 8-byte size).
    inside = names[4] + 4 + 8 + 40
    data[inside:inside + 64] = bytes(range(64))
    bag.write_bytes(bytes(data))
    player, port = start_player(processes, no_ros, str(bag), "--paused",
                                "--package-path", demo_files[1])
    with slicer_client.connect("127.0.0.1", port) as ros:
        robot = ros.robot("demo", fixed_frame="world")
        wait_until(lambda: robot.state == "loaded", timeout=30, what="the robot")
        play_to_end(ros)
        want = expected_link_poses(robot_bag, len(robot_bag.times) - 1)["tool_flange"]
        wait_until(lambda: np.allclose(tool_pose(robot)[:3, 3], want[:3, 3], atol=0.01),
                   timeout=30, what="the last pose, after the bad chunks")
    out = player.output()
    assert "compressed with 'zstx', which this reader does not decompress" in out
    assert "is unreadable" in out
    assert "Traceback" not in out


def test_a_truncated_bag_plays_what_it_holds(
        processes: Processes, no_ros: dict[str, str], robot_bag: RobotBag,
        demo_files: tuple[str, str], tmp_path: Path) -> None:
    """A recording cut short (no summary, no index): read in one pass to where it ends,
    said so; the robot reaches a pose of the bag before the cut."""
    bag = rewrite(robot_bag.mcap, tmp_path / "cut.mcap", chunk_size=24 * 1024)
    data = bag.read_bytes()
    bag.write_bytes(data[:int(len(data) * 0.6)])
    player, port = start_player(processes, no_ros, str(bag), "--paused",
                                "--package-path", demo_files[1])
    with slicer_client.connect("127.0.0.1", port) as ros:
        robot = ros.robot("demo", fixed_frame="world")
        wait_until(lambda: robot.state == "loaded", timeout=30, what="the robot")
        assert 0.3 < ros.playback().duration < 2.0
        # Seeks and a new subscriber's look back read the file again from its start.
        ros.seek(0.25)
        image = ros.subscribe("/camera/image", "Image")
        wait_until(lambda: image.count >= 1, timeout=30, what="the image at 0.25 s")
        play_to_end(ros)
        wait_until(lambda: "tool_flange" in robot.transforms, timeout=30, what="a pose")
        got = tool_pose(robot)[:3, 3]
        last = max(k for k in range(len(robot_bag.times)) if np.allclose(
            expected_link_poses(robot_bag, k)["tool_flange"][:3, 3], got, atol=0.01)) \
            if any(np.allclose(expected_link_poses(robot_bag, k)["tool_flange"][:3, 3], got,
                               atol=0.01) for k in range(0, len(robot_bag.times), 1)) else -1
        assert 0 < last < len(robot_bag.times) - 1, "a pose of the bag, before the cut"
    out = player.output()
    assert "no index (the file ends early" in out
    assert "Traceback" not in out


@pytest.mark.parametrize("content", [b"", b"not a bag at all, just text\n" * 10])
def test_a_file_that_is_not_mcap_is_one_line_and_exit_2(
        processes: Processes, no_ros: dict[str, str], tmp_path: Path, content: bytes) -> None:
    bag = tmp_path / "bad.mcap"
    bag.write_bytes(content)
    child = processes.start("play", [sys.executable, "-u", "-m", "bridge.console", "play",
                                     str(bag), "--port", "0"], env=no_ros)
    assert child.popen.wait(timeout=60) == 2
    out = child.output()
    assert "slicer-ros2-bridge play:" in out and "not an MCAP file" in out
    assert "Traceback" not in out
    missing = processes.start("play", [sys.executable, "-u", "-m", "bridge.console", "play",
                                       str(tmp_path / "nowhere.mcap"), "--port", "0"],
                              env=no_ros)
    assert missing.popen.wait(timeout=60) == 2
    assert "nowhere.mcap: no such file" in missing.output()


def test_a_bag_without_a_robot_description(
        processes: Processes, no_ros: dict[str, str], tmp_path: Path) -> None:
    """A robot is refused, naming what the bag lacks; its tf and images play."""
    bag = write_robot_bag(tmp_path / "plain", "<robot name='unused'/>", states=20)
    target = rewrite(bag.mcap, tmp_path / "no_description.mcap", leave_out="/robot_description")
    player, port = start_player(processes, no_ros, str(target), "--paused", "--start", "0.1")
    with slicer_client.connect("127.0.0.1", port) as ros:
        error = refused(lambda: ros.robot("demo", timeout=10))
        assert error.code == ErrorCode.NOT_FOUND
        assert "the bag's descriptions: none" in str(error)
        matrix = ros.lookup_transform("world", "base_link", timeout=5)
        # The bag starts with state 0 (no description before it): 0.1 s in is state 10.
        assert matrix[0, 3] == pytest.approx(1000 * 0.001 * 10, abs=1e-3)
        sub = ros.subscribe("/camera/image", "Image")
        wait_until(lambda: sub.count >= 1, timeout=30, what="the image")
    assert "holds no robot description" in player.output()
    assert "Traceback" not in player.output()
