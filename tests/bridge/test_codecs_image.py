"""sensor_msgs/Image <-> IMAGE: every encoding pixel-exact, padded step, byte order, errors."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sensor_msgs.msg import Image as RosImage

from bridge.codecs import CodecError, codec_for
from bridge.codecs.image import SLICER_DIRECTIONS
from protocol.messages import Image, String, unpack_body

H, W = 5, 7
RNG = np.random.default_rng(1234)


def _wire(body: Any) -> Any:
    return unpack_body(body.TYPE, body.pack())


def _ros_image(encoding: str, pixels: np.ndarray, pad: int = 0,
               big_endian: bool = False) -> RosImage:
    """A ROS image with `pad` bytes of padding at the end of each row."""
    h, w = pixels.shape[:2]
    dtype = pixels.dtype.newbyteorder(">" if big_endian else "<")
    rows = np.ascontiguousarray(pixels, dtype=dtype).reshape(h, -1).view(np.uint8)
    padded = np.zeros((h, rows.shape[1] + pad), dtype=np.uint8)
    padded[:, :rows.shape[1]] = rows
    padded[:, rows.shape[1]:] = 0xAB  # garbage in the padding must not leak
    msg = RosImage(height=h, width=w, encoding=encoding, is_bigendian=int(big_endian),
                   step=padded.shape[1])
    msg.data.frombytes(padded.tobytes())
    return msg


def _pixels(dtype: str, channels: int) -> np.ndarray:
    if np.dtype(dtype).kind == "f":
        return RNG.normal(size=(H, W, channels)).astype(dtype)
    info = np.iinfo(dtype)
    return RNG.integers(info.min, info.max, size=(H, W, channels), endpoint=True).astype(dtype)


ENCODINGS = [("mono8", "u1", 1), ("rgb8", "u1", 3), ("rgba8", "u1", 4), ("mono16", "u2", 1),
             ("16UC1", "u2", 1), ("32FC1", "f4", 1), ("16SC1", "i2", 1), ("64FC1", "f8", 1)]


@pytest.mark.parametrize("encoding, dtype, channels", ENCODINGS)
@pytest.mark.parametrize("pad", [0, 3])
def test_encodings_round_trip_pixel_exact(encoding: str, dtype: str, channels: int,
                                          pad: int) -> None:
    codec = codec_for("Image")
    pixels = _pixels(dtype, channels)
    msg = _ros_image(encoding, pixels, pad)
    enc = codec.encode(msg)
    assert isinstance(enc.body, Image)
    assert enc.metadata["ros2.encoding"] == encoding
    on_wire = _wire(enc.body)
    assert on_wire.pixels.shape == (1, H, W, channels)
    np.testing.assert_array_equal(on_wire.pixels[0], pixels)
    back = codec.from_igtl(on_wire, metadata=enc.metadata)
    assert back.encoding == encoding
    assert (back.height, back.width, back.is_bigendian) == (H, W, 0)
    assert back.step == W * channels * np.dtype(dtype).itemsize  # padding dropped
    got = np.frombuffer(back.data, dtype=np.dtype(dtype).newbyteorder("<"))
    np.testing.assert_array_equal(got.reshape(H, W, channels), pixels)


def test_upright_geometry_in_slicer() -> None:
    body = codec_for("Image").to_igtl(_ros_image("mono8", _pixels("u1", 1)))
    # columns along -R, rows along -A: row 0 at the top, column 0 at the left of the Red view
    np.testing.assert_array_equal(body.directions, SLICER_DIRECTIONS)
    np.testing.assert_array_equal(body.spacing, [1.0, 1.0, 1.0])
    assert body.coordinate == "RAS"
    wire = _wire(body)
    np.testing.assert_allclose(wire.directions, SLICER_DIRECTIONS)
    np.testing.assert_allclose(wire.origin, [0.0, 0.0, 0.0], atol=1e-4)


def test_bgr8_is_sent_as_rgb_and_comes_back_as_rgb8_or_bgr8() -> None:
    codec = codec_for("Image")
    bgr = _pixels("u1", 3)
    msg = _ros_image("bgr8", bgr, pad=1)
    enc = codec.encode(msg)
    wire = _wire(enc.body)
    np.testing.assert_array_equal(wire.pixels[0], bgr[..., ::-1])  # Slicer gets red first
    plain = codec.from_igtl(wire)  # no metadata (an image made in Slicer): rgb8
    assert plain.encoding == "rgb8"
    np.testing.assert_array_equal(np.frombuffer(plain.data, np.uint8).reshape(H, W, 3),
                                  bgr[..., ::-1])
    same = codec.from_igtl(wire, metadata=enc.metadata)  # with the bridge's metadata: bgr8
    assert same.encoding == "bgr8"
    np.testing.assert_array_equal(np.frombuffer(same.data, np.uint8).reshape(H, W, 3), bgr)


def test_bgra8_reorders_to_rgba() -> None:
    bgra = _pixels("u1", 4)
    body = codec_for("Image").to_igtl(_ros_image("bgra8", bgra))
    np.testing.assert_array_equal(body.pixels[0], bgra[..., [2, 1, 0, 3]])


@pytest.mark.parametrize("encoding, dtype, channels", [("mono16", "u2", 1), ("32FC1", "f4", 1),
                                                        ("16UC1", "u2", 1)])
def test_big_endian_images(encoding: str, dtype: str, channels: int) -> None:
    pixels = _pixels(dtype, channels)
    body = codec_for("Image").to_igtl(_ros_image(encoding, pixels, pad=2, big_endian=True))
    np.testing.assert_array_equal(_wire(body).pixels[0], pixels)


def test_data_size_mismatch_is_a_codec_error() -> None:
    msg = _ros_image("rgb8", _pixels("u1", 3), pad=2)
    msg.data.pop()
    with pytest.raises(CodecError) as err:
        codec_for("Image").to_igtl(msg)
    assert err.value.field == "data"
    assert str(H * msg.step) in err.value.expected


@pytest.mark.parametrize("change, field", [
    (lambda m: setattr(m, "step", W * 3 - 1), "step"),
    (lambda m: setattr(m, "encoding", "yuv422"), "encoding"),
    (lambda m: setattr(m, "height", 0), "height"),
])
def test_bad_ros_images(change: Any, field: str) -> None:
    msg = _ros_image("rgb8", _pixels("u1", 3))
    change(msg)
    with pytest.raises(CodecError) as err:
        codec_for("Image").to_igtl(msg)
    assert err.value.field == field


def test_bad_bodies_from_slicer() -> None:
    codec = codec_for("Image")
    with pytest.raises(CodecError) as err:
        codec.from_igtl(Image(np.zeros((2, H, W, 1), np.uint8)))
    assert err.value.field == "pixels" and "one slice" in err.value.expected
    with pytest.raises(CodecError) as err:
        codec.from_igtl(Image(np.zeros((1, H, W, 2), np.uint8)))
    assert err.value.field == "pixels"
    with pytest.raises(CodecError) as err:
        codec.from_igtl(String(text="image"))
    assert err.value.field == "body"


def _value_round_trip(encoding: str, pixels: np.ndarray) -> tuple[Any, RosImage]:
    codec = codec_for("Image")
    msg = _ros_image(encoding, pixels)
    value = codec.to_value(msg)
    return value, codec.from_value(value)


def test_values() -> None:
    mono = _pixels("u1", 1)
    value, back = _value_round_trip("mono8", mono)
    assert value["encoding"] == "mono8" and value["pixels"] == mono[..., 0].tolist()
    assert back.encoding == "mono8"
    np.testing.assert_array_equal(np.frombuffer(back.data, np.uint8).reshape(H, W), mono[..., 0])
    depth = _pixels("f4", 1)
    value, back = _value_round_trip("32FC1", depth)
    np.testing.assert_array_equal(np.frombuffer(back.data, "<f4").reshape(H, W), depth[..., 0])
    # no encoding: integers 0..255 become mono8 / rgb8
    guessed = codec_for("Image").from_value({"pixels": [[[1, 2, 3], [4, 5, 6]]]})
    assert (guessed.encoding, guessed.height, guessed.width) == ("rgb8", 1, 2)
    # base64 data form
    import base64
    raw = codec_for("Image").from_value({"encoding": "mono16", "height": 1, "width": 2,
                                         "data": base64.b64encode(b"\x01\x00\x02\x00").decode()})
    assert list(np.frombuffer(raw.data, "<u2")) == [1, 2]


@pytest.mark.parametrize("value, field", [
    ({"encoding": "mono8", "height": 2, "width": 2, "data": "AAAA"}, "value.data"),
    ({"encoding": "mono8", "pixels": [[0, 256]]}, "value.pixels[0][1]"),
    ({"encoding": "rgb8", "pixels": [[0, 1]]}, "value.pixels"),
    ({"encoding": "rgb9", "pixels": [[0, 1]]}, "value.encoding"),
    ({"pixels": [[0, 1], [2]]}, "value.pixels"),
    ({"pixels": [[0, 1]], "colour": 1}, "value.colour"),
    ([[0, 1]], "value"),
])
def test_bad_image_values(value: Any, field: str) -> None:
    with pytest.raises(CodecError) as err:
        codec_for("Image").from_value(value)
    assert err.value.field == field


# --- read from the serialized bytes (the daemon's subscriptions take images raw) -----------
def _same_encoded(a: Any, b: Any) -> None:
    assert (a.metadata, a.stamp) == (b.metadata, b.stamp)
    np.testing.assert_array_equal(_wire(a.body).pixels, _wire(b.body).pixels)
    assert a.body.pack() == b.body.pack()


@pytest.mark.parametrize("encoding, dtype, channels", [*ENCODINGS, ("bgr8", "u1", 3)])
@pytest.mark.parametrize("frame_id", ["", "c", "cam", "camera_optical_frame"])
@pytest.mark.parametrize("big_endian", [False, True])
def test_the_serialized_image_encodes_as_the_message(encoding: str, dtype: str,
                                                     channels: int, frame_id: str,
                                                     big_endian: bool) -> None:
    """Every field's alignment moves with the frame's and the encoding's lengths."""
    from rclpy.serialization import serialize_message
    codec = codec_for("Image")
    msg = _ros_image(encoding, _pixels(dtype, channels), pad=3, big_endian=big_endian)
    msg.header.frame_id = frame_id
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1_700_000_000, 1_500_000_000
    from_bytes = codec.encode_serialized(serialize_message(msg))
    assert from_bytes is not None
    _same_encoded(from_bytes, codec.encode(msg))


