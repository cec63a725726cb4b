"""The bag writer on its own (no ROS graph): what it writes is read back by rosbags, a
bounded queue drops and counts, a file size limit closes the bag readable with the counts
of what it holds (bridge/record/bag.py)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from bridge.record.bag import BagPathError, BagWriter, check_bag_path
from bridge.record.definitions import SEPARATOR, full_definition

rosbags = pytest.importorskip("rosbags.highlevel", reason="the test extra's rosbags")


def cdr_string(text: str) -> bytes:
    """A std_msgs/String in CDR, little endian, built by hand (an independent encoder)."""
    data = text.encode() + b"\0"
    body = len(data).to_bytes(4, "little") + data
    return b"\0\x01\0\0" + body + b"\0" * (-len(body) % 4)


def test_a_bag_reads_back_with_its_full_definitions(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    bag = BagWriter(path)
    pose = bag.add_channel("/pose", "geometry_msgs/msg/PoseStamped",
                           full_definition("geometry_msgs/msg/PoseStamped"))
    text = bag.add_channel("/text", "std_msgs/msg/String", full_definition("std_msgs/msg/String"))
    sent = [cdr_string(f"message {i}") for i in range(50)]
    bag.offer(text, sent[:25])
    bag.offer(text, sent[25:])
    bag.attach("package://p/meshes/a.stl", b"solid a\nendsolid a\n")
    stats = bag.close()
    assert (stats.messages, stats.dropped, stats.attachments, stats.running) == (50, 0, 1, False)
    with rosbags.AnyReader([path]) as reader:
        got = [(c.topic, bytes(raw)) for c, _, raw in reader.messages()]
        values = [reader.deserialize(raw, c.msgtype).data for c, _, raw in reader.messages()]
        connections = {c.topic: c for c in reader.connections}
    assert got == [("/text", m) for m in sent]
    assert values == [f"message {i}" for i in range(50)]
    assert set(connections) == {"/pose", "/text"} and pose == 0
    definition = full_definition("geometry_msgs/msg/PoseStamped")
    assert definition.startswith("# A Pose with reference coordinate frame and timestamp")
    assert f"{SEPARATOR}\nMSG: geometry_msgs/Pose\n" in definition
    assert f"{SEPARATOR}\nMSG: builtin_interfaces/Time\n" in definition


def test_a_full_queue_drops_and_counts(tmp_path: Path) -> None:
    bag = BagWriter(tmp_path / "q.mcap", queue_bytes=1000)
    channel = bag.add_channel("/text", "std_msgs/msg/String",
                              full_definition("std_msgs/msg/String"))
    bag.offer(channel, [cdr_string("x" * 2000)])  # more than the whole queue
    stats = bag.close()
    assert (stats.messages, stats.dropped) == (0, 1)
    assert stats.topics[0].to_dict() == {"topic": "/text", "type": "std_msgs/msg/String",
                                         "messages": 0, "dropped": 1}


def test_paths_are_refused_by_reason(tmp_path: Path) -> None:
    existing = tmp_path / "e.mcap"
    existing.write_bytes(b"kept")
    for path, reason in ((tmp_path / "none" / "a.mcap", "missing"), (existing, "exists"),
                         (Path("/sys/a.mcap"), "forbidden")):
        with pytest.raises(BagPathError) as refused:
            BagWriter(path)
        assert refused.value.reason == reason, path
    assert existing.read_bytes() == b"kept"
    for text in ("a.bag", "relative.mcap"):
        with pytest.raises(BagPathError) as refused:
            check_bag_path(text, absolute=True)
        assert refused.value.reason == "invalid"


def test_a_file_size_limit_closes_the_bag_readable_with_true_counts(tmp_path: Path) -> None:
    path = tmp_path / "limited.mcap"
    script = textwrap.dedent(f"""
        import resource, time
        from bridge.record.bag import BagWriter
        from bridge.record.definitions import full_definition
        resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, 300_000))
        bag = BagWriter({str(path)!r}, chunk_bytes=64 * 1024)
        channel = bag.add_channel("/text", "std_msgs/msg/String",
                                  full_definition("std_msgs/msg/String"))
        for i in range(3000):
            text = f"message {{i}} " + "x" * 200
            data = text.encode() + b"\\0"
            body = len(data).to_bytes(4, "little") + data
            bag.offer(channel, [b"\\0\\1\\0\\0" + body + b"\\0" * (-len(body) % 4)])
            if i % 100 == 0:
                time.sleep(0.01)
        stats = bag.close()
        print(stats.messages, stats.dropped)
        print(stats.error)
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          cwd=Path(__file__).resolve().parents[2], timeout=120)
    assert done.returncode == 0, done.stderr
    counts, error = done.stdout.splitlines()[:2]
    messages, dropped = (int(n) for n in counts.split())
    assert messages + dropped == 3000 and dropped > 0
    assert error.startswith("recording stopped: the file size limit (RLIMIT_FSIZE) is reached")
    assert path.stat().st_size <= 300_000
    with rosbags.AnyReader([path]) as reader:
        values = [reader.deserialize(raw, c.msgtype).data for c, _, raw in reader.messages()]
    assert len(values) == messages
    assert values == [f"message {i} " + "x" * 200 for i in range(messages)]


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_compressed_chunks_read_back(tmp_path: Path, compression: str) -> None:
    path = tmp_path / f"{compression}.mcap"
    bag = BagWriter(path, compression=compression)
    channel = bag.add_channel("/text", "std_msgs/msg/String",
                              full_definition("std_msgs/msg/String"))
    sent = [cdr_string("same text " * 20) for _ in range(200)]
    bag.offer(channel, sent)
    stats = bag.close()
    assert stats.bytes < sum(len(m) for m in sent) / 4  # compressed
    with rosbags.AnyReader([path]) as reader:
        assert [bytes(raw) for _, _, raw in reader.messages()] == sent
