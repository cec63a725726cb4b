"""The security policy on what Slicer sends to ROS: a publisher's frame and labels topic
(declared by create_publisher), the frames its messages name, set_robot_joints' topic and
--read-only. Judged from the declarations, without a daemon (the routes themselves are
tested end to end in tests/client/test_slicer_to_ros.py)."""

from __future__ import annotations

import pytest

from bridge.codecs import codec_for
from bridge.core.security import NameRules, SecurityPolicy
from protocol import commands as c
from protocol.commands import ForbiddenError


def _check(policy: SecurityPolicy, op: str, args: dict) -> None:
    # Names as the dispatcher hands them over: resolved (these tests give them absolute).
    policy.check_request(c.parse_request(op, c.dumps(args)), "/slicer_bridge")


def test_a_denied_labels_topic_or_frame_refuses_the_publisher() -> None:
    policy = SecurityPolicy(topics=NameRules(deny=("/private/*",)),
                            frames=NameRules(deny=("secret*",)))
    ok = {"topic": "/plan/points", "type": "geometry_msgs/msg/PoseArray", "frame": "ras",
          "labels_topic": "/plan/labels"}
    _check(policy, "create_publisher", ok)
    with pytest.raises(ForbiddenError) as caught:
        _check(policy, "create_publisher", {**ok, "labels_topic": "/private/labels"})
    assert caught.value.field == "labels_topic"
    with pytest.raises(ForbiddenError) as caught:
        _check(policy, "create_publisher", {**ok, "frame": "secret_room"})
    assert caught.value.field == "frame"


def test_set_robot_joints_is_a_write_judged_on_its_topic() -> None:
    request = {"name": "demo", "positions": {"joint_1": 0.1}, "topic": "/demo/joint_states"}
    with pytest.raises(ForbiddenError, match="read-only"):
        _check(SecurityPolicy(read_only=True), "set_robot_joints", request)
    with pytest.raises(ForbiddenError) as caught:
        _check(SecurityPolicy(topics=NameRules(deny=("*/joint_states",))),
               "set_robot_joints", request)
    assert caught.value.field == "topic"
    _check(SecurityPolicy(read_only=True), "describe_robot_joints", {"name": "demo"})


def test_the_publish_guard_judges_header_and_path_frames() -> None:
    def publish_check(policy: SecurityPolicy, topic: str, ros_type: str):
        request = c.parse_request("create_publisher", c.dumps({"topic": topic,
                                                               "type": ros_type}))
        return policy.content_guard(request).message_check()

    assert publish_check(SecurityPolicy(), "/m", "visualization_msgs/msg/Marker") is None
    check = publish_check(SecurityPolicy(frames=NameRules(deny=("secret*",))), "/path",
                          "nav_msgs/msg/Path")
    assert check is not None
    path = codec_for("nav_msgs/msg/Path").from_value(
        {"poses": [{"header": {"frame_id": "ras"}}, {"header": {"frame_id": "secret"}}]},
        frame_id="")
    with pytest.raises(ForbiddenError) as caught:
        check(path)
    assert caught.value.field == "value.poses[1].header.frame_id"
    path.poses[1].header.frame_id = "ras"
    check(path)
    path.header.frame_id = "/secret_room"  # judged as tf holds it: no leading '/'
    with pytest.raises(ForbiddenError, match="secret_room"):
        check(path)


def test_motion_execute_is_a_write_judged_on_its_action_and_the_rest_are_reads() -> None:
    """Issue 46: executing moves a robot (the writers' rule and the action globs judge it);
    solving, planning and distances are reads; publishing a distance writes a topic."""
    execute = {"name": "demo", "positions": {"joint_1": 0.1},
               "action": "/arm/follow_joint_trajectory"}
    with pytest.raises(ForbiddenError, match="read-only"):
        _check(SecurityPolicy(read_only=True), "execute_motion", execute)
    with pytest.raises(ForbiddenError) as caught:
        _check(SecurityPolicy(actions=NameRules(deny=("/arm/*",))), "execute_motion", execute)
    assert caught.value.field == "action"
    _check(SecurityPolicy(), "execute_motion", execute)
    with pytest.raises(ForbiddenError, match="read-only"):
        _check(SecurityPolicy(read_only=True), "publish_distance",
               {"name": "demo", "link": "tool_flange", "obstacle": "o", "topic": "/d"})
    identity = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    for op, args in (("solve_ik", {"name": "demo", "tip": "tool_flange", "target": identity}),
                     ("plan_motion", {"name": "demo", "positions": {"joint_1": 0.1}}),
                     ("obstacle_distances", {"name": "demo", "link": "tool_flange"}),
                     ("set_obstacle", {"name": "demo", "obstacle": "o", "topic": "/o"})):
        _check(SecurityPolicy(read_only=True), op, args)
