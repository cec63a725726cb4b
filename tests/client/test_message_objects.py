"""Message objects built at run time from the daemon's type descriptions, and the
reference's Slicer values, with VTK and with the plain stand-ins (no daemon: the
descriptions come from the same function the daemon answers `describe_type` with)."""

from __future__ import annotations

import base64

import numpy as np
import pytest

from protocol.commands import TypeDescription
from slicer_client.reference.messages import (MessageTypes, MessageValueError, accessor_name,
                                              vtk_class_name)
from slicer_client.reference.slicer_types import slicer_type_for
from slicer_client.reference.vtk_values import SlicerValues, array_values, table_columns

pytestmark = pytest.mark.ros
interface_types = pytest.importorskip("bridge.types.capability",
                                      reason="describes types with rclpy's introspection")


def _describe(name: str, kind: str) -> TypeDescription:
    return TypeDescription.from_dict(interface_types.describe_type(name, kind).to_dict())


@pytest.fixture(params=["vtk", "plain"])
def values(request: pytest.FixtureRequest) -> SlicerValues:
    if request.param == "vtk":
        pytest.importorskip("vtk", reason="the test extra installs vtk")
        return SlicerValues(None)
    return SlicerValues(False)


@pytest.fixture
def types(values: SlicerValues) -> MessageTypes:
    return MessageTypes(_describe, values)


def test_names_follow_the_reference_generator() -> None:
    assert accessor_name("frame_id") == "FrameId"
    assert accessor_name("child_frame_id") == "ChildFrameId"
    assert vtk_class_name("geometry_msgs/msg/PoseArray") == "vtkGeometryMsgsPoseArray"
    assert vtk_class_name("turtlesim/srv/Spawn_Request") == "vtkTurtlesimSpawnRequest"


def test_a_pose_array_round_trips_through_ros_units(types: MessageTypes) -> None:
    message = types.new("geometry_msgs/msg/PoseArray")
    assert type(message).__name__ == "vtkGeometryMsgsPoseArray"
    assert message.GetHeader().GetFrameId() == "" and message.GetPoses() == ()
    message.GetHeader().SetFrameId("base")
    message.GetHeader().GetStamp().SetSec(5)
    pose = types.values.matrix()
    pose.SetElement(0, 3, 250.0)  # mm
    pose.SetElement(0, 0, 0.0)
    pose.SetElement(0, 1, -1.0)
    pose.SetElement(1, 0, 1.0)
    pose.SetElement(1, 1, 0.0)
    message.SetPoses([pose, np.eye(4)])
    ros = message.to_ros()
    assert ros["header"] == {"stamp": {"sec": 5, "nanosec": 0}, "frame_id": "base"}
    assert ros["poses"][0]["position"] == {"x": 0.25, "y": 0.0, "z": 0.0}  # metres
    assert ros["poses"][0]["orientation"]["z"] == pytest.approx(np.sqrt(0.5))
    back = types.from_ros("geometry_msgs/msg/PoseArray", ros)
    assert back == message
    assert back.GetPoses()[0].GetElement(0, 3) == 250.0
    assert back.GetPoses()[1].GetElement(2, 2) == 1.0


def test_a_message_from_ros_converts_each_field_when_first_read(types: MessageTypes) -> None:
    """A subscriber's GetLastMessage at a display's rate: a field is converted when read
    (the pose, not the header too), once; a field the JSON lacks reads as its default, a
    malformed one fails when read, naming it, and the rest still reads."""
    ros = {"header": {"stamp": {"sec": 7, "nanosec": 9}, "frame_id": "tool"},
           "pose": {"position": {"x": 0.5, "y": 0.0, "z": 0.0},
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}}
    message = types.from_ros("geometry_msgs/msg/PoseStamped", ros)
    assert set(dict(message._fields)) == set()  # nothing converted yet
    pose = message.GetPose()
    assert pose.GetElement(0, 3) == 500.0 and message.GetPose() is pose  # mm, once
    assert set(dict(message._fields)) == {"pose"}
    assert message.GetHeader().GetStamp().GetSec() == 7
    assert message.to_ros() == ros
    partial = types.from_ros("geometry_msgs/msg/PoseStamped", {"pose": ros["pose"]})
    assert partial.GetHeader().GetFrameId() == "" and partial.GetPose().GetElement(0, 3) == 500.0
    bad = types.from_ros("geometry_msgs/msg/PoseStamped",
                         {"header": ros["header"], "pose": {"position": {"x": 1.0}}})
    assert bad.GetHeader().GetFrameId() == "tool"
    with pytest.raises(MessageValueError, match=r"pose: expected a geometry_msgs/msg/Pose "
                                                 r"\(position x y z, orientation x y z w\), "
                                                 r"got \{'position': \{'x': 1.0\}\}"):
        bad.GetPose()  # its position lacks y, and it has no orientation: said when read