def test_a_bad_serialized_image_is_refused_or_left_to_rclpy() -> None:
    from rclpy.serialization import serialize_message
    codec = codec_for("Image")
    msg = _ros_image("rgb8", _pixels("u1", 3))
    data = serialize_message(msg)
    assert codec.encode_serialized(data[:-1]) is None  # cut short: rclpy says why
    assert codec.encode_serialized(b"\x01\x00" + data[2:]) is None  # big-endian CDR
    assert codec.encode_serialized(b"") is None
    msg.step = W * 3 - 1
    with pytest.raises(CodecError) as err:
        codec.encode_serialized(serialize_message(msg))
    assert err.value.field == "step"
    assert codec_for("String").encode_serialized(data) is None  # no reader of its bytes


@settings(max_examples=300, deadline=None)
@given(cut=st.integers(0, 200), flips=st.lists(st.tuples(st.integers(0, 120), st.integers(0, 255)),
                                                max_size=6))
def test_damaged_serialized_images_are_refused_or_left_to_rclpy(
        cut: int, flips: list[tuple[int, int]]) -> None:
    """A peer's bytes: a cut or altered message never raises anything but CodecError."""
    from rclpy.serialization import serialize_message
    msg = _ros_image("rgb8", _pixels("u1", 3), pad=1)
    msg.header.frame_id = "camera"
    data = bytearray(serialize_message(msg))
    for at, value in flips:
        if at < len(data):
            data[at] = value
    damaged = bytes(data[:len(data) - cut])
    try:
        encoded = codec_for("Image").encode_serialized(damaged)
    except CodecError:
        return
    if encoded is not None:
        assert isinstance(encoded.body, Image)


