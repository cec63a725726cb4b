"""sensor_msgs PointCloud2 / PointCloud <-> OpenIGTLink POLYDATA (and POINT on the way in).

ROS -> Slicer: points in mm (float32), one polyvertex cell of all the points (what every
reader takes, `protocol.polydata`), the point colours (0..1, the 4-component SCALAR "RGBA")
if the cloud has a packed ``rgb``/``rgba`` field, and every other single-valued numeric
field (``intensity`` ...) as a SCALAR point attribute. Points with a NaN/inf coordinate
(the usual "no return" marker), or one beyond float32 once in mm (`fit_float32_mm`: 1e36
m), are dropped, along with their attributes. Everything is numpy over the raw buffer:
``np.frombuffer`` with a structured dtype built from the fields' offsets, ``point_step``
and byte order; ``row_step`` padding is cut with one strided copy. No Python loop per point
(PointCloud v1 stores one Python object per point, so gathering those is the one
unavoidable loop). Where x, y and z are float32 (depth cameras, lidars), the POLYDATA's
points are made in float32 straight (`float32_metres_to_mm`: the same numbers as through
float64), each column read once from the buffer; rows are judged column by column and
gathered with ``take`` (numpy's ``all(axis=1)`` and boolean row indexing took 8 of the 19
ms a VGA cloud cost).

Slicer -> ROS: POLYDATA points (or POINT elements) become a PointCloud2 with float32 x, y, z
in metres, a packed float32 ``rgb`` field if a colour point attribute (TYPE RGBA, or the
SCALAR "RGBA" of 4 components; or POINT colours) is present (named ``rgba`` when some
alpha is not opaque), and 1-component SCALAR point attributes as float32 fields. height 1,
dense, little-endian.

Packed colour: the 4 bytes of the float32 field read as uint32 0xAARRGGBB (PCL's layout).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from bridge.codecs.base import KEY_SHAPE, Body, Encoded, TypeCodec
from bridge.codecs.cdr import CdrError, read_point_cloud2
from bridge.codecs.errors import CodecError
from bridge.codecs.generic import numeric_array
from protocol.conversions import (fit_float32_mm, float32_metres_to_mm, metres_to_mm,
                                  mm_to_metres)
from protocol.messages import AttributeKind, Point, PolyData, PolyDataAttribute
from protocol.polydata import (RGBA_ATTRIBUTE, colour_attribute, point_attribute, point_colours,
                               vertex_cell)
from protocol.naming import KEY_DROPPED, KEY_UNITS, UNITS_MM

__all__ = [
    "KEY_DROPPED",
    "CloudArrays",
    "PointCloud2Codec",
    "PointCloudCodec",
    "arrays_to_cloud2",
    "cloud2_arrays",
    "cloud2_polydata",
]

# sensor_msgs/PointField datatypes -> numpy base types.
_POINTFIELD_DTYPES: dict[int, str] = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4",
                                      7: "f4", 8: "f8"}
_FLOAT32, _UINT32 = 7, 6
_COLOUR_NAMES = ("rgb", "rgba")


@dataclass(frozen=True)
class CloudArrays:
    """A cloud in numpy form: xyz in metres (N, 3) float64, colours (N, 4) uint8 or None,
    scalar fields name -> (N,) arrays."""

    xyz_m: np.ndarray
    rgba: np.ndarray | None
    scalars: dict[str, np.ndarray]
    dropped: int = 0


# --------------------------------------------------------------------------- PointCloud2 in

def _struct_dtype(msg: Any) -> tuple[np.dtype, str | None, list[str]]:
    order = ">" if msg.is_bigendian else "<"
    step = int(msg.point_step)
    names: list[str] = []
    formats: list[str] = []
    offsets: list[int] = []
    colour: str | None = None
    scalars: list[str] = []
    for i, f in enumerate(msg.fields):
        base = _POINTFIELD_DTYPES.get(int(f.datatype))
        if base is None:
            raise CodecError(field=f"fields[{i}].datatype", expected="1..8 (PointField types)",
                             got=int(f.datatype))
        size = np.dtype(base).itemsize * max(int(f.count), 1)
        if int(f.offset) + size > step:
            raise CodecError(field=f"fields[{i}].offset", expected=f"a field ending within "
                             f"point_step {step}", got=f"offset {f.offset} + {size} bytes")
        name = f.name
        if name in names:
            continue  # a duplicated name: the first one wins
        if name in ("x", "y", "z"):
            if base not in ("f4", "f8") or int(f.count) != 1:
                raise CodecError(field=f"fields[{i}]", expected=f"{name} as one FLOAT32 or "
                                 "FLOAT64", got=f"datatype {f.datatype}, count {f.count}")
        elif name in _COLOUR_NAMES and colour is None:
            if int(f.datatype) not in (_FLOAT32, _UINT32) or int(f.count) != 1:
                continue  # an unusual colour layout: left out rather than misread
            colour, base = name, "u4"  # the float's bytes are the packed colour
        elif int(f.count) == 1 and name and name not in _COLOUR_NAMES:
            scalars.append(name)
        else:
            continue
        names.append(name)
        formats.append(order + base)
        offsets.append(int(f.offset))
    missing = [n for n in ("x", "y", "z") if n not in names]
    if missing:
        raise CodecError(field="fields", expected="x, y and z fields",
                         got="no " + ", ".join(missing))
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": step})
    return dtype, colour, scalars


def _unpack_colour(packed: np.ndarray, with_alpha: bool) -> np.ndarray:
    u = packed.astype(np.uint32, copy=False)
    rgba = np.empty((u.size, 4), dtype=np.uint8)
    rgba[:, 0] = (u >> 16) & 0xFF
    rgba[:, 1] = (u >> 8) & 0xFF
    rgba[:, 2] = u & 0xFF
    rgba[:, 3] = (u >> 24) & 0xFF if with_alpha else 0xFF
    return rgba


def _cloud2_table(msg: Any) -> tuple[np.ndarray, str | None, list[str]]:
    """A checked PointCloud2's points as one structured array over its buffer (row padding
    cut), the colour field's name (None: no colour) and the scalar fields' names."""
    h, w = int(msg.height), int(msg.width)
    step, row_step = int(msg.point_step), int(msg.row_step)
    n = h * w
    if n and step <= 0:
        raise CodecError(field="point_step", expected="> 0", got=step)
    if n and row_step < w * step:
        raise CodecError(field="row_step", expected=f">= width * point_step = {w * step}",
                         got=row_step)
    if len(msg.data) != h * row_step:
        raise CodecError(field="data", expected=f"{h * row_step} bytes (height * row_step = "
                         f"{h} * {row_step})", got=f"{len(msg.data)} bytes")
    dtype, colour, scalar_names = _struct_dtype(msg)
    if n == 0:
        return np.zeros(0, dtype=dtype), colour, scalar_names
    if row_step == w * step:
        return np.frombuffer(msg.data, dtype=dtype, count=n), colour, scalar_names
    # cut the padding at the end of each row: one strided copy
    raw = np.frombuffer(msg.data, dtype=np.uint8).reshape(h, row_step)[:, :w * step]
    return np.ascontiguousarray(raw).view(dtype).reshape(n), colour, scalar_names


def _kept_rows(ok: np.ndarray) -> np.ndarray | None:
    """The indices of the rows of an (N, 3) boolean array that are all True; None when
    every row is (nothing to gather). Column by column: ``all(axis=1)`` is ten times
    slower on three columns."""
    keep = ok[:, 0] & ok[:, 1] & ok[:, 2]
    return None if bool(keep.all()) else np.flatnonzero(keep)


def _kept(values: np.ndarray, kept: np.ndarray | None) -> np.ndarray:
    return values if kept is None else values.take(kept, axis=0)


def _point_data(table: np.ndarray, colour: str | None, scalar_names: list[str],
                kept: np.ndarray | None) -> tuple[np.ndarray | None, dict[str, np.ndarray]]:
    """The kept points' colours ((N, 4) uint8) and scalar fields (float32)."""
    rgba = None if colour is None else _unpack_colour(_kept(table[colour], kept),
                                                      colour == "rgba")
    scalars = {s: _kept(table[s], kept).astype(np.float32) for s in scalar_names}
    return rgba, scalars


