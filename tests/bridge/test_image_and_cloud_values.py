"""sensor_msgs/Image and point clouds from a client's values and unusual bodies: what is
accepted (big-endian pixels, fractional pixels, duplicated or odd PointCloud2 fields, cell
data) and what is refused, naming the field. Real rclpy classes, real numpy."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from geometry_msgs.msg import Point32
from sensor_msgs.msg import ChannelFloat32, PointCloud, PointCloud2, PointField

from bridge.codecs import CodecError, codec_for
from protocol.messages import AttributeKind, Image, Point, PolyData, PolyDataAttribute

pytestmark = pytest.mark.ros


def _refusal(call: Any) -> CodecError:
    with pytest.raises(CodecError) as caught:
        call()
    return caught.value


# ------------------------------------------------------------------ images

def test_big_endian_pixels_from_an_image_body_are_read_in_order() -> None:
    pixels = np.arange(6, dtype=">u2").reshape(1, 2, 3, 1)
    body = Image(pixels=pixels, spacing=np.ones(3), directions=np.eye(3), origin=np.zeros(3))
    msg = codec_for("sensor_msgs/msg/Image").from_igtl(body, metadata={"ros2.encoding": "mono16"})
    assert (msg.height, msg.width, msg.encoding) == (2, 3, "mono16")
    values = np.frombuffer(bytes(msg.data), dtype=">u2" if msg.is_bigendian else "<u2")
    assert values.tolist() == [0, 1, 2, 3, 4, 5]


def test_fractional_pixels_without_an_encoding_become_32fc1() -> None:
    msg = codec_for("sensor_msgs/msg/Image").from_value({"pixels": [[0.5, 2.0]]})
    assert (msg.encoding, msg.height, msg.width) == ("32FC1", 1, 2)
    assert np.frombuffer(bytes(msg.data), dtype="<f4").tolist() == [0.5, 2.0]


@pytest.mark.parametrize("value, field, expected, got", [
    ({"encoding": 5, "pixels": []}, "value.encoding", "a string", "int"),
    ({"encoding": "mono8"}, "value.pixels", "rows of pixels", "nothing"),
    ({"pixels": [1, 2]}, "value.pixels", "rows x columns (x components)", "shape (2,)"),
    ({"data": "AAAA", "height": 1, "width": 1}, "value.encoding", "an encoding with data",
     "nothing"),
    ({"encoding": "mono8", "data": 5, "height": 1, "width": 1}, "value.data", "base64 text",
     "int"),
    ({"encoding": "mono8", "data": "@@@", "height": 1, "width": 1}, "value.data",
     "base64 text", "str"),
])
def test_bad_image_values_name_the_field(value: dict[str, Any], field: str, expected: str,
                                         got: str) -> None:
    err = _refusal(lambda: codec_for("sensor_msgs/msg/Image").from_value(value))
    assert (err.field, err.expected, err.got) == (field, expected, got)


# ------------------------------------------------------------------ point clouds

_XYZ = [PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1)
        for i, c in enumerate("xyz")]


def _cloud(extra: list[PointField], *, step: int = 16) -> PointCloud2:
    data = np.zeros(step, dtype=np.uint8)
    data[:12] = np.frombuffer(np.array([1.0, 2.0, 3.0], dtype="<f4").tobytes(), np.uint8)
    data[12:16] = [10, 20, 30, 40]
    return PointCloud2(height=1, width=1, point_step=step, row_step=step, fields=_XYZ + extra,
                       data=data.tobytes())


def test_a_duplicated_field_name_keeps_the_first() -> None:
    extra = [PointField(name="x", offset=12, datatype=PointField.FLOAT32, count=1)]
    value = codec_for("sensor_msgs/msg/PointCloud2").to_value(_cloud(extra))
    assert value == {"points": [[1000.0, 2000.0, 3000.0]]}


@pytest.mark.parametrize("name", ["rgb", "normal"])
def test_fields_of_several_bytes_are_left_out(name: str) -> None:
    # A colour as 4 UINT8 (an unusual layout) or a 4-count field: not misread, left out.
    extra = [PointField(name=name, offset=12, datatype=PointField.UINT8, count=4)]
    value = codec_for("sensor_msgs/msg/PointCloud2").to_value(_cloud(extra))
    assert value == {"points": [[1000.0, 2000.0, 3000.0]]}


def test_a_zero_point_step_is_refused() -> None:
    cloud = PointCloud2(height=1, width=1, point_step=0, row_step=0, fields=_XYZ, data=b"")
    err = _refusal(lambda: codec_for("sensor_msgs/msg/PointCloud2").to_value(cloud))
    assert (err.field, err.expected, str(err.got)) == ("point_step", "> 0", "0")


def test_cloud_values_that_are_not_points_are_refused() -> None:
    codec = codec_for("sensor_msgs/msg/PointCloud2")
    err = _refusal(lambda: codec.from_value(5))
    assert (err.field, err.got) == ("value", "int")
    err = _refusal(lambda: codec.from_value({"points": [[0, 0, 0]], "colors": []}))
    assert (err.field, err.expected) == ("value.colors", "points or rgba")


def test_an_empty_markups_list_is_an_empty_cloud_and_cell_data_is_dropped() -> None:
    codec = codec_for("sensor_msgs/msg/PointCloud2")
    empty = codec.from_igtl(Point([]))
    assert (empty.width, len(empty.data)) == (0, 0)
    body = PolyData(points=np.array([[1000.0, 0, 0], [0, 1000.0, 0]], dtype=np.float32),
                    attributes=[PolyDataAttribute(name="labels", kind=AttributeKind.SCALAR,
                                                  data=np.array([7.0], np.float32),
                                                  on_cells=True)])
    cloud = codec.from_igtl(body)
    assert cloud.width == 2
    assert [f.name for f in cloud.fields] == ["x", "y", "z"]


def test_point_cloud_v1_values_both_ways_in_mm() -> None:
    codec = codec_for("sensor_msgs/msg/PointCloud")
    msg = PointCloud(points=[Point32(x=0.001, y=0.0, z=0.0)],
                     channels=[ChannelFloat32(name="intensity", values=[3.0])])
    value = codec.to_value(msg)
    assert np.allclose(value["points"], [[1.0, 0.0, 0.0]])
    back = codec.from_value({"points": [[1, 2, 3]]})
    p = back.points[0]
    assert (p.x, p.y, p.z) == pytest.approx((0.001, 0.002, 0.003))
