"""Generic JSON/YAML over any installed message type, via rclpy introspection."""

from __future__ import annotations

import base64
import json
import math
from typing import Any

import numpy as np
import pytest
import yaml

from bridge.codecs import (
    CodecError,
    codec_for,
    dict_to_message,
    json_to_message,
    message_to_dict,
    message_to_json,
    message_to_yaml,
)
from protocol.messages import String, unpack_body


def _wire(body: Any) -> Any:
    return unpack_body(body.TYPE, body.pack())


def _navsatfix() -> Any:
    from sensor_msgs.msg import NavSatFix, NavSatStatus

    fix = NavSatFix()
    fix.header.stamp.sec, fix.header.stamp.nanosec = 1_700_000_000, 123_456_789
    fix.header.frame_id = "gps"
    fix.status.status = NavSatStatus.STATUS_FIX
    fix.status.service = NavSatStatus.SERVICE_GPS
    fix.latitude, fix.longitude, fix.altitude = 48.8566, 2.3522, 35.25
    fix.position_covariance = np.arange(9, dtype=np.float64) * 0.5
    fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
    return fix


def _marker() -> Any:
    from geometry_msgs.msg import Point
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import Marker, UVCoordinate

    m = Marker()
    m.header.frame_id = "map"
    m.ns, m.id, m.type, m.action = "tools", 7, Marker.LINE_STRIP, Marker.ADD
    m.pose.position.x, m.pose.orientation.w = 0.25, 1.0
    m.scale.x = 0.01
    m.color = ColorRGBA(r=1.0, g=0.5, b=0.25, a=1.0)
    m.lifetime.sec, m.lifetime.nanosec = 2, 500_000_000
    m.points = [Point(x=float(i), y=-float(i), z=0.5 * i) for i in range(5)]
    m.colors = [ColorRGBA(r=0.1 * i, a=1.0) for i in range(5)]
    m.texture.format = "png"
    m.texture.data = bytes([0, 1, 2, 254, 255])
    m.uv_coordinates = [UVCoordinate(u=0.5, v=0.25)]
    m.text = "naïve ✓"
    m.mesh_file.filename = "tool.stl"
    m.mesh_file.data = bytes(range(16))
    return m


def test_navsatfix_round_trips_field_equal() -> None:
    fix = _navsatfix()
    d = message_to_dict(fix)
    assert d["header"] == {"stamp": {"sec": 1_700_000_000, "nanosec": 123_456_789},
                           "frame_id": "gps"}
    assert d["position_covariance"] == [0.5 * i for i in range(9)]
    assert "COVARIANCE_TYPE_DIAGONAL_KNOWN" not in d  # constants are not fields
    back = json_to_message("sensor_msgs/msg/NavSatFix", message_to_json(fix))
    assert back == fix


def test_marker_nested_and_arrays_round_trip_field_equal() -> None:
    m = _marker()
    text = message_to_json(m)
    d = json.loads(text)
    assert d["points"][3] == {"x": 3.0, "y": -3.0, "z": 1.5}
    # uint8[] travels as base64 in JSON
    assert base64.b64decode(d["texture"]["data"]) == bytes([0, 1, 2, 254, 255])
    assert list(d) == list(type(m).get_fields_and_field_types())  # field order kept
    back = json_to_message("visualization_msgs/msg/Marker", text)
    assert back == m


def test_generic_codec_through_a_string_body() -> None:
    m = _marker()
    codec = codec_for("visualization_msgs/msg/Marker")
    enc = codec.encode(m)
    assert isinstance(enc.body, String)
    assert enc.metadata["ros2.format"] == "json"
    assert enc.metadata["ros2.frame"] == "map"
    assert codec.from_igtl(_wire(enc.body)) == m
    assert codec.from_value(codec.to_value(m)) == m


def test_caller_stamp_and_frame_override_the_header() -> None:
    codec = codec_for("sensor_msgs/msg/NavSatFix")
    msg = codec.from_value(message_to_dict(_navsatfix()), stamp=(5, 6), frame_id="base")
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (5, 6)
    assert msg.header.frame_id == "base"


def test_bytes_accepted_as_list_of_ints_too() -> None:
    d = message_to_dict(_marker(), bytes_as="list")
    assert d["texture"]["data"] == [0, 1, 2, 254, 255]
    assert dict_to_message("visualization_msgs/msg/Marker", d) == _marker()


def test_byte_array_and_octet_fields() -> None:
    from std_msgs.msg import ByteMultiArray
    from unique_identifier_msgs.msg import UUID

    arr = ByteMultiArray(data=[b"\x00", b"\x7f", b"\xff"])
    d = message_to_dict(arr)
    assert base64.b64decode(d["data"]) == b"\x00\x7f\xff"
    assert dict_to_message(ByteMultiArray, d) == arr
    uid = UUID(uuid=np.arange(16, dtype=np.uint8))
    assert dict_to_message(UUID, json.loads(message_to_json(uid))) == uid
    with pytest.raises(CodecError) as err:
        dict_to_message(UUID, {"uuid": [1, 2, 3]})
    assert err.value.field == "uuid"
    assert "16" in err.value.expected


def test_time_accepts_seconds() -> None:
    from builtin_interfaces.msg import Time

    msg = dict_to_message("std_msgs/msg/Header", {"stamp": 12.25, "frame_id": "x"})
    assert msg.stamp == Time(sec=12, nanosec=250_000_000)


def test_nan_survives_json() -> None:
    from std_msgs.msg import Float64

    back = json_to_message("std_msgs/msg/Float64", message_to_json(Float64(data=math.nan)))
    assert math.isnan(back.data)


