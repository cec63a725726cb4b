"""Slicer -> ROS from a real scene through the module and Slicer's own connector: a
textured model, a point list, a curve and a transform node reach real rclpy subscribers
(scenes/to_ros.py), in metres."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from support import Child, Processes, RunningDaemon, wait_until


def _echo(processes: Processes, topic: str, ros_type: str) -> Child:
    child = processes.python(f"echo{topic.replace('/', '_')}", "echo_subscriber.py", topic,
                             ros_type)
    child.wait_for_output("READY", timeout=30)
    return child


def _last(child: Child) -> Any:
    lines = [line for line in child.lines() if line.startswith("MSG ")]
    return json.loads(lines[-1][4:]) if lines else None


def test_models_markups_curves_and_transforms_reach_ros(
        run_scene, daemon: RunningDaemon, processes: Processes, tmp_path: Path) -> None:
    echoes = {name: _echo(processes, topic, kind) for name, topic, kind in (
        ("mesh", "/slicer_model", "shape_msgs/msg/Mesh"),
        ("poses", "/slicer_points", "geometry_msgs/msg/PoseArray"),
        ("path", "/slicer_curve", "nav_msgs/msg/Path"),
        ("tf", "/tf", "tf2_msgs/msg/TFMessage"))}
    flag = tmp_path / "seen"

    def needle() -> Any:
        for line in reversed([ln for ln in echoes["tf"].lines() if ln.startswith("MSG ")]):
            for t in json.loads(line[4:])["transforms"]:
                if t["child_frame_id"] == "needle":
                    return t
        return None

    def watch() -> None:
        try:
            wait_until(lambda: all(_last(e) is not None for n, e in echoes.items()
                                   if n != "tf") and needle() is not None,
                       timeout=90, what="every kind in ROS")
        finally:
            flag.touch()
    watcher = threading.Thread(target=watch)
    watcher.start()
    got = run_scene("to_ros", port=daemon.port, flag=str(flag))
    watcher.join()
    assert got["has_tcoords"] and got["problems"] == [] and got["errors"] == []
    mesh = _last(echoes["mesh"])
    vertices = np.array([[v["x"], v["y"], v["z"]] for v in mesh["vertices"]])
    # The 20 mm cube centred on (100, 0, 0) mm in world: metres in ROS, 12 triangles.
    assert vertices.min(axis=0) == pytest.approx([0.09, -0.01, -0.01], abs=1e-6)
    assert vertices.max(axis=0) == pytest.approx([0.11, 0.01, 0.01], abs=1e-6)
    assert len(mesh["triangles"]) == 12
    poses = _last(echoes["poses"])
    assert poses["header"]["frame_id"] == "base_link"
    np.testing.assert_allclose([[p["position"][k] for k in "xyz"] for p in poses["poses"]],
                               [[0.01, 0.02, 0.03], [0.04, 0.05, 0.06]], atol=1e-9)
    path = _last(echoes["path"])
    xyz = np.array([[p["pose"]["position"][k] for k in "xyz"] for p in path["poses"]])
    assert xyz[0] == pytest.approx([0, 0, 0], abs=1e-9)
    assert xyz[-1] == pytest.approx([0.02, 0.01, 0], abs=1e-9)
    assert len(xyz) >= 3  # the curve's polyline: its control points and what lies between
    t = needle()
    assert t["header"]["frame_id"] == "base_link"
    assert [t["transform"]["translation"][k] for k in "xy"] == pytest.approx([0.005, 0.006])