def test_wrench_and_twist_are_arrays_of_six_and_anything_else_of_six_is_zeros(
        types: MessageTypes) -> None:
    message = types.new("geometry_msgs/msg/WrenchStamped")
    wrench = message.GetWrench()
    assert array_values(wrench) == [0.0] * 6
    wrench.SetValue(4, 2.5)
    assert message.to_ros()["wrench"] == {"force": {"x": 0.0, "y": 0.0, "z": 0.0},
                                          "torque": {"x": 0.0, "y": 2.5, "z": 0.0}}
    wrench.SetNumberOfValues(2)  # the reference sends zeros for anything but 6 values
    assert message.to_ros()["wrench"]["torque"] == {"x": 0.0, "y": 0.0, "z": 0.0}
    twist = types.new("geometry_msgs/msg/TwistStamped")
    twist.SetTwist([1, 2, 3, 4, 5, 6])
    assert twist.to_ros()["twist"]["angular"] == {"x": 4.0, "y": 5.0, "z": 6.0}


def test_sequences_fixed_arrays_bytes_and_checks(types: MessageTypes) -> None:
    state = types.new("sensor_msgs/msg/JointState")
    state.SetName(["a", "b"])
    state.SetPosition(np.array([0.5, 1]))
    assert state.GetName() == ("a", "b") and state.GetPosition() == (0.5, 1.0)
    with pytest.raises(MessageValueError, match=r"JointState.position\[1\]: expected a number"):
        state.SetPosition([0.5, "x"])
    with pytest.raises(MessageValueError, match="name: expected a sequence"):
        state.SetName(3)
    uuid = types.new("unique_identifier_msgs/msg/UUID")
    assert uuid.GetUuid() == (0,) * 16
    with pytest.raises(MessageValueError, match="expected 16 values, got 2"):
        uuid.SetUuid([1, 2])
    uuid.SetUuid(range(16))
    assert uuid.to_ros() == {"uuid": base64.b64encode(bytes(range(16))).decode()}
    assert types.from_ros("unique_identifier_msgs/msg/UUID", uuid.to_ros()) == uuid
    assert types.for_yaml("unique_identifier_msgs/msg/UUID", uuid.to_ros()) == {
        "uuid": list(range(16))}
    header = types.new("std_msgs/msg/Header")
    with pytest.raises(MessageValueError, match="stamp: expected a vtkBuiltinInterfacesTime"):
        header.SetStamp(5)
    header.SetStamp({"sec": 3, "nanosec": 4})  # generic JSON is taken too
    assert header.GetStamp().GetSec() == 3


def test_constants_and_defaults_come_from_the_type(types: MessageTypes) -> None:
    status = types.message_class("action_msgs/msg/GoalStatus")
    assert status.STATUS_ACCEPTED == 1 and status.STATUS_ABORTED == 6
    quaternion_default = types.new("geometry_msgs/msg/Quaternion")
    assert quaternion_default.GetW() == 1.0  # the .msg default, not 0


def test_service_parts_have_their_own_classes(types: MessageTypes) -> None:
    described = types.description("std_srvs/srv/SetBool", "service")
    request = types.new(described.parts["request"])
    assert type(request).__name__ == "vtkStdSrvsSetBoolRequest"
    request.SetData(True)
    assert request.to_ros() == {"data": True}


def test_the_reference_slicer_types_both_ways(types: MessageTypes, values: SlicerValues) -> None:
    def of(name: str, ros_type: str):  # noqa: ANN202
        return slicer_type_for(name, ros_type, types, values)

    table = of("vtkMRMLROS2PublisherIntTableNode", "std_msgs/msg/Int64MultiArray")
    columns = values.table()
    for column in ([0, 3, 6], [1, 5, 9]):
        columns.AddColumn(values.filled_array(column, integer=True))
    kind, message = table.to_publish(columns)
    assert kind == "message" and message["data"] == [0, 1, 3, 5, 6, 9]
    assert message["layout"]["dim"] == [{"label": "x", "size": 3, "stride": 2},
                                        {"label": "y", "size": 2, "stride": 1}]
    assert table_columns(table.from_ros(message)) == [[0, 3, 6], [1, 5, 9]]
    array = of("IntArray", "std_msgs/msg/Int64MultiArray")
    assert array_values(array.from_ros(array.to_publish([1, 2, 3])[1])) == [1, 2, 3]
    with pytest.raises(MessageValueError, match="expected integers, got 1.5"):
        array.to_publish([1, 1.5])
    assert of("String", "std_msgs/msg/String").to_publish("x") == ("message", {"data": "x"})
    with pytest.raises(MessageValueError, match="expected a string"):
        of("String", "std_msgs/msg/String").to_publish(3)
    with pytest.raises(MessageValueError, match="int64"):
        of("Int", "std_msgs/msg/Int64").to_publish(2**63)
    assert of("Empty", "std_msgs/msg/Empty").from_ros({}) == ""
    pose = of("Pose", "geometry_msgs/msg/Pose")
    matrix = pose.blank()
    matrix.SetElement(2, 3, 3.1415)
    assert pose.from_ros(pose.to_publish(matrix)[1]).GetElement(2, 3) == 3.1415
    sheared = np.eye(4)
    sheared[0, 1] = 0.2
    with pytest.raises(MessageValueError, match="orthonormal"):
        pose.to_publish(sheared)
    stamped = of("PoseStamped", "geometry_msgs/msg/PoseStamped")
    blank = stamped.blank()
    assert type(blank).__name__ == "vtkGeometryMsgsPoseStamped"
    # A bare matrix still publishes a PoseStamped (the reference's first releases).
    assert stamped.to_publish(matrix)[1]["pose"]["position"]["z"] == pytest.approx(0.0031415)
    with pytest.raises(MessageValueError, match="PoseStamped message object"):
        stamped.to_publish("nope")