@pytest.mark.parametrize("encoding, dtype, channels", [("rgb8", "uint8", 3),
                                                       ("mono16", "uint16", 1)])
def test_a_video_frame_goes_from_its_ros_bytes_to_the_wire_parts_without_a_copy(
        encoding: str, dtype: str, channels: int) -> None:
    """The frame that is sent holds the pixels where they lie in the serialized message:
    no copy of them is made in Python between the ROS bytes and the socket."""
    from rclpy.serialization import serialize_message

    from bridge.core.hub import frame_for
    from protocol.framing import Decoder
    from protocol.messages import Message

    pixels = RNG.integers(0, 255, size=(240, 320, channels)).astype(dtype)  # a large frame
    data = bytes(serialize_message(_ros_image(encoding, pixels)))
    encoded = codec_for("sensor_msgs/msg/Image").encode_serialized(data)
    assert encoded is not None and not isinstance(encoded, CodecError)
    frame = frame_for(Message(device_name="camera", body=encoded.body, timestamp=1,
                              metadata=encoded.metadata))
    head, content, tail = frame.encoded_parts(2)
    assert np.shares_memory(np.frombuffer(content, dtype=np.uint8),
                            np.frombuffer(data, dtype=np.uint8))
    decoder = Decoder()
    decoder.feed(b"".join((head, content, tail)))  # and the bytes are a valid IMAGE
    message = decoder.next_message()
    assert message is not None and isinstance(message.body, Image)
    np.testing.assert_array_equal(message.body.pixels[0], pixels)
