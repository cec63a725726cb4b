"""sensor_msgs/Image <-> OpenIGTLink IMAGE, vectorised (one numpy view, at most one copy).

Row order (why no pixel flip is needed): a ROS image stores row 0 at the TOP, column 0 at
the LEFT. OpenIGTLinkIO (3D Slicer) takes the IMAGE matrix as IJK-to-RAS and ignores the
header's RAS/LPS flag, so the codec sends the rows as they are and puts the flip in the
geometry: i (columns) runs along -R and j (rows) along -A, k along +S. Slicer's Red (axial)
view shows R on the left and A at the top, so screen-right is -R and screen-down is -A: the
picture appears upright and not mirrored there, with no pixel copy. Spacing is 1 mm per
pixel (sensor_msgs/Image carries no pixel size), the first pixel's centre at the origin.

Encodings: mono8, 8UC1, rgb8, rgba8, bgr8, bgra8, 8UC3, 8UC4, mono16, 16UC1, 16SC1, 32SC1,
32FC1, 64FC1, rgb16, rgba16, bgr16, bgra16. Blue-first encodings are reordered to RGB(A)
(Slicer shows vector volumes as RGB). ``step`` padding and ``is_bigendian`` are honoured;
a data size other than ``height * step`` is a `CodecError`.

Back (from Slicer): slice 0 of a one-slice IMAGE becomes the ROS image, rows in buffer
order. The encoding follows the pixel type (uint8 x1/x3/x4 -> mono8/rgb8/rgba8, uint16 x1 ->
mono16, float32 x1 -> 32FC1 ...) unless metadata ``ros2.encoding`` names a compatible one
(so a bgr8 image sent by the bridge comes back as bgr8, byte for byte).
"""

from __future__ import annotations

import base64
import binascii
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from bridge.codecs.base import KEY_ENCODING, Body, Encoded, TypeCodec
from bridge.codecs.cdr import CdrError, read_image
from bridge.codecs.errors import CodecError
from bridge.codecs.generic import numeric_array
from protocol.messages import Image
from protocol.naming import KEY_UNITS, UNITS_MM

__all__ = ["ENCODINGS", "SLICER_DIRECTIONS", "ImageCodec", "image_pixels"]


@dataclass(frozen=True)
class _Encoding:
    dtype: str  # numpy base type, no byte order ("u1", "f4")
    channels: int
    swap_rb: bool = False  # blue first: reorder to red first for Slicer


ENCODINGS: dict[str, _Encoding] = {
    "mono8": _Encoding("u1", 1), "8UC1": _Encoding("u1", 1),
    "rgb8": _Encoding("u1", 3), "rgba8": _Encoding("u1", 4),
    "bgr8": _Encoding("u1", 3, True), "bgra8": _Encoding("u1", 4, True),
    "8UC3": _Encoding("u1", 3), "8UC4": _Encoding("u1", 4),
    "mono16": _Encoding("u2", 1), "16UC1": _Encoding("u2", 1), "16SC1": _Encoding("i2", 1),
    "32SC1": _Encoding("i4", 1), "32FC1": _Encoding("f4", 1), "64FC1": _Encoding("f8", 1),
    "rgb16": _Encoding("u2", 3), "rgba16": _Encoding("u2", 4),
    "bgr16": _Encoding("u2", 3, True), "bgra16": _Encoding("u2", 4, True),
}
# The encoding a Slicer image gets when no metadata says otherwise: (dtype, channels).
_DEFAULT_FOR: dict[tuple[str, int], str] = {
    ("u1", 1): "mono8", ("u1", 3): "rgb8", ("u1", 4): "rgba8",
    ("u2", 1): "mono16", ("i2", 1): "16SC1", ("i4", 1): "32SC1",
    ("f4", 1): "32FC1", ("f8", 1): "64FC1", ("u2", 3): "rgb16", ("u2", 4): "rgba16",
}
# What a blue-first encoding looks like once its channels are reordered.
_RGB_OF = {"bgr8": "rgb8", "bgra8": "rgba8", "bgr16": "rgb16", "bgra16": "rgba16"}

# i along -R, j along -A, k along +S (columns = axis directions in RAS): see module doc.
SLICER_DIRECTIONS = np.diag([-1.0, -1.0, 1.0])


def _swap_rb(pixels: np.ndarray) -> np.ndarray:
    order = [2, 1, 0] + ([3] if pixels.shape[-1] == 4 else [])
    return pixels[..., order]