def test_yaml_is_ros2_topic_echo_style() -> None:
    from std_msgs.msg import String as RosString

    assert message_to_yaml(RosString(data="hello")).strip() == "data: hello"
    text = message_to_yaml(_navsatfix())
    assert "header:\n  stamp:\n    sec: 1700000000\n    nanosec: 123456789\n  frame_id: gps" \
        in text
    assert "position_covariance:\n- 0.0\n- 0.5\n" in text
    assert yaml.safe_load(message_to_yaml(_marker()))["texture"]["data"] == [0, 1, 2, 254, 255]
    assert codec_for("String").to_yaml(RosString(data="hello")).strip() == "data: hello"


@pytest.mark.parametrize("ros_type, value, field", [
    ("sensor_msgs/msg/NavSatFix", {"latitude": "north"}, "latitude"),
    ("sensor_msgs/msg/NavSatFix", {"latitude": True}, "latitude"),
    ("sensor_msgs/msg/NavSatFix", {"status": {"status": 200}}, "status.status"),  # int8
    ("sensor_msgs/msg/NavSatFix", {"status": {"service": -1}}, "status.service"),  # uint16
    ("sensor_msgs/msg/NavSatFix", {"header": {"frame_id": 5}}, "header.frame_id"),
    ("sensor_msgs/msg/NavSatFix", {"header": []}, "header"),
    ("sensor_msgs/msg/NavSatFix", {"position_covariance": [1.0] * 8}, "position_covariance"),
    ("sensor_msgs/msg/NavSatFix", {"position_covariance": [1.0] * 8 + ["x"]},
     "position_covariance[8]"),
    ("sensor_msgs/msg/NavSatFix", {"altitud": 3.0}, "altitud"),
    ("std_msgs/msg/Int64", {"data": 2**63}, "data"),
    ("std_msgs/msg/Int64", {"data": 1.5}, "data"),
    ("std_msgs/msg/Int64MultiArray", {"data": [1, 2**64]}, "data[1]"),
    ("std_msgs/msg/Int64MultiArray", {"data": [1, True]}, "data[1]"),
    ("std_msgs/msg/Bool", {"data": 1}, "data"),
    ("std_msgs/msg/Float32", {"data": 1e39}, "data"),
    ("visualization_msgs/msg/Marker", {"points": [{"x": 1.0}, {"w": 2.0}]}, "points[1].w"),
    ("visualization_msgs/msg/Marker", {"points": {"x": 1.0}}, "points"),
    ("visualization_msgs/msg/Marker", {"texture": {"data": "not base64!"}}, "texture.data"),
    ("visualization_msgs/msg/Marker", {"texture": {"data": [1, 256]}}, "texture.data[1]"),
])
def test_bad_values_name_the_field(ros_type: str, value: dict[str, Any], field: str) -> None:
    with pytest.raises(CodecError) as err:
        dict_to_message(ros_type, value)
    assert err.value.field == field
    assert err.value.expected


def test_not_an_object_and_bad_json() -> None:
    with pytest.raises(CodecError) as err:
        dict_to_message("std_msgs/msg/String", ["hello"])  # type: ignore[arg-type]
    assert err.value.field == "std_msgs/msg/String"
    with pytest.raises(CodecError) as err:
        json_to_message("std_msgs/msg/String", "{not json")
    assert err.value.field == "text"
    with pytest.raises(CodecError) as err:
        codec_for("sensor_msgs/msg/NavSatFix").from_igtl(String(text="[1, 2]"))
    assert err.value.field == "sensor_msgs/msg/NavSatFix"


def test_wrong_body_type_for_generic_codec() -> None:
    from protocol.messages import Transform

    with pytest.raises(CodecError) as err:
        codec_for("sensor_msgs/msg/NavSatFix").from_igtl(Transform(np.eye(4)))
    assert err.value.field == "body"
    assert "STRING" in err.value.expected


def test_string_body_limit_is_a_codec_error() -> None:
    from std_msgs.msg import String as RosString

    with pytest.raises(CodecError) as err:
        codec_for("String").to_igtl(RosString(data="é" * 40000))  # 80000 bytes of UTF-8
    assert err.value.field == "text"
    assert "65535" in err.value.expected


def test_bool_sequences_bounded_sequences_and_bounded_strings() -> None:
    from rcl_interfaces.msg import ParameterValue
    from shape_msgs.msg import SolidPrimitive

    pv = ParameterValue(type=6, bool_array_value=[True, False, True],
                        string_array_value=["a", "ü"])
    assert json_to_message("rcl_interfaces/msg/ParameterValue", message_to_json(pv)) == pv
    with pytest.raises(CodecError) as err:
        dict_to_message(ParameterValue, {"bool_array_value": [True, 1]})
    assert err.value.field == "bool_array_value[1]"

    box = SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[0.1, 0.2, 0.3])
    assert json_to_message("shape_msgs/msg/SolidPrimitive", message_to_json(box)) == box
    with pytest.raises(CodecError) as err:
        dict_to_message(SolidPrimitive, {"dimensions": [1.0, 2.0, 3.0, 4.0]})
    assert err.value.field == "dimensions" and "at most 3" in err.value.expected

    from rmw_dds_common.msg import NodeEntitiesInfo

    with pytest.raises(CodecError) as err:
        dict_to_message(NodeEntitiesInfo, {"node_name": "n" * 300})
    assert err.value.field == "node_name"


def test_every_installed_message_type_round_trips_its_defaults() -> None:
    from bridge.codecs import installed_types

    types = installed_types()
    assert "tf2_msgs/msg/TFMessage" in types and len(types) > 100
    for ros_type in types:
        cls = codec_for(ros_type).message_class
        assert json_to_message(ros_type, message_to_json(cls())) == cls(), ros_type
