"""A ROS stamp that OpenIGTLink cannot hold (issue 26, item 1) is replaced by the current
time on every path that turns one into an OpenIGTLink time stamp: the rule's one owner,
and each path with a real publisher in another process."""

from __future__ import annotations

import json
import re
import time
from typing import Iterator

import pytest

from protocol.conversions import (igtl_stamp_or_now, igtl_timestamp_from_ros,
                                  igtl_timestamp_to_seconds)
from support import Processes, RunningDaemon, assert_clean_exit, start_daemon, wait_until

BAD = {"sec": 1_700_000_000, "nanosec": 1_500_000_000}  # a legal uint32, not a legal stamp


@pytest.mark.parametrize("sec,nanosec", [(0, 0), (-5, 0), (1, 1_500_000_000), (1 << 33, 0),
                                         (True, 0)])
def test_a_stamp_openigtlink_cannot_hold_becomes_now(sec: int, nanosec: int) -> None:
    before = time.time()
    got = igtl_timestamp_to_seconds(igtl_stamp_or_now(sec, nanosec))
    assert before - 0.001 <= got <= time.time() + 0.001


def test_a_good_stamp_is_kept() -> None:
    assert igtl_stamp_or_now(1_700_000_000, 5) == igtl_timestamp_from_ros(1_700_000_000, 5)


@pytest.fixture(scope="module")
def daemon(module_processes: Processes) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes)
    yield running
    assert_clean_exit(running)


@pytest.mark.ros
@pytest.mark.parametrize("topic,ros_type,fields", [
    ("/bad_stamp_pose", "geometry_msgs/msg/PoseStamped",  # the raw fast path
     {"header": {"stamp": BAD, "frame_id": "world"}, "pose": {"orientation": {"w": 1.0}}}),
    ("/bad_stamp_point", "geometry_msgs/msg/PointStamped",  # a codec's path
     {"header": {"stamp": BAD, "frame_id": "world"}, "point": {"x": 0.25}}),
    ("/bad_stamp_markers", "visualization_msgs/msg/Marker",  # the markers' path
     {"header": {"stamp": BAD, "frame_id": "world"}, "ns": "n", "id": 1, "type": 1,
      "action": 0, "pose": {"orientation": {"w": 1.0}}, "scale": {"x": 0.1, "y": 0.1,
                                                                 "z": 0.1},
      "color": {"r": 1.0, "a": 1.0}}),
])
def test_each_path_streams_a_bad_stamp_as_now(daemon: RunningDaemon, processes: Processes,
                                              topic: str, ros_type: str,
                                              fields: dict[str, object]) -> None:
    with daemon.connect() as client:
        if ros_type.endswith("Marker"):
            client.command("create_marker_subscriber", {"topic": topic, "type": ros_type,
                                                        "fixed_frame": "world"})
        else:
            device = client.command("create_subscriber", {"topic": topic,
                                                          "type": ros_type})["device"]
        processes.python("pub", "publish_json.py", topic, ros_type, json.dumps(fields))
        started = time.time()
        if ros_type.endswith("Marker"):
            wait_until(lambda: any(d.startswith("mk:") for d in client.devices()), 60,
                       "a marker's model")
            device = next(d for d in client.devices() if d.startswith("mk:"))
        message = client.wait_for(device, timeout=60)
        got = igtl_timestamp_to_seconds(message.timestamp)
        assert started - 5 <= got <= time.time() + 1, (got, started)
    log = daemon.child.output()
    assert "Traceback" not in log and not re.search(r" (ERROR|CRITICAL|FATAL) ", log), \
        log[-3000:]