def cloud2_arrays(msg: Any) -> CloudArrays:
    """A PointCloud2's points that are finite as float32 in mm (kept in metres), colours and
    scalar fields, vectorised."""
    table, colour, scalar_names = _cloud2_table(msg)
    n = table.size
    if n == 0:
        return CloudArrays(np.zeros((0, 3)), None if colour is None else
                           np.zeros((0, 4), np.uint8), {s: np.zeros(0) for s in scalar_names})
    xyz = np.empty((n, 3), dtype=np.float64)
    xyz[:, 0], xyz[:, 1], xyz[:, 2] = table["x"], table["y"], table["z"]
    kept = _kept_rows(fit_float32_mm(xyz))  # NaN, inf, or beyond float32 in mm
    rgba, scalars = _point_data(table, colour, scalar_names, kept)
    return CloudArrays(_kept(xyz, kept), rgba, scalars, 0 if kept is None else n - kept.size)


def cloud2_polydata(msg: Any) -> tuple[PolyData, int]:
    """``arrays_to_polydata(cloud2_arrays(msg))`` and the number of points dropped, made
    without float64 where x, y and z are float32 (the same POLYDATA)."""
    table, colour, scalar_names = _cloud2_table(msg)
    n = table.size
    fields: Any = table.dtype.fields or {}
    if n == 0 or any(fields[c][0].kind != "f" or fields[c][0].itemsize != 4 for c in "xyz"):
        cloud = cloud2_arrays(msg)
        return arrays_to_polydata(cloud), cloud.dropped
    mm = np.empty((n, 3), dtype=np.float32)
    for i, c in enumerate("xyz"):
        float32_metres_to_mm(table[c], out=mm[:, i])
    kept = _kept_rows(np.isfinite(mm))  # inf: beyond float32 in mm (`fit_float32_mm`)
    rgba, scalars = _point_data(table, colour, scalar_names, kept)
    return _polydata(_kept(mm, kept), rgba, scalars), 0 if kept is None else n - kept.size


