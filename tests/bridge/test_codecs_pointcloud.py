"""PointCloud2 / PointCloud <-> POLYDATA (mm, vertex cells, RGBA), and back from POINT."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from geometry_msgs.msg import Point32
from rclpy.serialization import serialize_message
from sensor_msgs.msg import ChannelFloat32, PointCloud, PointCloud2, PointField

from bridge.codecs import CodecError, codec_for
from protocol.messages import (
    AttributeKind,
    Point,
    PointElement,
    PolyData,
    PolyDataAttribute,
    String,
    unpack_body,
)
from protocol.polydata import RGBA_ATTRIBUTE

RNG = np.random.default_rng(7)


def _wire(body: Any) -> Any:
    return unpack_body(body.TYPE, body.pack())


def _cloud(xyz: np.ndarray, *, rgb: np.ndarray | None = None, xyz_type: str = "f4",
           point_step: int = 32, offsets: tuple[int, int, int, int] = (0, 4, 8, 16),
           height: int = 1, row_pad: int = 0, big_endian: bool = False,
           intensity: np.ndarray | None = None, colour_name: str = "rgb") -> PointCloud2:
    """A PointCloud2 laid out like real drivers do: fields at given offsets, padding."""
    n = xyz.shape[0]
    width = n // height
    order = ">" if big_endian else "<"
    names: list[str] = ["x", "y", "z"]
    formats = [order + xyz_type] * 3
    offs = list(offsets[:3])
    datatype = PointField.FLOAT32 if xyz_type == "f4" else PointField.FLOAT64
    fields = [PointField(name=c, offset=o, datatype=datatype, count=1)
              for c, o in zip("xyz", offs)]
    if rgb is not None:
        names.append(colour_name)
        formats.append(order + "u4")
        offs.append(offsets[3])
        fields.append(PointField(name=colour_name, offset=offsets[3],
                                 datatype=PointField.FLOAT32, count=1))
    if intensity is not None:
        names.append("intensity")
        formats.append(order + "f4")
        offs.append(offsets[3] + 4)
        fields.append(PointField(name="intensity", offset=offsets[3] + 4,
                                 datatype=PointField.FLOAT32, count=1))
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offs,
                      "itemsize": point_step})
    table = np.zeros(n, dtype=dtype)
    table["x"], table["y"], table["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    if rgb is not None:
        table[colour_name] = rgb
    if intensity is not None:
        table["intensity"] = intensity
    rows = table.view(np.uint8).reshape(height, width * point_step)
    padded = np.full((height, width * point_step + row_pad), 0xEE, dtype=np.uint8)
    padded[:, :width * point_step] = rows
    msg = PointCloud2(height=height, width=width, is_bigendian=big_endian,
                      point_step=point_step, row_step=width * point_step + row_pad,
                      is_dense=False)
    msg.fields = fields
    msg.data.frombytes(padded.tobytes())
    return msg


def _packed(r: np.ndarray, g: np.ndarray, b: np.ndarray, a: np.ndarray | None = None
            ) -> np.ndarray:
    a = np.full_like(r, 255) if a is None else a
    return ((a.astype(np.uint32) << 24) | (r.astype(np.uint32) << 16)
            | (g.astype(np.uint32) << 8) | b.astype(np.uint32))


def test_100k_points_with_rgb_to_polydata_and_back() -> None:
    n = 100_000
    xyz = RNG.uniform(-2.0, 2.0, size=(n, 3)).astype(np.float32)
    colours = RNG.integers(0, 256, size=(n, 3))
    msg = _cloud(xyz, rgb=_packed(colours[:, 0], colours[:, 1], colours[:, 2]))
    codec = codec_for("PointCloud2")
    enc = codec.encode(msg)
    body = enc.body
    assert isinstance(body, PolyData)
    assert enc.metadata["ros2.units"] == "mm" and enc.metadata["ros2.shape"] == str(n)
    np.testing.assert_allclose(body.points, xyz.astype(np.float64) * 1000.0, rtol=1e-6)
    # one polyvertex cell of all the points, [n, 0..n-1] (Slicer's converter crashed on a
    # second vertex cell)
    np.testing.assert_array_equal(body.vertices, [n, *range(n)])
    (rgba,) = [a for a in body.attributes if a.name == RGBA_ATTRIBUTE]
    assert (rgba.kind, rgba.on_cells) == (AttributeKind.SCALAR, False)
    np.testing.assert_array_equal(np.round(rgba.data[:, :3] * 255), colours)
    np.testing.assert_array_equal(rgba.data[:, 3], 1.0)

    back = codec.from_igtl(_wire(body))
    assert (back.height, back.width, back.is_dense) == (1, n, True)
    assert [f.name for f in back.fields] == ["x", "y", "z", "rgb"]
    table = np.frombuffer(back.data, dtype=np.dtype({"names": ["x", "y", "z", "rgb"],
                                                     "formats": ["<f4"] * 3 + ["<u4"]}))
    np.testing.assert_allclose(table["x"], xyz[:, 0], rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal((table["rgb"] >> 16) & 0xFF, colours[:, 0])
    np.testing.assert_array_equal(table["rgb"] & 0xFF, colours[:, 2])


def test_nan_points_are_dropped_with_their_colours() -> None:
    xyz = np.array([[1.0, 2.0, 3.0], [np.nan, 0.0, 0.0], [0.5, np.inf, 0.0], [-1.0, -2.0, -3.0]],
                   dtype=np.float32)
    rgb = _packed(np.array([10, 20, 30, 40]), np.array([0, 0, 0, 0]), np.array([1, 2, 3, 4]))
    enc = codec_for("PointCloud2").encode(_cloud(xyz, rgb=rgb))
    np.testing.assert_allclose(enc.body.points, [[1000, 2000, 3000], [-1000, -2000, -3000]])
    assert enc.metadata["ros2.dropped"] == "2"
    (rgba,) = enc.body.attributes
    np.testing.assert_array_equal(np.round(rgba.data * 255)[:, 0], [10, 40])
    assert enc.body.vertices.tolist() == [2, 0, 1]


def test_points_finite_in_metres_but_not_as_float32_in_mm_are_dropped() -> None:
    xyz = np.array([[1.0, 2.0, 3.0], [1e36, 0.0, 0.0], [0.0, -3e38, 0.0], [3e35, 0.0, 0.0]],
                   dtype=np.float32)
    enc = codec_for("PointCloud2").encode(_cloud(xyz))
    assert np.all(np.isfinite(enc.body.points))
    np.testing.assert_allclose(enc.body.points, [[1000, 2000, 3000], [3e38, 0, 0]], rtol=1e-6)
    assert enc.metadata["ros2.dropped"] == "2"


def test_float64_fields_odd_offsets_row_padding_and_intensity() -> None:
    xyz = RNG.normal(size=(12, 3))
    intensity = np.arange(12, dtype=np.float32)
    msg = _cloud(xyz, xyz_type="f8", point_step=48, offsets=(8, 16, 24, 32), height=3,
                 row_pad=5, rgb=_packed(np.full(12, 255), np.full(12, 128), np.zeros(12)),
                 intensity=intensity)
    body = codec_for("PointCloud2").to_igtl(msg)
    np.testing.assert_allclose(body.points, xyz * 1000.0, rtol=1e-6)
    attrs = {a.name: a for a in body.attributes}
    np.testing.assert_array_equal(attrs["intensity"].data[:, 0], intensity)
    assert attrs["intensity"].kind == AttributeKind.SCALAR
    np.testing.assert_allclose(attrs["RGBA"].data[0], [1.0, 128 / 255, 0.0, 1.0])
    back = codec_for("PointCloud2").from_igtl(_wire(body))
    assert [f.name for f in back.fields] == ["x", "y", "z", "rgb", "intensity"]


def test_float32_cloud_gives_the_bytes_of_the_same_numbers_as_float64() -> None:
    # float32 x, y, z take their own path (float32 mm straight): the same POLYDATA, NaN
    # rows, rows beyond float32 in mm, colours and scalars dropped alike.
    xyz = RNG.normal(size=(300, 3)).astype(np.float32) * np.float32(10.0) ** RNG.integers(
        -40, 39, size=(300, 3)).astype(np.float32)
    xyz[::7, 1] = np.nan
    top = np.float32(np.finfo(np.float32).max / 1000.0)  # the last length finite in mm
    xyz[5] = (0.1, 0.2, top)
    xyz[6] = (np.nextafter(top, np.float32(np.inf)), 0.0, 0.0)
    rgb = _packed(*(RNG.integers(0, 256, size=(3, 300))))
    intensity = RNG.random(300).astype(np.float32)
    codec = codec_for("PointCloud2")
    single = codec.encode(_cloud(xyz, rgb=rgb, intensity=intensity, height=2, row_pad=3))
    double = codec.encode(_cloud(xyz.astype(np.float64), rgb=rgb, intensity=intensity,
                                 height=2, row_pad=3, xyz_type="f8", point_step=48,
                                 offsets=(0, 8, 16, 24)))
    assert single.body.pack() == double.body.pack()
    assert single.metadata == double.metadata
    assert single.metadata["ros2.dropped"] == str(300 - single.body.points.shape[0])
    assert np.finfo(np.float32).max in single.body.points[:, 2]  # row 5 kept, row 6 not
    assert not np.isin(single.body.points[:, 0], [np.inf, -np.inf]).any()


@pytest.mark.parametrize("frame_id", ["", "c", "camera_depth_optical_frame"])
def test_a_cloud_read_from_its_bytes_gives_what_the_message_gives(frame_id: str) -> None:
    # The daemon reads a subscribed cloud from its serialized bytes (no rclpy message):
    # the same body, metadata and stamp, whatever the alignment the frame id leaves.
    xyz = RNG.normal(size=(60, 3)).astype(np.float32)
    xyz[::9, 0] = np.nan
    rgb = _packed(*(RNG.integers(0, 256, size=(3, 60))))
    clouds = [_cloud(xyz, rgb=rgb, intensity=RNG.random(60).astype(np.float32), height=3,
                     row_pad=3),
              _cloud(xyz, rgb=rgb, big_endian=True, colour_name="rgba", point_step=16,
                     offsets=(0, 4, 8, 12)),
              _cloud(xyz.astype(np.float64), xyz_type="f8", point_step=48,
                     offsets=(8, 16, 24, 32)),
              _cloud(np.zeros((0, 3), np.float32))]
    codec = codec_for("PointCloud2")
    for msg in clouds:
        msg.header.frame_id = frame_id
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1_700_000_000, 123_456_789
        read = codec.encode_serialized(serialize_message(msg))
        made = codec.encode(msg)
        assert read is not None
        assert read.body.pack() == made.body.pack()
        assert (read.metadata, read.stamp) == (made.metadata, made.stamp)
    assert codec.encode_serialized(b"\x00\x00" + serialize_message(clouds[0])[2:]) is None


def test_big_endian_cloud_and_rgba_field() -> None:
    xyz = np.array([[0.001, 0.002, 0.003]], dtype=np.float32)
    msg = _cloud(xyz, rgb=_packed(np.array([1]), np.array([2]), np.array([3]), np.array([128])),
                 big_endian=True, colour_name="rgba")
    body = codec_for("PointCloud2").to_igtl(msg)
    np.testing.assert_allclose(body.points, [[1.0, 2.0, 3.0]], rtol=1e-6)
    np.testing.assert_allclose(body.attributes[0].data * 255, [[1, 2, 3, 128]], atol=1e-4)
    back = codec_for("PointCloud2").from_igtl(_wire(body))
    assert back.fields[3].name == "rgba"  # not opaque: alpha kept
    assert int(np.frombuffer(back.data, "<u4")[3]) >> 24 == 128


def test_uncoloured_cloud_has_no_attribute_and_empty_cloud_works() -> None:
    body = codec_for("PointCloud2").to_igtl(_cloud(np.zeros((3, 3), np.float32), point_step=16))
    assert body.attributes == [] and body.points.shape == (3, 3)
    empty = codec_for("PointCloud2").to_igtl(_cloud(np.zeros((0, 3), np.float32)))
    assert empty.points.shape == (0, 3)
    back = codec_for("PointCloud2").from_igtl(_wire(empty))
    assert back.width == 0 and len(back.data) == 0


@pytest.mark.parametrize("change, field", [
    (lambda m: m.data.pop(), "data"),
    (lambda m: setattr(m, "row_step", m.row_step - 1), "row_step"),
    (lambda m: setattr(m, "fields", m.fields[:2]), "fields"),
    (lambda m: setattr(m.fields[1], "offset", 30), "fields[1].offset"),
    (lambda m: setattr(m.fields[0], "datatype", 5), "fields[0]"),
    (lambda m: setattr(m.fields[2], "datatype", 42), "fields[2].datatype"),
])
def test_bad_clouds_are_codec_errors(change: Any, field: str) -> None:
    msg = _cloud(np.ones((4, 3), np.float32))
    change(msg)
    with pytest.raises(CodecError) as err:
        codec_for("PointCloud2").to_igtl(msg)
    assert err.value.field == field


def test_from_point_body() -> None:
    body = Point([PointElement(name="F-1", rgba=(255, 0, 0, 255), position=np.array([1., 2., 3.])),
                  PointElement(name="F-2", rgba=(0, 255, 0, 255),
                               position=np.array([-10., 0., 5.5]))])
    cloud = codec_for("PointCloud2").from_igtl(_wire(body), frame_id="ras")
    assert cloud.header.frame_id == "ras" and cloud.width == 2
    table = np.frombuffer(cloud.data, dtype=np.dtype({"names": ["x", "y", "z", "rgb"],
                                                      "formats": ["<f4"] * 3 + ["<u4"]}))
    np.testing.assert_allclose(np.stack([table["x"], table["y"], table["z"]], 1),
                               [[0.001, 0.002, 0.003], [-0.01, 0.0, 0.0055]], rtol=1e-6)
    assert [int(v) & 0xFFFFFF for v in table["rgb"]] == [0xFF0000, 0x00FF00]


def test_polydata_with_nan_point_from_slicer_is_refused() -> None:
    body = PolyData(points=np.array([[0, 0, 0], [np.nan, 1, 1]], dtype=np.float32))
    with pytest.raises(CodecError) as err:
        codec_for("PointCloud2").from_igtl(body)
    assert err.value.field == "points[1]"
    with pytest.raises(CodecError) as err:
        codec_for("PointCloud2").from_igtl(String(text="points"))
    assert err.value.field == "body"


def test_point_cloud_v1_round_trip() -> None:
    codec = codec_for("PointCloud")
    msg = PointCloud()
    msg.header.frame_id = "sonar"
    msg.points = [Point32(x=0.1, y=0.2, z=0.3), Point32(x=float("nan"), y=0.0, z=0.0),
                  Point32(x=-0.5, y=0.0, z=1.0)]
    rgb = _packed(np.array([255, 0, 9]), np.array([0, 0, 9]), np.array([0, 255, 9]))
    colour = ChannelFloat32(name="rgb")
    colour.values.frombytes(rgb.astype("<u4").view("<f4").tobytes())
    msg.channels = [colour, ChannelFloat32(name="intensity", values=[1.0, 2.0, 3.0])]
    enc = codec.encode(msg)
    np.testing.assert_allclose(enc.body.points, [[100, 200, 300], [-500, 0, 1000]], rtol=1e-6)
    attrs = {a.name: a for a in enc.body.attributes}
    np.testing.assert_array_equal(attrs["intensity"].data[:, 0], [1.0, 3.0])
    np.testing.assert_allclose(attrs["RGBA"].data[1], [9 / 255, 9 / 255, 9 / 255, 1.0])
    back = codec.from_igtl(_wire(enc.body), frame_id="sonar")
    assert len(back.points) == 2 and back.points[1].x == pytest.approx(-0.5)
    assert [c.name for c in back.channels] == ["rgb", "intensity"]
    assert np.frombuffer(back.channels[0].values, "<u4")[1] & 0xFFFFFF == 0x090909
    bad = PointCloud(points=[Point32()], channels=[ChannelFloat32(name="i", values=[1.0, 2.0])])
    with pytest.raises(CodecError) as err:
        codec.to_igtl(bad)
    assert err.value.field == "channels[0].values"


def test_values_in_mm() -> None:
    codec = codec_for("PointCloud2")
    msg = _cloud(np.array([[0.001, 0.0, -0.002]], np.float32),
                 rgb=_packed(np.array([1]), np.array([2]), np.array([3])))
    value = codec.to_value(msg)
    assert value["points"] == [[pytest.approx(1.0), 0.0, pytest.approx(-2.0)]]
    assert value["rgba"] == [[1, 2, 3, 255]]
    back = codec.from_value(value)
    assert back.width == 1 and back.fields[3].name == "rgb"
    plain = codec.from_value([[1000.0, 0.0, 0.0]])
    assert np.frombuffer(plain.data, "<f4").tolist() == [1.0, 0.0, 0.0]
    for value, field in (([[1.0, 2.0]], "value.points"),
                         ({"points": [[0, 0, 0]], "rgba": [[0, 0, 0]]}, "value.rgba"),
                         ({"points": [[0, 0, float("nan")]]}, "value.points[0]")):
        with pytest.raises(CodecError) as err:
            codec.from_value(value)
        assert err.value.field == field


def test_rgba_attribute_from_slicer_clamped() -> None:
    body = PolyData(points=np.zeros((2, 3), np.float32),
                    attributes=[PolyDataAttribute("Colors", AttributeKind.RGBA,
                                                  np.array([[1.5, 0.5, -1, 1], [0, 0, 1, 0.5]],
                                                           np.float32))])
    cloud = codec_for("PointCloud2").from_igtl(body)
    assert cloud.fields[3].name == "rgba"
    packed = np.frombuffer(cloud.data, "<u4").reshape(2, 4)[:, 3]
    assert [hex(int(v)) for v in packed] == ["0xffff8000", "0x800000ff"]


def test_colours_as_sent_today_and_before_both_become_the_rgb_field() -> None:
    """Colours come as the daemon sends them now (the point SCALAR "RGBA" of 4 components)
    or as clients built before sent them (TYPE RGBA): the same packed field either way. A
    4-component SCALAR of another name is not a colour, nor a 1-component "RGBA"."""
    colours = np.array([[1.0, 0.5, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0]], np.float32)
    packed = []
    for kind in (AttributeKind.SCALAR, AttributeKind.RGBA):
        body = PolyData(points=np.zeros((2, 3), np.float32),
                        attributes=[PolyDataAttribute(RGBA_ATTRIBUTE, kind, colours)])
        cloud = codec_for("PointCloud2").from_igtl(PolyData.unpack(body.pack()))
        assert [f.name for f in cloud.fields] == ["x", "y", "z", "rgb"]
        packed.append(np.frombuffer(cloud.data, "<u4").reshape(2, 4)[:, 3].tolist())
    assert packed[0] == packed[1] == [0xFFFF8000, 0xFF0000FF]
    other = PolyData(points=np.zeros((2, 3), np.float32),
                     attributes=[PolyDataAttribute("weights", AttributeKind.SCALAR, colours),
                                 PolyDataAttribute(RGBA_ATTRIBUTE, AttributeKind.SCALAR,
                                                   np.ones((2, 1), np.float32))])
    cloud = codec_for("PointCloud2").from_igtl(other)
    assert [f.name for f in cloud.fields] == ["x", "y", "z"]
