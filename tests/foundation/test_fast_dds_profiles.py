"""The Fast DDS profiles the README offers (bench/*.xml) load under this venv's Fast DDS
without an error (a broken copy shows such an error is seen), and a daemon started with
the reader profile, as the README suggests for large frames, relays a ROS peer's pose."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from protocol.messages import Transform
from support import REPO, Processes, scaled, start_daemon, wait_until

pytestmark = pytest.mark.ros

VARIABLE = "FASTRTPS_DEFAULT_PROFILES_FILE"
READER_AT_ONCE = REPO / "bench" / "fastdds_reader_at_once.xml"
PROFILES = [READER_AT_ONCE, REPO / "bench" / "fastdds_image_publisher.xml"]

# A node with a reader and a writer: what makes Fast DDS load every kind of profile.
CHECK = """
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import Image
rclpy.init()
node = Node("fast_dds_profile_check")
node.create_subscription(Image, "/fast_dds_profile_check", lambda message: None, 10)
node.create_publisher(Image, "/fast_dds_profile_check", 10)
node.destroy_node()
rclpy.shutdown()
print("made a node, a reader and a writer")
"""


def fast_dds_reading(profile: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", CHECK], env={**os.environ, VARIABLE: str(profile)},
                          capture_output=True, text=True, timeout=scaled(60))


def test_a_broken_profile_is_reported(tmp_path: Path) -> None:
    broken = tmp_path / "broken.xml"
    broken.write_text(READER_AT_ONCE.read_text().replace("<sec>0</sec>", "<sec>zero</sec>"))
    seen = fast_dds_reading(broken)
    # Fast DDS logs to standard output, and goes on with its defaults.
    assert "XMLPARSER" in seen.stdout and "heartbeatResponseDelay" in seen.stdout, seen.stdout


@pytest.mark.parametrize("profile", PROFILES, ids=lambda path: path.name)
def test_the_profile_loads_without_an_error(profile: Path) -> None:
    done = fast_dds_reading(profile)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "made a node, a reader and a writer", done.stdout
    assert "Error" not in done.stderr, done.stderr


@pytest.mark.integration
def test_a_daemon_with_the_reader_profile_relays_a_pose(processes: Processes) -> None:
    daemon = start_daemon(processes, env={VARIABLE: str(READER_AT_ONCE)})
    processes.python("pose", "pose_publisher.py", "/profile_pose", "0.25", "0.5", "0.75",
                     "0", "0", "0", "1")
    with daemon.connect() as client:
        device = client.command("create_subscriber", {"topic": "/profile_pose",
                                                      "type": "PoseStamped"})["device"]
        wait_until(lambda: client.latest(device) is not None, timeout=scaled(20),
                   what="the publisher's pose through the daemon")
        body = client.latest(device).body
        assert isinstance(body, Transform)
        np.testing.assert_allclose(body.matrix[:3, 3], [250.0, 500.0, 750.0], atol=1e-3)
    assert "XMLPARSER" not in daemon.child.output()