# --------------------------------------------------------------------------- PointCloud (v1)

def cloud1_arrays(msg: Any) -> CloudArrays:
    """A sensor_msgs/PointCloud's points finite as float32 in mm, colour channel
    ("rgb"/"rgba", packed float) and other channels as scalars."""
    n = len(msg.points)
    # The one unavoidable loop: PointCloud keeps a Python Point32 per point.
    xyz = np.array([(p.x, p.y, p.z) for p in msg.points], dtype=np.float64).reshape(n, 3)
    keep = fit_float32_mm(xyz).all(axis=1)  # NaN, inf, or beyond float32 in mm
    dropped = int(n - np.count_nonzero(keep))
    rgba = None
    scalars: dict[str, np.ndarray] = {}
    for i, ch in enumerate(msg.channels):
        values = np.frombuffer(ch.values, dtype=np.float32) if len(ch.values) else \
            np.zeros(0, np.float32)
        if values.size != n:
            raise CodecError(field=f"channels[{i}].values", expected=f"{n} values (one per "
                             "point)", got=f"{values.size} values")
        if ch.name in _COLOUR_NAMES and rgba is None:
            rgba = _unpack_colour(values.view(np.uint32)[keep], ch.name == "rgba")
        elif ch.name and ch.name not in scalars:
            scalars[ch.name] = values[keep].copy()
    return CloudArrays(xyz[keep], rgba, scalars, dropped)


# --------------------------------------------------------------------------- POLYDATA

def arrays_to_polydata(cloud: CloudArrays) -> PolyData:
    return _polydata(metres_to_mm(cloud.xyz_m).astype(np.float32), cloud.rgba, cloud.scalars)


def _polydata(points_mm: np.ndarray, rgba: np.ndarray | None,
              scalars: dict[str, np.ndarray]) -> PolyData:
    """The POLYDATA of points ((N, 3) float32, mm), their colours ((N, 4) uint8) and
    scalar fields."""
    n = points_mm.shape[0]
    attributes: list[PolyDataAttribute] = []
    if rgba is not None:
        attributes.append(colour_attribute(rgba.astype(np.float32) / np.float32(255.0)))
    for name, values in scalars.items():
        if name != RGBA_ATTRIBUTE:
            attributes.append(point_attribute(name, AttributeKind.SCALAR,
                                              values.astype(np.float32).reshape(n, 1)))
    return PolyData(points=points_mm, vertices=vertex_cell(n), attributes=attributes)


