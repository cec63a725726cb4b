"""Type-name resolution and codec selection (real rclpy message classes, no ROS node)."""

from __future__ import annotations

import pytest

from bridge.codecs import CodecError, codec_for, message_class, resolve_type, ros_type_of


@pytest.mark.parametrize("name, expected", [
    ("String", "std_msgs/msg/String"),
    ("vtkMRMLROS2PublisherStringNode", "std_msgs/msg/String"),
    ("vtkMRMLROS2SubscriberPoseStampedNode", "geometry_msgs/msg/PoseStamped"),
    ("std_msgs/msg/String", "std_msgs/msg/String"),
    ("std_msgs/String", "std_msgs/msg/String"),
    ("std_msgs.msg.String", "std_msgs/msg/String"),
    ("Int", "std_msgs/msg/Int64"),
    ("Double", "std_msgs/msg/Float64"),
    ("IntTable", "std_msgs/msg/Int64MultiArray"),
    ("DoubleArray", "std_msgs/msg/Float64MultiArray"),
    ("UInt8Image", "sensor_msgs/msg/Image"),
    ("vtkMRMLROS2SubscriberJointStateNode", "sensor_msgs/msg/JointState"),
    ("NavSatFix", "sensor_msgs/msg/NavSatFix"),  # any installed bare name, found once
    ("vtkMRMLROS2SubscriberNavSatFixNode", "sensor_msgs/msg/NavSatFix"),
    ("  Joy ", "sensor_msgs/msg/Joy"),
])
def test_resolve_type_spellings(name: str, expected: str) -> None:
    assert resolve_type(name) == expected


@pytest.mark.parametrize("name", ["NoSuchType", "nosuch_msgs/msg/Thing", "std_msgs/msg/Nope",
                                  "vtkMRMLROS2SubscriberNoSuchNode", "std_msgs/srv/String",
                                  "", "a b"])
def test_unknown_type_is_a_codec_error_naming_it(name: str) -> None:
    with pytest.raises(CodecError) as err:
        resolve_type(name)
    assert err.value.field == "type"
    assert repr(name.strip()) in str(err.value.got) or repr(name) in str(err.value.got)


def test_non_string_type_name() -> None:
    with pytest.raises(CodecError) as err:
        resolve_type(42)  # type: ignore[arg-type]
    assert err.value.field == "type"


def test_message_class_and_type_of_agree() -> None:
    cls = message_class("visualization_msgs/msg/Marker")
    assert ros_type_of(cls) == "visualization_msgs/msg/Marker"
    assert ros_type_of(cls()) == "visualization_msgs/msg/Marker"


@pytest.mark.parametrize("name, codec_class, igtl", [
    ("Empty", "EmptyCodec", "STRING"),
    ("String", "StringCodec", "STRING"),
    ("Bool", "BoolCodec", "STRING"),
    ("Int64", "Int64Codec", "STRING"),
    ("Float64", "Float64Codec", "STRING"),
    ("Int64MultiArray", "MultiArrayCodec", "STRING"),
    ("Float64MultiArray", "MultiArrayCodec", "STRING"),
    ("Pose", "PoseCodec", "TRANSFORM"),
    ("PoseStamped", "PoseCodec", "TRANSFORM"),
    ("TransformStamped", "PoseCodec", "TRANSFORM"),
    ("WrenchStamped", "WrenchCodec", "STRING"),
    ("PoseArray", "PoseArrayCodec", "STRING"),
    ("JointState", "JointStateCodec", "STRING"),
    ("Joy", "JoyCodec", "STRING"),
    ("Image", "ImageCodec", "IMAGE"),
    ("PointCloud2", "PointCloud2Codec", "POLYDATA"),
    ("PointCloud", "PointCloudCodec", "POLYDATA"),
    ("sensor_msgs/msg/NavSatFix", "GenericJsonCodec", "STRING"),
    ("tf2_msgs/msg/TFMessage", "GenericJsonCodec", "STRING"),
])
def test_codec_for_picks_the_specific_codec(name: str, codec_class: str, igtl: str) -> None:
    codec = codec_for(name)
    assert type(codec).__name__ == codec_class
    assert codec.igtl_type == igtl
    assert codec.ros_type == resolve_type(name)


def test_codec_for_unknown_type() -> None:
    with pytest.raises(CodecError) as err:
        codec_for("geometry_msgs/msg/NoPose")
    assert err.value.field == "type"


def test_wrong_message_instance_is_refused() -> None:
    from std_msgs.msg import Bool

    with pytest.raises(CodecError) as err:
        codec_for("String").to_igtl(Bool(data=True))
    assert err.value.field == "message"
    assert err.value.expected == "std_msgs/msg/String"


def test_unexpected_failures_become_codec_errors() -> None:
    # A body of the right class holding nonsense must not raise anything but CodecError.
    from protocol.messages import Image, PolyData

    with pytest.raises(CodecError) as err:
        codec_for("Image").from_igtl(Image(pixels=object()))  # type: ignore[arg-type]
    assert err.value.field in ("body", "pixels")
    with pytest.raises(CodecError) as err:
        codec_for("PointCloud2").from_igtl(PolyData(points="abc"))  # type: ignore[arg-type]
    assert err.value.field in ("body", "points")
