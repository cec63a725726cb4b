"""A robot in a real Slicer scene, loaded and moved through the ROS2Bridge module's logic,
with 3D Slicer's own OpenIGTLinkIF connector making the nodes (scenes/robot.py)."""

from __future__ import annotations

import math
import pytest

from support import RunningDaemon

DEMO_LINKS = ["base_link", "elbow_link", "finger_left", "finger_right", "forearm_link",
              "shoulder_link", "tool_flange", "upper_arm_link", "wrist_1_link",
              "wrist_2_link", "wrist_3_link"]


def test_the_demo_robot_is_placed_coloured_filed_and_moved_by_its_sliders(
        run_scene, demo: RunningDaemon) -> None:
    got = run_scene("robot", port=demo.port, robot="demo", node="/robot_state_publisher",
                    models=14, joint="joint_1", child_link="shoulder_link", degrees=30.0)
    links = [name.split(":", 1)[1] for name in got["links"]]
    assert links == DEMO_LINKS
    # Each link's transform is its pose in the robot's fixed frame (no chain of parents);
    # each model sits under its link's transform.
    assert set(got["link_parents"].values()) == {None}
    assert len(got["models"]) == 14
    for name, model in got["models"].items():
        assert model["parent"] == f"demo:{model['link']}", (name, model)
        assert model["folders"] == ["robot demo", "ROS2 robots"], (name, model)
        assert model["points"] > 0 and model["opacity"] == 1.0
        # The demo's meshes are one colour each: shown as the display colour, scalars off.
        assert model["rgba_colours"] <= 1 and not model["scalars"], (name, model)
    base = got["models"]["demo:base_link:0"]["colour"]
    assert base == pytest.approx([0.2, 0.21, 0.23], abs=0.01)
    assert got["robot_lines"] == ["demo: 14 of 14 meshes received"]
    # The slider moved joint_1 to 30 degrees; the shoulder's transform node followed. Its
    # Python observer was called as Slicer calls one: the event as a string, and a custom
    # event (TransformModifiedEvent = 15000) as 'NoEvent'.
    assert got["sliders"]["joint_1"][0] == "deg"
    assert got["sliders"]["joint_1"][1:] == pytest.approx([-180.0, 180.0], abs=0.01)
    assert got["moved"]["joint_1"] == pytest.approx(math.radians(30.0))
    assert got["angle"] == pytest.approx(30.0, abs=0.5)
    assert got["events"] == ["NoEvent"] and got["event_count"] >= 1