def _encoding(name: str, field: str) -> _Encoding:
    enc = ENCODINGS.get(name)
    if enc is None:
        raise CodecError(field=field, expected="one of " + ", ".join(ENCODINGS),
                         got=repr(name))
    return enc


def image_pixels(msg: Any) -> tuple[np.ndarray, str]:
    """(height, width, channels) native-endian pixels of a sensor_msgs/Image, red first,
    and the encoding they now have. A view on ``msg.data`` when no copy is needed."""
    enc = _encoding(msg.encoding, "encoding")
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    if h < 1 or w < 1:
        raise CodecError(field="height" if h < 1 else "width", expected="at least 1 pixel",
                         got=f"{h}x{w}")
    dtype = np.dtype(enc.dtype).newbyteorder(">" if msg.is_bigendian else "<")
    row_bytes = w * enc.channels * dtype.itemsize
    if step < row_bytes:
        raise CodecError(field="step", expected=f"at least {row_bytes} bytes (width * "
                         f"{enc.channels * dtype.itemsize} bytes per {msg.encoding} pixel)",
                         got=step)
    if len(msg.data) != h * step:
        raise CodecError(field="data", expected=f"{h * step} bytes (height * step = {h} * "
                         f"{step})", got=f"{len(msg.data)} bytes")
    raw = np.frombuffer(msg.data, dtype=np.uint8).reshape(h, step)
    if step != row_bytes:
        raw = np.ascontiguousarray(raw[:, :row_bytes])  # drop the row padding: one copy
    pixels = raw.view(dtype).reshape(h, w, enc.channels)
    if not dtype.isnative:
        pixels = pixels.astype(dtype.newbyteorder("="))
    name = msg.encoding
    if enc.swap_rb:
        pixels, name = _swap_rb(pixels), _RGB_OF[name]
    return pixels, name


def _message(pixels: np.ndarray, encoding: str) -> Any:
    """A sensor_msgs/Image from (h, w, c) pixels already in ``encoding``'s channel order."""
    from sensor_msgs.msg import Image as RosImage

    h, w, c = pixels.shape
    data = np.ascontiguousarray(pixels, dtype=pixels.dtype.newbyteorder("<"))
    msg = RosImage(height=h, width=w, encoding=encoding, is_bigendian=0,
                   step=w * c * data.dtype.itemsize)
    msg.data.frombytes(data.tobytes())  # array.array from bytes: one memcpy, no Python loop
    return msg


def _choose_encoding(dtype: np.dtype, channels: int, wanted: str | None, field: str) -> str:
    base = dtype.str[1:]
    if wanted:
        enc = _encoding(wanted, field)
        if (enc.dtype, enc.channels) == (base, channels):
            return wanted
    name = _DEFAULT_FOR.get((base, channels))
    if name is None:
        raise CodecError(field="pixels", expected="uint8 with 1, 3 or 4 components, or one "
                         "component of uint16, int16, int32, float32, float64",
                         got=f"{dtype.name} with {channels} components")
    return name


def _from_pixels(pixels: np.ndarray, wanted: str | None, field: str) -> Any:
    _h, _w, c = pixels.shape
    encoding = _choose_encoding(pixels.dtype, c, wanted, field)
    if ENCODINGS[encoding].swap_rb:
        pixels = _swap_rb(pixels)  # Slicer holds red first
    return _message(pixels, encoding)


