"""The module's Record section in a real Slicer scene against a real daemon (issue 45):
scenes/module_record.py presses Record as a user does; the bag it made is read here with
rosbags, an independent reader."""

from __future__ import annotations

from pathlib import Path

import pytest

from support import Processes, RunningDaemon

pytestmark = pytest.mark.ros


def test_the_record_button_records_what_the_module_bridges(
        run_scene, daemon: RunningDaemon, processes: Processes, tmp_path: Path) -> None:
    rosbags = pytest.importorskip("rosbags.highlevel",
                                  reason="the test extra's rosbags reads the bag")
    poses = processes.python("poses", "stream_publisher.py", "/module_rec_pose", "100")
    poses.wait_for_output("READY")
    bag = tmp_path / "module.mcap"
    got = run_scene("module_record", timeout=300, port=daemon.port, bag=str(bag),
                    topic="/module_rec_pose")
    assert got["saved_path"] == str(bag)  # kept in the module's parameter node
    assert got["label_running"].startswith(f"Recording {bag}: ")
    final = got["final"]
    assert final["running"] is False and final["messages"] >= 20
    assert got["label_final"].startswith(f"Recorded {bag}: {final['messages']} messages, "
                                         f"0 dropped")
    with rosbags.AnyReader([bag]) as reader:
        topics = [connection.topic for connection, _, _ in reader.messages()]
    assert topics.count("/module_rec_pose") == final["topics"]["/module_rec_pose"] >= 20
    # A second start on the same file: refused (ALREADY_EXISTS), the button back up.
    assert "ALREADY_EXISTS" in got["second"], got["second"]
    assert got["button_after"] is False and got["running_after"] is False
