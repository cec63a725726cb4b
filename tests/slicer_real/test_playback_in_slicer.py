"""The ROS2Bridge module in a real Slicer scene, playing a bag (issue 45): a player without
ROS (`slicer-ros2-bridge play`, every ROS import failing in its process) serves a bag
written by rosbags; the module's logic pauses, seeks, sets the rate and resumes it, and the
robot's link transforms in the scene are at the bag's poses: yourdfpy's forward kinematics
at the bag's joint states, after its world -> base_link transform (scenes/module_playback.py)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from support import Processes

pytestmark = pytest.mark.ros


def test_the_module_plays_a_bag_and_seeks_it(run_scene, processes: Processes,
                                             no_ros: dict[str, str], robot_bag: Any,
                                             demo_files: tuple[str, str]) -> None:
    pytest.importorskip("mcap_ros2", reason="the play extra (mcap-ros2-support)")
    from bags import NS
    from play_support import expected_link_poses, start_player

    player, port = start_player(processes, no_ros, str(robot_bag.mcap), "--paused",
                                "--start", "1.0", "--package-path", demo_files[1])

    def at(offset: float) -> list[list[float]]:
        """base_link <- tool_flange (mm) at ``offset`` s: the robot's fixed frame is its root."""
        t = robot_bag.times[0] - NS // 100 + int(round(offset * NS))
        poses = expected_link_poses(robot_bag, robot_bag.state_at(t))
        return (np.linalg.inv(poses["base_link"]) @ poses["tool_flange"]).tolist()

    expected = {str(offset): at(offset) for offset in (1.0, 0.4, 1.7, 2.0)}
    got = run_scene("module_playback", timeout=300, port=port, expected=expected)
    assert got["start"]["paused"] and got["start"]["offset"] == 1.0
    assert got["start"]["duration"] == pytest.approx(2.0)
    assert got["seeks"] == {"0.4": pytest.approx(0.4), "1.7": pytest.approx(1.7)}
    for offset, pose in got["poses"].items():  # after each seek, the pose at its time
        np.testing.assert_allclose(np.array(pose)[:3, 3], np.array(expected[offset])[:3, 3],
                                   atol=0.01)
    assert got["rate"] == 3.0 and got["resumed_paused"] is False
    assert got["paused_at_end"] is True
    assert "NO-ROS GUARD" not in player.output() and "Traceback" not in player.output()


def test_a_played_bag_becomes_sequences_and_browsing_moves_the_robot(
        run_scene, processes: Processes, no_ros: dict[str, str], robot_bag: Any,
        demo_files: tuple[str, str]) -> None:
    """The module records a played bag as Slicer sequences (one per streamed node, on the
    bag's clock, under one browser whose proxies are the nodes): browsing item i shows the
    robot's pose at its time t_i, by yourdfpy's FK of the bag's joint state then, and the
    bag's image at t_i as a volume."""
    pytest.importorskip("mcap_ros2", reason="the play extra (mcap-ros2-support)")
    from bags import NS
    from play_support import expected_link_poses, start_player

    player, port = start_player(processes, no_ros, str(robot_bag.mcap), "--paused",
                                "--package-path", demo_files[1])
    got = run_scene("bag_sequences", timeout=300, port=port, start=0.5, step=0.25,
                    items=[0, 3, 6])
    assert got["items"] == 7  # 0.5, 0.75 ... 2.0 s
    assert "demo:tool_flange (bag)" in got["sequences"]
    assert got["models_under_links"] == 14  # the models stay under their link transforms
    for index, shown in got["shown"].items():
        t = robot_bag.times[0] - NS // 100 + int(round(float(index) * NS))
        poses = expected_link_poses(robot_bag, robot_bag.state_at(t))
        want = np.linalg.inv(poses["base_link"]) @ poses["tool_flange"]
        np.testing.assert_allclose(np.array(shown["flange"])[:3, 3], want[:3, 3], atol=0.01,
                                   err_msg=f"item at {index} s")
        # The image as a volume, in step: the bag's image at that time (its pixels' sum,
        # whatever order Slicer's volume holds them in).
        pixels = np.frombuffer(robot_bag.image_at(t), dtype=np.uint8)
        assert shown["image_sum"] == int(pixels.sum(dtype=np.int64)), f"image at {index} s"
    assert "Traceback" not in player.output()