@dataclass(frozen=True)
class ImageCodec(TypeCodec):
    """sensor_msgs/Image <-> IMAGE (one slice, 1 mm pixels, upright in Slicer's Red view)."""

    bulk: ClassVar[bool] = True

    def encode_serialized(self, data: bytes) -> Encoded | None:
        """The pixels are read where they lie in the serialized message: the one copy left
        is into the frame that is sent."""
        try:
            raw = read_image(data)
        except CdrError:
            return None
        return self._encode_checked(raw)

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        pixels, _ = image_pixels(msg)
        body = Image(pixels=pixels[np.newaxis], spacing=np.ones(3),
                     directions=SLICER_DIRECTIONS.copy(), origin=np.zeros(3), coordinate="RAS")
        return body, {KEY_ENCODING: msg.encoding, KEY_UNITS: UNITS_MM}

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        if not isinstance(body, Image):
            raise CodecError(field="body", expected="an OpenIGTLink IMAGE (for "
                             f"{self.ros_type})", got=type(body).__name__)
        pixels = np.asarray(body.pixels)
        if pixels.ndim != 4:
            raise CodecError(field="pixels", expected="4 dimensions (slices, rows, columns, "
                             "components)", got=f"shape {pixels.shape}")
        if pixels.shape[0] != 1:
            raise CodecError(field="pixels", expected="one slice (sensor_msgs/Image is 2-D)",
                             got=f"{pixels.shape[0]} slices")
        if not pixels.dtype.isnative:
            pixels = pixels.astype(pixels.dtype.newbyteorder("="))
        return _from_pixels(pixels[0], metadata.get(KEY_ENCODING), f"metadata.{KEY_ENCODING}")

    def _to_value(self, msg: Any) -> Any:
        pixels, encoding = image_pixels(msg)
        nested = pixels[..., 0] if pixels.shape[-1] == 1 else pixels
        return {"encoding": encoding, "height": int(msg.height), "width": int(msg.width),
                "pixels": nested.tolist()}

    def _from_value(self, value: Any) -> Any:
        if not isinstance(value, dict):
            raise CodecError(field="value", expected="an object with encoding and pixels (or "
                             "height, width and base64 data)", got=type(value).__name__)
        unknown = sorted(set(value) - {"encoding", "height", "width", "pixels", "data"})
        if unknown:
            raise CodecError(field=f"value.{unknown[0]}",
                             expected="encoding, height, width, pixels or data",
                             got="an unknown key")
        encoding = value.get("encoding")
        if encoding is not None and not isinstance(encoding, str):
            raise CodecError(field="value.encoding", expected="a string",
                             got=type(encoding).__name__)
        if "data" in value:
            return self._from_data(value, encoding)
        if "pixels" not in value:
            raise CodecError(field="value.pixels", expected="rows of pixels", got="nothing")
        if encoding is not None:
            enc = _encoding(encoding, "value.encoding")
            base = {"u1": "uint8", "u2": "uint16", "i2": "int16", "i4": "int32",
                    "f4": "float", "f8": "double"}[enc.dtype]
            arr = numeric_array(value["pixels"], "value.pixels", base, ndim=None)
            if arr.ndim == 2 and enc.channels == 1:
                arr = arr[..., np.newaxis]
            if arr.ndim != 3 or arr.shape[2] != enc.channels or 0 in arr.shape:
                raise CodecError(field="value.pixels", expected=f"rows x columns x "
                                 f"{enc.channels} values for {encoding}",
                                 got=f"shape {arr.shape}")
            return _message(arr, encoding)
        arr = numeric_array(value["pixels"], "value.pixels", "double", ndim=None)
        if arr.ndim == 2:
            arr = arr[..., np.newaxis]
        if arr.ndim != 3 or 0 in arr.shape:
            raise CodecError(field="value.pixels", expected="rows x columns (x components)",
                             got=f"shape {arr.shape}")
        # No encoding given: integers 0..255 are 8-bit, anything else one-channel 32FC1.
        if np.all(arr == np.round(arr)) and arr.min() >= 0 and arr.max() <= 255:
            return _from_pixels(arr.astype(np.uint8), None, "value.encoding")
        return _from_pixels(arr.astype(np.float32), None, "value.encoding")

    def _from_data(self, value: dict[str, Any], encoding: str | None) -> Any:
        from bridge.codecs.generic import check_int

        if encoding is None:
            raise CodecError(field="value.encoding", expected="an encoding with data",
                             got="nothing")
        enc = _encoding(encoding, "value.encoding")
        h = check_int(value.get("height"), "value.height", "uint32")
        w = check_int(value.get("width"), "value.width", "uint32")
        data = value["data"]
        try:
            raw = base64.b64decode(data, validate=True) if isinstance(data, str) else None
        except (binascii.Error, ValueError):
            raw = None
        if raw is None:
            raise CodecError(field="value.data", expected="base64 text", got=type(data).__name__)
        itemsize = np.dtype(enc.dtype).itemsize
        need = h * w * enc.channels * itemsize
        if len(raw) != need or h == 0 or w == 0:
            raise CodecError(field="value.data", expected=f"{need} bytes (height {h} x width "
                             f"{w} x {enc.channels * itemsize} bytes per pixel)",
                             got=f"{len(raw)} bytes")
        pixels = np.frombuffer(raw, dtype=np.dtype(enc.dtype).newbyteorder("<"))
        return _message(pixels.reshape(h, w, enc.channels), encoding)
