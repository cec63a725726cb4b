"""The Slicer module's logic that needs no Slicer: scene planner, bridge-state format,
connector command building and reply parsing, values and matrices."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from protocol import commands as c
from protocol.messages import Message, Status, String, TrackingData, Transform
from protocol.naming import NameKey, device_name_for, metadata_for
from slicer_client import (BridgeSpec, BridgeState, CommandRefusedError, CommandTimeoutError,
                           MatrixError, StateFormatError, as_numpy, to_vtk)
from slicer_client.connection import ConnectionClosedError
from slicer_client.connector_codec import (COMMAND_STATUS, SLICER_TEXT_ENCODING,
                                           build_command, message_from_node,
                                           outgoing_content, parse_reply)
from slicer_client.scene_plan import (DEFAULT_COLOUR, describe_bridges, is_point_like,
                                      link_metadata, metadata_from_attributes, model_colour,
                                      plan_node,
                                      point_colours_differ, vertex_per_point)
from slicer_client.values import value_from_message


def attrs(meta: dict[str, str]) -> dict[str, str]:
    return {f"OpenIGTLink.{k}": v for k, v in meta.items()}


# --- scene planner ------------------------------------------------------------------------
def test_robot_visual_goes_under_its_link_transform_in_the_robot_folder() -> None:
    meta = metadata_from_attributes({**attrs(metadata_for(
        NameKey.robot_visual("PSM1", "tool_link", 0))), "Other": "x"})
    plan = plan_node("PSM1:tool_link:0", meta)
    assert plan.kind == "robot_visual"
    assert plan.parent_device == "PSM1:tool_link"
    assert plan.folder == "robot PSM1"
    assert plan.display_name == "PSM1 tool_link"
    assert plan.colour == DEFAULT_COLOUR


def test_a_mesh_of_one_colour_gets_it_and_a_mesh_of_many_shows_its_point_colours() -> None:
    """Issue 42 (7): the module gave every robot model the mean of its RGBA array as its
    display colour, which greys a DAE's vertex colours into one. A mesh of one colour keeps
    that display colour (scalars off); a mesh whose points differ shows them (scalars on)."""
    meta = metadata_from_attributes(attrs(metadata_for(NameKey.robot_visual("arm", "hand", 0))))
    one = np.tile(np.array([0.25, 0.5, 0.75, 1.0], np.float32), (6, 1))
    plan = plan_node("arm:hand:0", meta, rgba=one)
    assert (plan.colour, plan.opacity, plan.point_colours) == ((0.25, 0.5, 0.75), 1.0, False)
    red_blue = np.array([[1, 0, 0, 1], [1, 0, 0, 1], [0, 0, 1, 0.5]], np.float32)
    plan = plan_node("arm:hand:0", meta, rgba=red_blue)
    assert plan.point_colours
    assert plan.colour == pytest.approx((2 / 3, 0.0, 1 / 3))  # the mean, under the scalars
    # The URDF material in the metadata stays the display colour; no array, one colour.
    plan = plan_node("arm:hand:0", {**meta, "ros2.color": "0 1 0 1"}, rgba=red_blue)
    assert (plan.colour, plan.point_colours) == ((0.0, 1.0, 0.0), True)
    assert not plan_node("arm:hand:0", {**meta, "ros2.color": "0 1 0 1"}).point_colours
    # The decision alone: one row, equal rows, a difference in alpha only, the daemon's word.
    assert not point_colours_differ({}, one[:1]) and not point_colours_differ({}, one)
    assert point_colours_differ({}, np.array([[1, 0, 0, 1], [1, 0, 0, 0.5]]))
    assert point_colours_differ({"ros2.point_colors": "1"}) and not point_colours_differ({})
    assert not point_colours_differ({}, np.zeros((0, 4)))


def test_point_clouds_and_points_markers_are_point_like() -> None:
    """Issue 42 (8): the daemon sends their points as one polyvertex cell, of which Slicer's
    converter keeps the first: these models get one vertex per point again in the module."""
    def sub(ros_type: str) -> dict[str, str]:
        return metadata_for(NameKey.subscriber("/cloud"), ros_type=ros_type)

    def marker(kind: str) -> dict[str, str]:
        return {**metadata_for(NameKey.marker("/m", "ns", 1)), "ros2.marker_type": kind}
    for meta, expected in ((sub("sensor_msgs/msg/PointCloud2"), True),
                           (sub("sensor_msgs/msg/PointCloud"), True),
                           (sub("sensor_msgs/msg/Image"), False),
                           (marker("points"), True), (marker("point"), True),
                           (marker("sphere_list"), False), (marker("line_strip"), False),
                           (metadata_for(NameKey.robot_visual("r", "l", 0)), False), ({}, False)):
        assert is_point_like(meta) is expected, meta
        assert plan_node("dev", meta).point_like is expected, meta
    offsets, connectivity = vertex_per_point(4)
    assert (offsets.tolist(), connectivity.tolist()) == ([0, 1, 2, 3, 4], [0, 1, 2, 3])
    assert offsets.dtype == connectivity.dtype == np.int64
    assert [a.tolist() for a in vertex_per_point(0)] == [[0], []]


def test_long_link_names_use_the_daemons_hashed_device_or_the_create_reply() -> None:
    link = "a_very_long_link_name_indeed"
    meta = metadata_for(NameKey.robot_visual("PSM1", link, 2))
    plan = plan_node("whatever", meta)
    assert plan.parent_device == device_name_for(NameKey.robot_link("PSM1", link))
    assert "~" in plan.parent_device and plan.display_name.endswith("visual 2")
    given = plan_node("whatever", meta, link_devices={("PSM1", link): "from-reply"})
    assert given.parent_device == "from-reply"


def test_colours_from_metadata_then_rgba_attribute_then_default() -> None:
    assert model_colour({"ros2.color": "1 0 0 0.5"}) == ((1.0, 0.0, 0.0), 0.5)
    assert model_colour({"ros2.color": "bad"}, [0.2, 0.4, 0.6, 1.0]) == ((0.2, 0.4, 0.6), 1.0)
    assert model_colour({}, None) == (DEFAULT_COLOUR, 1.0)
    assert model_colour({}, [2.0, -1.0, 0.5]) == ((1.0, 0.0, 0.5), 1.0)


@pytest.mark.parametrize("key, kind, folder", [
    (NameKey.robot_link("R", "base"), "robot_link", "robot R"),
    (NameKey.robot_description("R"), "robot_description", "robot R"),
    (NameKey.robot_poses("R"), "robot_poses", "robot R"),
    (NameKey.tf_lookup("world", "tool"), "tf_lookup", "ROS2 tf"),
    (NameKey.subscriber("/tool"), "subscriber", "ROS2 topics"),
    (NameKey.parameter_client("/rsp"), "parameters", "ROS2 parameters"),
])
def test_every_role_has_a_plan(key: NameKey, kind: str, folder: str) -> None:
    plan = plan_node(device_name_for(key), metadata_for(key, ros_type="std_msgs/msg/String"))
    assert (plan.kind, plan.folder, plan.parent_device) == (kind, folder, None)


def test_a_link_node_of_a_robot_s_tdata_is_planned_as_its_transform_was() -> None:
    poses = metadata_for(NameKey.robot_poses("PSM1"), frame="world", units="mm")
    poses["ros2.parent"] = "world"
    meta = link_metadata(poses, "PSM1", "tool_link")
    assert meta == {"ros2.role": "robot_link", "ros2.robot": "PSM1", "ros2.link": "tool_link",
                    "ros2.frame": "world", "ros2.parent": "world", "ros2.units": "mm"}
    plan = plan_node("PSM1:tool_link", meta)
    assert (plan.kind, plan.display_name, plan.folder) == ("robot_link", "PSM1 tool_link",
                                                           "robot PSM1")


def test_unknown_nodes_are_left_alone() -> None:
    plan = plan_node("Needle", {})
    assert (plan.kind, plan.folder, plan.colour) == ("other", None, None)


def test_bridge_lines_name_each_bridge_and_nothing_else() -> None:
    """One line per entry of ``bridges``; the reply's other keys (the tf buffer, goals,
    cached ROS clients) are not bridges."""
    reply = {"bridges": [
        {"kind": "subscriber", "topic": "/tool", "type": "geometry_msgs/msg/PoseStamped",
         "device": "tool"},
        {"kind": "tf_lookup", "parent": "world", "child": "tool", "device": "tf:world>tool"},
        {"kind": "robot", "name": "PSM1", "links": 7},
        {"kind": "served_action", "action": "/plan", "device": "act:plan"}],
        "tf_buffer": {"topics": ["/tf"]}, "goals": [{"action": "/fjt", "goal_id": "ab"}]}
    assert describe_bridges(reply) == [
        "subscriber: /tool [geometry_msgs/msg/PoseStamped] as tool",
        "tf_lookup: world -> tool as tf:world>tool", "robot: PSM1",
        "served_action: /plan as act:plan"]


# --- bridge state -------------------------------------------------------------------------
def test_state_round_trips_and_keeps_order_and_follow_ups() -> None:
    state = BridgeState((
        BridgeSpec("create_subscriber", {"topic": "/a", "type": "String"}),
        BridgeSpec("create_parameter_client", {"node": "/rsp"},
                   (("observe_parameters", {"node": "/rsp", "names": ["x"]}),)),
        BridgeSpec("create_robot", {"name": "PSM1", "tf_prefix": "PSM1/"})))
    again = BridgeState.from_json(state.to_json())
    assert again == state
    assert again.specs[1].remove_command() == ("remove_parameter_client", {"node": "/rsp"})
    assert [s.key for s in again.specs] == [("create_subscriber", "/a"),
                                            ("create_parameter_client", "/rsp"),
                                            ("create_robot", "PSM1")]
    assert BridgeState.from_json("") == BridgeState()


@pytest.mark.parametrize("text, message", [
    ("{", "expected JSON"),
    ('{"version": 9}', "version 1 expected, got 9"),
    ('{"version": 1, "bridges": [{"op": "publish", "args": {}}]}', "bridges[0].op"),
    ('{"version": 1, "bridges": [{"op": "create_subscriber", "args": {"topic": "/a", '
     '"type": "String", "qos": {"depth": 0}}}]}', "qos.depth"),
    ('{"version": 1, "bridges": [{"op": "create_subscriber", "args": {"topic": "/a"}}]}',
     "type"),
])
def test_bad_saved_state_names_the_entry_and_field(text: str, message: str) -> None:
    with pytest.raises(StateFormatError, match=message.replace("[", r"\[").replace("]", r"\]")):
        BridgeState.from_json(text)


# --- connector command codec --------------------------------------------------------------
def test_build_command_validates_and_encodes() -> None:
    name, text = build_command("create_subscriber", {"topic": "/tool", "type": "PoseStamped"})
    assert name == "create_subscriber"
    assert json.loads(text)["topic"] == "/tool" and json.loads(text)["schema"] == 1
    with pytest.raises(c.MissingFieldError, match="type"):
        build_command("create_subscriber", {"topic": "/tool"})
    with pytest.raises(c.TooLargeError, match="65535"):
        build_command("publish", {"topic": "/t", "value": "x" * 70000})


def test_parse_reply_success_refusal_expiry() -> None:
    ok = c.Reply.success("list_bridges", {"bridges": []}).to_json()
    assert parse_reply("list_bridges", ok) == {"bridges": []}
    refused = c.Reply.failure("create_subscriber", c.ErrorCode.OUT_OF_RANGE,
                              "qos.depth: expected >= 1, got 0", "qos.depth").to_json()
    with pytest.raises(CommandRefusedError) as caught:
        parse_reply("create_subscriber", refused)
    assert caught.value.field == "qos.depth" and "got 0" in str(caught.value)
    with pytest.raises(CommandTimeoutError, match="5"):
        parse_reply("hello", "", expired=True, timeout=5.0)
    with pytest.raises(CommandRefusedError, match="connector says no"):
        parse_reply("hello", "", error_message="connector says no")


def test_parse_reply_follows_the_slicer_command_status() -> None:
    # igtlioCommandStatus numbers, as vtkSlicerOpenIGTLinkCommand.GetCommandStatus() returns
    assert COMMAND_STATUS[2] == "expired" and COMMAND_STATUS[5] == "response_received"
    ok = c.Reply.success("list_bridges", {"bridges": []}).to_json()
    assert parse_reply("list_bridges", ok, status=5) == {"bridges": []}
    with pytest.raises(CommandTimeoutError, match="within 3"):
        parse_reply("hello", "", status=2, timeout=3.0)
    with pytest.raises(ConnectionClosedError, match="no connection to the daemon"):
        parse_reply("hello", "", status=0)  # blocking send with no socket returns at once
    with pytest.raises(ConnectionClosedError, match="socket"):
        parse_reply("hello", "", status=4)
    with pytest.raises(ConnectionClosedError, match="status 42"):
        parse_reply("hello", "", status=42)


def test_outgoing_content_is_what_the_connector_can_carry() -> None:
    kind, rows = outgoing_content(Message("tfb:w>t", Transform(np.eye(4))))
    assert kind == "vtkMRMLLinearTransformNode" and rows[3] == [0.0, 0.0, 0.0, 1.0]
    assert outgoing_content(Message("pub:cmd", String("go"))) == ("vtkMRMLTextNode", "go")
    assert SLICER_TEXT_ENCODING == 3  # VTK_ENCODING_UTF_8, read as MIBenum 3 (US-ASCII)
    with pytest.raises(ValueError, match="not ASCII"):
        outgoing_content(Message("pub:cmd", String("caf\u00e9")))
    with pytest.raises(ValueError, match="no metadata"):
        outgoing_content(Message("pub:cmd", String("go"), metadata={"ros2.topic": "/cmd"}))
    with pytest.raises(TypeError, match="TRANSFORM and STRING"):
        outgoing_content(Message("x", Status(text="hello")))


def test_connector_nodes_become_messages() -> None:
    meta = metadata_for(NameKey.subscriber("/tool"), ros_type="std_msgs/msg/Int64")
    message = message_from_node("tool", attrs(meta), text="42")
    assert isinstance(message.body, String) and value_from_message(message) == 42
    moved = np.eye(4)
    moved[0, 3] = 5.0
    transform = message_from_node("tf:w>t", {}, matrix=moved.tolist())
    assert isinstance(transform.body, Transform)
    np.testing.assert_allclose(value_from_message(transform), moved)
    assert message_from_node("x", {}) is None
    poses = message_from_node("poses:R", attrs(metadata_for(NameKey.robot_poses("R"))),
                              poses=(["R:a", "R:b"], [moved.ravel(), np.eye(4).ravel()]))
    assert isinstance(poses.body, TrackingData) and poses.metadata["ros2.robot"] == "R"
    assert [e.name for e in poses.body.elements] == ["R:a", "R:b"]
    np.testing.assert_allclose(poses.body.elements[0].matrix, moved)


# --- values and matrices ------------------------------------------------------------------
@pytest.mark.parametrize("ros_type, text, fmt, value", [
    ("std_msgs/msg/String", "hi", "text", "hi"),
    ("std_msgs/msg/Bool", "true", "text", True),
    ("std_msgs/msg/Float64", "2.5", "text", 2.5),
    ("std_msgs/msg/Empty", "", "text", None),
    ("std_msgs/msg/Float64MultiArray", "[[1, 2], [3, 4]]", "json", [[1, 2], [3, 4]]),
])
def test_values_follow_the_metadata(ros_type: str, text: str, fmt: str, value) -> None:
    message = Message("d", String(text), metadata={"ros2.type": ros_type, "ros2.format": fmt})
    assert value_from_message(message) == value


def test_matrices_accept_lists_and_refuse_non_rigid() -> None:
    np.testing.assert_allclose(as_numpy([[1, 0, 0, 1], [0, 1, 0, 2], [0, 0, 1, 3],
                                         [0, 0, 0, 1]])[:3, 3], [1, 2, 3])
    with pytest.raises(MatrixError, match="shape"):
        as_numpy(np.eye(3))
    with pytest.raises(MatrixError):
        as_numpy(np.diag([2.0, 1.0, 1.0, 1.0]))


def test_vtk_matrices_when_vtk_is_importable() -> None:
    if importlib.util.find_spec("vtk") is None:
        with pytest.raises(ImportError, match="vtk"):
            to_vtk(np.eye(4))
        pytest.skip("vtk is not installed here: only the clear ImportError was checked")
    matrix = np.eye(4)
    matrix[1, 3] = 7.0
    vtk_matrix = to_vtk(matrix)
    assert vtk_matrix.GetElement(1, 3) == 7.0
    np.testing.assert_allclose(as_numpy(vtk_matrix), matrix)


# --- markers --------------------------------------------------------------------------


def test_marker_models_go_under_their_frame_transform_in_a_topic_folder() -> None:
    from slicer_client.scene_plan import MARKERS_FOLDER, stale_marker_nodes

    key = NameKey.marker("/viz", "shapes", 7)
    meta = metadata_for(key, frame="base", units="mm")
    meta.update({"ros2.marker_type": "cube", "ros2.parent_device": "mkf:world>base",
                 "ros2.color": "1 0 0 0.5"})
    plan = plan_node(device_name_for(key), meta)
    assert (plan.kind, plan.parent_device, plan.folder) == ("marker", "mkf:world>base",
                                                            "markers /viz")
    assert plan.colour == (1.0, 0.0, 0.0) and plan.opacity == 0.5
    assert plan.display_name == "/viz shapes/7 (cube)" and not plan.point_colours
    assert plan_node("x", {**meta, "ros2.point_colors": "1"}).point_colours
    # A text marker is a text node: no transform parent, a labelled point instead.
    text = plan_node("t", {**meta, "ros2.marker_type": "text_view_facing",
                           "ros2.position": "10 20 30"})
    assert (text.kind, text.parent_device, text.label_parent, text.label_position) == (
        "marker_text", None, "mkf:world>base", (10.0, 20.0, 30.0))
    frame = plan_node("mkf:world>base", metadata_for(NameKey.marker_frame("world", "base")))
    assert (frame.kind, frame.folder) == ("marker_frame", MARKERS_FOLDER)
    # Nodes the topic's latest list no longer holds are removed; other topics' stay.
    nodes = {"a": {"ros2.role": "marker", "ros2.topic": "/viz"},
             "b": {"ros2.role": "marker", "ros2.topic": "/viz"},
             "c": {"ros2.role": "marker", "ros2.topic": "/other"},
             "d": {"ros2.role": "tf_lookup"}}
    assert stale_marker_nodes(nodes, {"/viz": ["b"]}) == ["a"]
    assert stale_marker_nodes(nodes, {"/viz": [], "/other": []}) == ["a", "b", "c"]
