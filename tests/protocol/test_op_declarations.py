"""Every op of the schema declares what it writes, creates, removes and touches, and the
rest of the project derives its tables from those declarations (issue 11: "the op is the
unit"). The examples below enumerate every op: a new op without one fails here."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import pytest

from protocol import commands as c
from protocol.commands import (ActionUse, Bridge, FileUse, FrameUse, Op, ParameterUse,
                               Resource, ServiceUse, TopicUse)

IDENTITY = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
VALUE = {"type": "integer", "value": 1}

# One valid request per op, and the resources it must declare (kind, field, judged name).
EXAMPLES: dict[str, tuple[dict[str, Any], set[tuple[str, str, str]]]] = {
    "hello": ({}, set()),
    "list_bridges": ({}, set()),
    "keep_bridge": ({"kind": "subscriber", "topic": "/a"}, set()),  # judged when it was made
    "list_topics": ({}, set()),
    "list_services": ({}, set()),
    "describe_type": ({"type": "PoseArray"}, set()),
    "authenticate": ({"nonce": "0" * 32, "proof": "1" * 64}, set()),
    "create_subscriber": ({"topic": "/a", "type": "String"}, {("topic", "topic", "/a")}),
    "remove_subscriber": ({"topic": "/a"}, set()),
    "create_publisher": ({"topic": "/a", "type": "String"}, {("topic", "topic", "/a")}),
    "remove_publisher": ({"topic": "/a"}, set()),
    "publish": ({"topic": "/a", "value": "x"}, {("topic", "topic", "/a")}),
    "get_last_message": ({"topic": "/a"}, {("topic", "topic", "/a")}),
    "create_parameter_client": ({"node": "/n"}, set()),
    "remove_parameter_client": ({"node": "/n"}, set()),
    "list_parameters": ({"node": "/n"}, set()),
    "get_parameters": ({"node": "/n", "names": ["p"]}, {("parameter", "names", "/n.p")}),
    "set_parameters": ({"node": "/n", "values": {"p": VALUE}},
                       {("parameter", "values", "/n.p")}),
    "observe_parameters": ({"node": "/n", "names": ["p"]}, {("parameter", "names", "/n.p")}),
    "server_declare_parameter": ({"name": "p", "value": VALUE},
                                 {("parameter", "name", "OWN.p")}),
    "server_set_parameter": ({"name": "p", "value": VALUE}, {("parameter", "name", "OWN.p")}),
    "server_get_parameters": ({"names": ["p"]}, {("parameter", "names", "OWN.p")}),
    "server_undeclare_parameter": ({"name": "p"}, {("parameter", "name", "OWN.p")}),
    "create_tf_lookup": ({"parent": "a", "child": "b"},
                         {("frame", "parent", "a"), ("frame", "child", "b")}),
    "remove_tf_lookup": ({"parent": "a", "child": "b"}, set()),
    "lookup_transform": ({"parent": "a", "child": "b"},
                         {("frame", "parent", "a"), ("frame", "child", "b")}),
    "create_tf_broadcaster": ({"parent": "a", "child": "b"},
                              {("frame", "parent", "a"), ("frame", "child", "b")}),
    "remove_tf_broadcaster": ({"parent": "a", "child": "b"}, set()),
    "broadcast_transform": ({"parent": "a", "child": "b", "matrix": IDENTITY},
                            {("frame", "parent", "a"), ("frame", "child", "b")}),
    "create_robot": ({"name": "r", "namespace": "PSM1", "fixed_frame": "world"},
                     {("parameter", "source.parameter",
                       "PSM1/robot_state_publisher.robot_description"),
                      ("frame", "fixed_frame", "world")}),
    "remove_robot": ({"name": "r"}, set()),
    "list_robots": ({}, set()),
    "describe_robot_joints": ({"name": "r"}, set()),
    "playback_status": ({}, set()),
    "pause_playback": ({}, set()),
    "resume_playback": ({}, set()),
    "seek_playback": ({"offset": 1.5}, set()),
    "set_playback_rate": ({"rate": 2.0}, set()),
    "set_robot_joints": ({"name": "r", "positions": {"j": 0.5}, "topic": "/PSM1/joint_states"},
                         {("topic", "topic", "/PSM1/joint_states")}),
    "solve_ik": ({"name": "r", "tip": "tool", "target": IDENTITY}, set()),  # a read
    "set_obstacle": ({"name": "r", "obstacle": "skull", "topic": "/skull"},
                     {("topic", "topic", "/skull")}),
    "remove_obstacle": ({"name": "r", "obstacle": "skull"}, set()),
    "obstacle_distances": ({"name": "r", "link": "tool"}, set()),
    "publish_distance": ({"name": "r", "link": "tool", "obstacle": "skull", "topic": "/d"},
                         {("topic", "topic", "/d")}),
    "plan_motion": ({"name": "r", "positions": {"j": 0.5}}, set()),
    "execute_motion": ({"name": "r", "positions": {"j": 0.5}, "action": "/arm/fjt"},
                       {("action", "action", "/arm/fjt")}),
    "call_service": ({"service": "/s", "type": "std_srvs/srv/Trigger"},
                     {("service", "service", "/s")}),
    "advertise_service": ({"service": "/s", "type": "std_srvs/srv/Trigger"},
                          {("service", "service", "/s")}),
    "unadvertise_service": ({"service": "/s"}, set()),
    "service_request": ({"service": "/s", "type": "std_srvs/srv/Trigger", "request": {}},
                        set()),
    "create_marker_subscriber": ({"topic": "/m", "type": "MarkerArray",
                                  "fixed_frame": "/world"},
                                 {("topic", "topic", "/m"), ("frame", "fixed_frame", "world")}),
    "remove_marker_subscriber": ({"topic": "/m"}, set()),
    "list_markers": ({"topic": "/m"}, {("topic", "topic", "/m")}),
    "list_actions": ({}, set()),
    "send_goal": ({"action": "/a", "type": "control_msgs/action/GripperCommand"},
                  {("action", "action", "/a")}),
    "cancel_goal": ({"action": "/a", "goal_id": "0" * 32}, {("action", "action", "/a")}),
    "advertise_action": ({"action": "/a", "type": "control_msgs/GripperCommand"},
                         {("action", "action", "/a")}),
    "unadvertise_action": ({"action": "/a"}, set()),
    "action_feedback": ({"action": "/a", "goal_id": "0" * 32, "feedback": {}},
                        {("action", "action", "/a")}),
    "action_goal": ({"action": "/a", "type": "control_msgs/GripperCommand",
                     "goal_id": "0" * 32, "goal": {}}, set()),
    "action_cancel": ({"action": "/a", "goal_id": "0" * 32}, set()),
    "action_decide": ({"action": "/a", "type": "control_msgs/GripperCommand", "goal": {}},
                      set()),
    "start_recording": ({"path": "/data/s.mcap", "topics": ["/a", "/b"]},
                        {("file", "path", "/data/s.mcap"), ("topic", "topics", "/a"),
                         ("topic", "topics", "/b")}),
    "stop_recording": ({"path": "/data/s.mcap"}, set()),
    "recording_status": ({"path": "/data/s.mcap"}, set()),
}


def judged(use: Resource) -> tuple[str, str, str]:
    if isinstance(use, TopicUse):
        return "topic", use.field, use.name
    if isinstance(use, ServiceUse):
        return "service", use.field, use.name
    if isinstance(use, ParameterUse):
        return "parameter", use.field, f"{use.node or 'OWN'}.{','.join(use.names)}"
    if isinstance(use, FrameUse):
        return "frame", use.field, use.frame
    if isinstance(use, ActionUse):
        return "action", use.field, use.name
    assert isinstance(use, FileUse)
    return "file", use.field, use.path


def test_the_examples_enumerate_every_op() -> None:
    assert set(EXAMPLES) == set(c.REQUEST_TYPES)


@pytest.mark.parametrize("op", sorted(EXAMPLES))
def test_each_op_declares_what_it_touches(op: str) -> None:
    args, expected = EXAMPLES[op]
    request = c.parse_request(op, c.dumps(args))
    cls = type(request)
    assert cls.op == op and isinstance(cls.writes, bool)
    assert "resources" in cls.__dict__  # its own declaration, not an inherited default
    uses = request.resources()
    assert {judged(use) for use in uses} == expected
    names = {f.name for f in fields(request)}
    for use in uses:  # every field a refusal would name is one of the request's
        assert use.field.split(".")[0] in names, (op, use.field)


def test_bridge_kinds_pair_create_and_remove_with_their_identity() -> None:
    kinds = c.bridge_kinds()
    assert set(kinds) == {"subscriber", "publisher", "parameter_client", "tf_lookup",
                          "tf_broadcaster", "robot", "served_service", "marker_subscriber",
                          "served_action"}
    for kind in kinds.values():
        assert kind.create.creates is kind.bridge and kind.remove.removes == kind.bridge.kind
        remove_fields = {f.name for f in fields(kind.remove)}
        assert set(kind.bridge.identity) <= remove_fields
    assert [f.op for f in kinds["parameter_client"].follow_ups] == ["observe_parameters"]
    # Writes: what --read-only refuses (removals are refused there as removals).
    assert {op for op, cls in c.REQUEST_TYPES.items() if cls.writes} == {
        "create_publisher", "publish", "create_tf_broadcaster", "broadcast_transform",
        "set_parameters", "server_declare_parameter", "server_set_parameter",
        "server_undeclare_parameter", "call_service", "advertise_service",
        "set_robot_joints", "send_goal", "cancel_goal", "advertise_action", "action_feedback",
        "start_recording", "stop_recording",
        # A player's clock: every client of the player sees what these change.
        "pause_playback", "resume_playback", "seek_playback", "set_playback_rate",
        "publish_distance", "execute_motion"}


def test_a_publisher_declares_its_frame_and_labels_topic() -> None:
    request = c.parse_request("create_publisher", c.dumps({
        "topic": "/m", "type": "shape_msgs/msg/Mesh", "frame": "patient",
        "labels_topic": "/m/labels"}))
    assert {judged(use) for use in request.resources()} == {
        ("topic", "topic", "/m"), ("topic", "labels_topic", "/m/labels"),
        ("frame", "frame", "patient")}
    assert all(use.writes for use in request.resources() if isinstance(use, TopicUse))


def test_derived_tables_follow_the_declarations() -> None:
    from bridge.config import SECTIONS
    from slicer_client.bridge_state import FOLLOW_UP_OPS, REMOVE_OPS

    kinds = c.bridge_kinds().values()
    assert SECTIONS == {k.bridge.section: k.create.op for k in kinds if k.bridge.section}
    assert REMOVE_OPS == {k.create.op: (k.remove.op, k.bridge.identity) for k in kinds
                          if not k.bridge.per_connection}
    assert FOLLOW_UP_OPS == ("observe_parameters",)


def test_an_op_that_declares_nothing_fails_at_import() -> None:
    with pytest.raises(TypeError, match="declares its name"):
        @dataclass(frozen=True)
        class NoName(Op, writes=False):  # type: ignore[call-arg]
            def resources(self) -> tuple[Resource, ...]:
                return ()
    with pytest.raises(TypeError, match="whether it writes"):
        @dataclass(frozen=True)
        class NoWrites(Op, op="test_no_writes"):
            def resources(self) -> tuple[Resource, ...]:
                return ()
    with pytest.raises(TypeError, match="what it touches"):
        @dataclass(frozen=True)
        class NoResources(Op, op="test_no_resources", writes=False):
            pass
    with pytest.raises(TypeError, match="declared twice"):
        @dataclass(frozen=True)
        class Twice(Op, op="hello", writes=False):
            def resources(self) -> tuple[Resource, ...]:
                return ()
    with pytest.raises(TypeError, match="identity field 'topic'"):
        @dataclass(frozen=True)
        class BadIdentity(Op, op="test_bad_identity", writes=False,
                          creates=Bridge("thing", ("topic",))):
            name: str

            def resources(self) -> tuple[Resource, ...]:
                return ()
    assert not [op for op in c.REQUEST_TYPES if op.startswith("test_")]


def test_a_create_op_without_its_remove_op_fails_the_pairing() -> None:
    @dataclass(frozen=True)
    class Orphan(Op, op="test_create_orphan", writes=False,
                 creates=Bridge("orphan", ("name",))):
        name: str

        def resources(self) -> tuple[Resource, ...]:
            return ()

    try:
        with pytest.raises(TypeError, match="'orphan' has no create/remove pair"):
            c.bridge_kinds()
    finally:
        del c.REQUEST_TYPES["test_create_orphan"]


def test_action_ops_parse_types_goal_ids_and_limits() -> None:
    goal = c.SendGoal.from_json(c.dumps({
        "action": "fjt", "type": "control_msgs/FollowJointTrajectory",
        "goal_id": "0123ABCD-0123-4567-89ab-0123456789AB", "result_timeout": 2}))
    assert goal.ros_type == "control_msgs/action/FollowJointTrajectory"
    assert goal.goal_id == "0123abcd0123456789ab0123456789ab" and goal.result_timeout == 2.0
    assert goal.goal == {} and goal.timeout == 4.0
    for args, field, code in [
            ({"action": "/a", "type": "control_msgs/msg/X"}, "type", c.ErrorCode.OUT_OF_RANGE),
            ({"action": "/a", "type": "p/A", "goal": []}, "goal", c.ErrorCode.WRONG_TYPE),
            ({"action": "/a", "type": "p/A", "goal_id": "xyz"}, "goal_id",
             c.ErrorCode.OUT_OF_RANGE),
            ({"action": "/a", "type": "p/A", "timeout": 0}, "timeout", c.ErrorCode.OUT_OF_RANGE),
            ({"action": "a b", "type": "p/A"}, "action", c.ErrorCode.OUT_OF_RANGE)]:
        with pytest.raises(c.CommandError) as error:
            c.SendGoal.from_json(c.dumps(args))
        assert (error.value.field, error.value.error_code) == (field, code), args
    assert c.resolve_action_type("pkg/action/Name") == "pkg/action/Name"
    assert c.goal_id_text("A" * 32) == "a" * 32
