"""The check both packaging tests make of a daemon started from an installed copy: it
answers hello and bridges a pose from a real rclpy publisher, in millimetres."""

from __future__ import annotations

import numpy as np
import pytest

from protocol.messages import Transform
from slicer_client.connection import Connection
from support import Child, Processes


def assert_serves_hello_and_a_pose(daemon: Child, port: int, processes: Processes,
                                   topic: str) -> None:
    daemon.wait_for_output("listening on", timeout=60)
    publisher = processes.python("pose", "pose_publisher.py", topic, "0.1", "0.2", "0.3",
                                 "0", "0", "0", "1")
    publisher.wait_for_output("READY", timeout=30)
    with Connection("127.0.0.1", port) as connection:
        hello = connection.command("hello", timeout=30)
        assert hello["node"] == "/slicer_bridge" and "create_subscriber" in hello["ops"]
        reply = connection.command("create_subscriber", {"topic": topic, "type": "PoseStamped"},
                                   timeout=30)
        pose = connection.wait_for(reply["device"], timeout=30)
        assert isinstance(pose.body, Transform)
        # metres in ROS, millimetres on the wire
        assert np.asarray(pose.body.matrix)[:3, 3] == pytest.approx([100.0, 200.0, 300.0])
    assert daemon.stop() == 0, daemon.output()[-3000:]
    assert "Traceback" not in daemon.output()