def polydata_arrays(body: PolyData) -> CloudArrays:
    """Points (mm -> m), the point colours (`protocol.polydata.point_colours`: TYPE RGBA or
    the SCALAR "RGBA") and the other 1-component SCALAR point attributes of a POLYDATA."""
    points = np.asarray(body.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise CodecError(field="points", expected="shape (N, 3)", got=f"shape {points.shape}")
    _check_finite(points, "points")
    n = points.shape[0]
    colours = point_colours(body.attributes, n)
    rgba = None if colours is None else \
        np.round(np.clip(np.nan_to_num(colours), 0.0, 1.0) * 255.0).astype(np.uint8)
    scalars: dict[str, np.ndarray] = {}
    for attr in body.attributes:
        data = np.asarray(attr.data, dtype=np.float32)
        if attr.on_cells or data.shape[0] != n:
            continue  # cell data has no place in a point cloud
        if attr.kind == AttributeKind.SCALAR and data.size == n and attr.name not in (
                "x", "y", "z", RGBA_ATTRIBUTE, *_COLOUR_NAMES) and attr.name not in scalars:
            scalars[attr.name] = data.reshape(n)
    return CloudArrays(mm_to_metres(points), rgba, scalars)


def point_arrays(body: Point) -> CloudArrays:
    """POINT elements' positions (mm -> m) and colours."""
    n = len(body.points)
    if n == 0:
        return CloudArrays(np.zeros((0, 3)), None, {})
    positions = numeric_array([list(np.asarray(p.position, dtype=np.float64))
                               for p in body.points], "points", "double", ndim=2)
    if positions.shape[1] != 3:
        raise CodecError(field="points.position", expected="3 numbers per point",
                         got=f"shape {positions.shape}")
    _check_finite(positions, "points")
    rgba = numeric_array([list(p.rgba) for p in body.points], "points.rgba", "uint8", ndim=2)
    return CloudArrays(mm_to_metres(positions), rgba.astype(np.uint8), {})


def _check_finite(points: np.ndarray, field: str) -> None:
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if bad.size:
        i = int(bad[0])
        raise CodecError(field=f"{field}[{i}]", expected="finite coordinates",
                         got=repr(points[i].tolist()))


# --------------------------------------------------------------------------- PointCloud2 out

def arrays_to_cloud2(cloud: CloudArrays) -> Any:
    """A dense, little-endian, height-1 PointCloud2: float32 x, y, z (m), packed rgb/rgba,
    float32 scalar fields."""
    from sensor_msgs.msg import PointCloud2, PointField

    n = cloud.xyz_m.shape[0]
    names = ["x", "y", "z"]
    formats = ["<f4", "<f4", "<f4"]
    colour_name = None
    if cloud.rgba is not None:
        colour_name = "rgb" if bool(np.all(cloud.rgba[:, 3] == 255)) else "rgba"
        names.append(colour_name)
        formats.append("<u4")
    scalar_names = [s for s in cloud.scalars if s not in names]
    names += scalar_names
    formats += ["<f4"] * len(scalar_names)
    dtype = np.dtype({"names": names, "formats": formats})
    table = np.empty(n, dtype=dtype)
    table["x"], table["y"], table["z"] = (cloud.xyz_m[:, 0], cloud.xyz_m[:, 1],
                                          cloud.xyz_m[:, 2])
    if colour_name is not None and cloud.rgba is not None:
        c = cloud.rgba.astype(np.uint32)
        table[colour_name] = (c[:, 3] << 24) | (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
    for s in scalar_names:
        table[s] = cloud.scalars[s]
    msg = PointCloud2(height=1, width=n, is_bigendian=False, point_step=dtype.itemsize,
                      row_step=dtype.itemsize * n, is_dense=True)
    offsets = {name: int(spec[1]) for name, spec in (dtype.fields or {}).items()}
    msg.fields = [PointField(name=name, offset=offsets[name], datatype=PointField.FLOAT32,
                             count=1) for name in names]
    msg.data.frombytes(table.tobytes())  # one memcpy into the array.array
    return msg


def arrays_to_cloud1(cloud: CloudArrays) -> Any:
    from geometry_msgs.msg import Point32
    from sensor_msgs.msg import ChannelFloat32, PointCloud

    msg = PointCloud()
    msg.points = [Point32(x=x, y=y, z=z) for x, y, z in cloud.xyz_m.astype(np.float32).tolist()]
    channels = []
    if cloud.rgba is not None:
        c = cloud.rgba.astype(np.uint32)
        packed = ((c[:, 3] << 24) | (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]).astype("<u4")
        name = "rgb" if bool(np.all(cloud.rgba[:, 3] == 255)) else "rgba"
        ch = ChannelFloat32(name=name)
        ch.values.frombytes(packed.view("<f4").tobytes())
        channels.append(ch)
    for s, values in cloud.scalars.items():
        ch = ChannelFloat32(name=s)
        ch.values.frombytes(values.astype("=f4").tobytes())
        channels.append(ch)
    msg.channels = channels
    return msg


# --------------------------------------------------------------------------- values

def _cloud_value(cloud: CloudArrays) -> dict[str, Any]:
    value: dict[str, Any] = {"points": metres_to_mm(cloud.xyz_m).tolist()}
    if cloud.rgba is not None:
        value["rgba"] = cloud.rgba.tolist()
    return value


def _value_cloud(value: Any) -> CloudArrays:
    if isinstance(value, list):
        value = {"points": value}
    if not isinstance(value, dict):
        raise CodecError(field="value", expected="an object with points (mm) and optional "
                         "rgba, or a list of points", got=type(value).__name__)
    unknown = sorted(set(value) - {"points", "rgba"})
    if unknown:
        raise CodecError(field=f"value.{unknown[0]}", expected="points or rgba",
                         got="an unknown key")
    pts = numeric_array(value.get("points", []), "value.points", "double", ndim=2)
    if pts.shape[1:] != (3,):
        raise CodecError(field="value.points", expected="N x 3 numbers (mm)",
                         got=f"shape {pts.shape}")
    _check_finite(pts, "value.points")
    rgba = None
    if value.get("rgba") is not None:
        rgba = numeric_array(value["rgba"], "value.rgba", "uint8", ndim=2)
        if rgba.shape != (pts.shape[0], 4):
            raise CodecError(field="value.rgba", expected=f"{pts.shape[0]} x 4 integers "
                             "0..255", got=f"shape {rgba.shape}")
    return CloudArrays(mm_to_metres(pts), rgba, {})


def _body_cloud(body: Body, ros_type: str) -> CloudArrays:
    if isinstance(body, PolyData):
        return polydata_arrays(body)
    if isinstance(body, Point):
        return point_arrays(body)
    raise CodecError(field="body", expected=f"an OpenIGTLink POLYDATA or POINT (for "
                     f"{ros_type})", got=type(body).__name__)


def _meta(npoints: int, dropped: int) -> dict[str, str]:
    meta = {KEY_UNITS: UNITS_MM, KEY_SHAPE: str(npoints)}
    if dropped:
        meta[KEY_DROPPED] = str(dropped)
    return meta


@dataclass(frozen=True)
class PointCloud2Codec(TypeCodec):
    """PointCloud2 <-> POLYDATA (mm, one polyvertex cell, colour and SCALAR attributes);
    POINT is accepted on the way back. Value: ``{"points": [[x, y, z] mm...],
    "rgba": [[r, g, b, a] 0..255...]}`` (rgba only if coloured)."""

    bulk: ClassVar[bool] = True

    def encode_serialized(self, data: bytes) -> Encoded | None:
        """The points are read where they lie in the serialized message (rclpy's
        deserialization would copy the 5 MB of a VGA cloud, and build the message)."""
        try:
            raw = read_point_cloud2(data)
        except CdrError:
            return None
        return self._encode_checked(raw)

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        body, dropped = cloud2_polydata(msg)
        return body, _meta(body.points.shape[0], dropped)

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        return arrays_to_cloud2(_body_cloud(body, self.ros_type))

    def _to_value(self, msg: Any) -> Any:
        return _cloud_value(cloud2_arrays(msg))

    def _from_value(self, value: Any) -> Any:
        return arrays_to_cloud2(_value_cloud(value))


@dataclass(frozen=True)
class PointCloudCodec(TypeCodec):
    """sensor_msgs/PointCloud (v1) <-> POLYDATA, as PointCloud2; colour in a packed ``rgb``
    channel, other channels as SCALAR attributes."""

    bulk: ClassVar[bool] = True

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        cloud = cloud1_arrays(msg)
        return arrays_to_polydata(cloud), _meta(cloud.xyz_m.shape[0], cloud.dropped)

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        return arrays_to_cloud1(_body_cloud(body, self.ros_type))

    def _to_value(self, msg: Any) -> Any:
        return _cloud_value(cloud1_arrays(msg))

    def _from_value(self, value: Any) -> Any:
        return arrays_to_cloud1(_value_cloud(value))
