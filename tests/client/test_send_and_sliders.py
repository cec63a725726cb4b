"""The module's logic that runs without Slicer: what "Send to ROS" makes of a node
(slicer_client/send_plan.py), and the joint sliders of a robot with mimic joints
(slicer_client/joint_sliders.py), from a `describe_robot_joints` table."""

from __future__ import annotations

import math

import pytest

from slicer_client.joint_sliders import joint_sliders, slider_positions
from slicer_client.send_plan import KIND_ORDER, SEND_TYPES, plan_send

# As the daemon describes bridge/robots/demo's gripper and a chained mimic.
TABLE = [
    {"name": "shoulder", "type": "revolute", "actuated": True, "lower": -1.5, "upper": 1.5,
     "mimic": None},
    {"name": "spin", "type": "continuous", "actuated": True, "lower": None, "upper": None,
     "mimic": None},
    {"name": "weld", "type": "fixed", "actuated": False, "lower": None, "upper": None,
     "mimic": None},
    {"name": "finger", "type": "prismatic", "actuated": True, "lower": 0.0, "upper": 0.04,
     "mimic": None},
    {"name": "finger_twin", "type": "prismatic", "actuated": False, "lower": 0.0,
     "upper": 0.02, "mimic": {"joint": "finger", "multiplier": 1.0, "offset": 0.0}},
    {"name": "finger_tip", "type": "revolute", "actuated": False, "lower": -1.0, "upper": 1.0,
     "mimic": {"joint": "finger_twin", "multiplier": 20.0, "offset": 0.5}},
]


def test_one_slider_per_actuated_joint_in_display_units() -> None:
    sliders = {s.name: s for s in joint_sliders(TABLE)}
    assert list(sliders) == ["shoulder", "spin", "finger"]
    shoulder = sliders["shoulder"]
    assert (shoulder.unit, shoulder.minimum, shoulder.maximum) == (
        "deg", pytest.approx(-math.degrees(1.5)), pytest.approx(math.degrees(1.5)))
    assert (sliders["spin"].minimum, sliders["spin"].maximum) == (-180.0, 180.0)


def test_mimic_limits_narrow_their_leaders_slider() -> None:
    finger = {s.name: s for s in joint_sliders(TABLE)}["finger"]
    assert finger.unit == "mm" and finger.followers == ("finger_twin", "finger_tip")
    # finger_twin = finger <= 0.02 m; finger_tip = 20 * finger + 0.5 <= 1 -> finger <= 0.025.
    assert finger.minimum == pytest.approx(0.0)
    assert finger.maximum == pytest.approx(20.0)  # mm


def test_slider_values_become_radians_and_metres_clamped_to_the_range() -> None:
    sliders = joint_sliders(TABLE)
    positions = slider_positions(sliders, {"shoulder": 45.0, "finger": 12.5, "spin": 500.0})
    assert positions["shoulder"] == pytest.approx(math.pi / 4)
    assert positions["finger"] == pytest.approx(0.0125)
    assert positions["spin"] == pytest.approx(math.pi)  # clamped to the slider's end
    with pytest.raises(KeyError, match="finger_twin"):
        slider_positions(sliders, {"finger_twin": 1.0})
    finger = sliders[2]
    assert finger.from_ros(finger.to_ros(7.5)) == pytest.approx(7.5)
    assert finger.initial == 0.0


def test_send_plans_follow_what_the_connector_can_carry() -> None:
    model = plan_send("vtkMRMLModelNode", "/anatomy/liver")
    assert (model.ros_type, model.outgoing_class, model.source) == (
        "shape_msgs/msg/Mesh", "vtkMRMLModelNode", "surface")
    points = plan_send("vtkMRMLMarkupsFiducialNode", "/plan/targets/")
    assert (points.ros_type, points.outgoing_class, points.labels_topic) == (
        "geometry_msgs/msg/PoseArray", "vtkMRMLMarkupsFiducialNode", "/plan/targets/labels")
    curve = plan_send("vtkMRMLMarkupsCurveNode", "/plan/path")
    assert (curve.ros_type, curve.outgoing_class, curve.source) == (
        "nav_msgs/msg/Path", "vtkMRMLModelNode", "curve")
    line = plan_send("vtkMRMLMarkupsLineNode", "/plan/line")
    assert (line.outgoing_class, line.source, line.labels_topic) == (
        "vtkMRMLMarkupsFiducialNode", "control_points", None)
    assert plan_send("vtkMRMLMarkupsCurveNode", "/c", "geometry_msgs/msg/PointStamped"
                     ).source == "control_points"
    with pytest.raises(ValueError, match="not nav_msgs/msg/Path"):
        plan_send("vtkMRMLModelNode", "/m", "nav_msgs/msg/Path")
    with pytest.raises(ValueError, match="not a vtkMRMLScalarVolumeNode"):
        plan_send("vtkMRMLScalarVolumeNode", "/v")
    assert set(KIND_ORDER) == set(SEND_TYPES) and KIND_ORDER[0] == "vtkMRMLMarkupsCurveNode"


def test_a_model_or_markups_with_a_nan_names_its_row() -> None:
    """Issue 25, item 11: a NaN is named with its row, not as a shape."""
    from slicer_client.errors import PointsError
    from slicer_client.resources import markups_point_body, model_polydata

    points = [[0.0, 0.0, 0.0], [1.0, float("nan"), 0.0], [0.0, 1.0, 0.0]]
    with pytest.raises(PointsError) as nan:
        model_polydata(points, [[0, 1, 2]])
    assert str(nan.value) == "points: expected finite coordinates in mm, got [1.0, nan, 0.0] " \
                             "at row 1"
    with pytest.raises(PointsError, match=r"got \[inf, 0.0, 0.0\] at row 0"):
        markups_point_body([float("inf"), 0, 0], ["entry"])
    with pytest.raises(PointsError) as shape:
        model_polydata([[0.0, 0.0], [1.0, 1.0]], [[0, 1, 0]])
    assert str(shape.value) == "points: expected shape (N, 3) in mm, got shape (2, 2)"
    assert isinstance(shape.value, ValueError)
    body = model_polydata(points[:1] + [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [[0, 1, 2]])
    assert body.points.tolist() == [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
