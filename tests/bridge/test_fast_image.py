"""The image hot path (bridge/codecs/fast_image.py): a message laid out as the last one the
codec converted is sent from its CDR bytes, the pixels where they lie, and its bytes on
the wire are the ordinary path's; whatever the codec copies or reorders, or a message laid
out otherwise, goes the ordinary way. Real rclpy serialization, a real hub."""

from __future__ import annotations

import asyncio
import threading
from dataclasses import replace
from typing import Any, Iterator

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Image as RosImage

from bridge.codecs import codec_for
from bridge.codecs.fast_image import RawImageStream
from bridge.core.hub import LARGE_MESSAGE_BYTES, Hub
from protocol.commands import QoS
from protocol.framing import StreamTemplate, encode
from protocol.messages import Image, Message
from protocol.naming import KEY_FRAME

# encoding -> (bytes per pixel, does the codec send the bytes where they lie?)
KEPT = {"rgb8": 3, "mono8": 1, "rgba8": 4, "mono16": 2, "32FC1": 4, "16SC1": 2, "64FC1": 8}
NOT_KEPT = {"bgr8": 3, "bgra8": 4}  # reordered to red first: a copy


def _image_bytes(encoding: str, size: int, *, width: int = 5, height: int = 0,
                 frame: str = "camera", stamp: tuple[int, int] = (1_700_000_000, 5),
                 seed: int = 0, pad: int = 0, bigendian: int = 0) -> bytes:
    """A serialized sensor_msgs/Image; by default just large enough to be sent as a large
    message (`hub.is_large`), which is what the kept way is for."""
    step = width * size + pad
    height = height or LARGE_MESSAGE_BYTES // step + 1
    msg = RosImage(height=height, width=width, encoding=encoding, is_bigendian=bigendian,
                   step=step)
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    msg.data = np.random.default_rng(seed).integers(
        0, 255, height * msg.step, dtype=np.uint8).tobytes()
    return bytes(serialize_message(msg))


class _Hub:
    """A real hub on a loop in a thread (no client: its newest value per device is read)."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.hub = Hub(self.loop)
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()


@pytest.fixture(scope="module")
def ros() -> Iterator[Any]:
    from bridge.ros.ros_node import RosNode, RosOptions

    node = RosNode(RosOptions(node_name="fast_image"))
    try:
        yield node
    finally:
        node.stop()


def _sent(ros: Any, messages: list[bytes], device: str = "camera") -> tuple[list[Message], Any]:
    """What a subscriber bridge sends of each message in turn (decoded from its wire bytes,
    CRC checked), and the bridge's image stream after the last."""
    from bridge.topics.capability import SubscriberBridge

    served = _Hub()
    bridge = SubscriberBridge(ros, served.hub, topic="/fast_image", qos=QoS(
        durability="transient_local"), codec=codec_for("sensor_msgs/msg/Image"),
        device=device, metadata={"ros2.topic": "/fast_image"})
    try:
        out = []
        for data in messages:
            bridge._on_raw(data)
            message = served.hub.latest(device)
            assert message is not None
            out.append(replace(message, message_id=0))  # the daemon's clock, not compared
        return out, bridge._images
    finally:
        bridge.close()
        served.close()


def _wire(message: Message) -> bytes:
    return encode(message, header_version=2)


@pytest.mark.ros
@settings(max_examples=25, deadline=None)
@given(encoding=st.sampled_from(sorted(KEPT)), frame=st.text(max_size=11),
       width=st.integers(16, 40), stamp=st.tuples(st.integers(1, 2**31 - 1),
                                                 st.integers(0, 999_999_999)))
def test_the_next_frame_of_a_stream_is_the_bytes_of_the_ordinary_path(
        ros: Any, encoding: str, frame: str, width: int, stamp: tuple[int, int]) -> None:
    # (An unset stamp becomes the time of sending on both paths: igtl_stamp_or_now.)
    first = _image_bytes(encoding, KEPT[encoding], width=width, frame=frame)
    second = _image_bytes(encoding, KEPT[encoding], width=width, frame=frame, stamp=stamp,
                          seed=1)
    streamed, images = _sent(ros, [first, second])
    assert images.convert(second) is not None  # the second went the kept way
    ordinary, _ = _sent(ros, [second])
    assert _wire(streamed[1]) == _wire(ordinary[0])
    body = streamed[1].body
    assert isinstance(body, Image)  # the second message's own pixels, in ROS's order
    assert np.asarray(body.pixels).tobytes() == bytes(deserialize_message(second,
                                                                          RosImage).data)


@pytest.mark.ros
def test_what_the_codec_copies_or_reorders_is_never_kept(ros: Any) -> None:
    cases = [_image_bytes(name, size) for name, size in NOT_KEPT.items()]
    cases.append(_image_bytes("rgb8", 3, pad=2))  # padded rows: dropped, so copied
    cases.append(_image_bytes("mono16", 2, bigendian=1))  # swapped to little-endian
    for data in cases:
        streamed, images = _sent(ros, [data, data])
        assert images.convert(data) is None
        assert _wire(streamed[0]) == _wire(streamed[1])  # both the ordinary way


@pytest.mark.ros
def test_a_message_laid_out_otherwise_goes_the_ordinary_way_and_is_kept_next(
        ros: Any) -> None:
    first = _image_bytes("rgb8", 3)
    other_frame = _image_bytes("rgb8", 3, frame="camera_2", seed=1)
    other_size = _image_bytes("rgb8", 3, width=6, seed=2)
    streamed, images = _sent(ros, [first, other_frame, other_size])
    assert streamed[1].metadata[KEY_FRAME] == "camera_2"
    assert isinstance(streamed[2].body, Image) and streamed[2].body.pixels.shape[2] == 6
    assert images.convert(other_size) is not None and images.convert(first) is None
    # Bytes that are not a whole image (cut short) never reach the kept way's reading.
    assert images.convert(other_size[:-1]) is None


def test_a_templates_parts_are_the_bytes_of_encode() -> None:
    pixels = np.arange(2 * 3 * 4 * 3, dtype=np.uint8).reshape(1, 3, 4, 6)
    body = Image(pixels=pixels, spacing=np.ones(3), directions=np.diag([-1.0, -1.0, 1.0]),
                 origin=np.zeros(3), coordinate="RAS")
    message = Message(device_name="camera", timestamp=123456789, metadata={"a": "b"},
                      body=body)
    lead, content = body.pack_parts()
    template = StreamTemplate(message.type_name, message.device_name, message.metadata)
    for message_id in (0, 7, 2**32 - 1):
        parts = template.encode_parts(lead, content, message.timestamp, message_id)
        assert b"".join(parts) == _wire(replace(message, message_id=message_id))
    assert RawImageStream().convert(b"\x00\x01\x00\x00" + bytes(40)) is None  # nothing kept


@pytest.mark.ros
def test_a_header_v1_client_gets_the_kept_ways_frame_as_the_ordinary_ones(ros: Any) -> None:
    """An OpenIGTLink 1.11 peer reads header v1: the frame made the kept way gives it the
    bytes the ordinary path gives (no metadata, no message id in v1)."""
    from bridge.core.outbox import TemplateBulkFrame

    first = _image_bytes("mono16", 2, width=7)
    second = _image_bytes("mono16", 2, width=7, stamp=(1_700_000_001, 9), seed=3)
    _, images = _sent(ros, [first])
    same = images.convert(second)
    assert same is not None
    template, lead, pixels, timestamp = same
    frame = TemplateBulkFrame(template, lead, pixels, timestamp, 42)
    ordinary, _ = _sent(ros, [second])
    assert frame.encoded(1) == encode(ordinary[0], header_version=1)
    assert frame.message.message_id == 42 and frame.message.metadata == ordinary[0].metadata


@pytest.mark.ros
def test_a_small_image_goes_the_ordinary_way_as_other_small_messages(ros: Any) -> None:
    """Whether a message is large is decided in one place (`hub.is_large`): a small image
    is queued in order as any small message, never made a large frame by the kept way."""
    small = _image_bytes("rgb8", 3, height=2)
    streamed, images = _sent(ros, [small, small])
    assert images.convert(small) is None
    assert _wire(streamed[0]) == _wire(streamed[1])


@pytest.mark.ros
def test_alignment_padding_a_serializer_left_unset_is_not_compared(ros: Any) -> None:
    """Fast CDR may leave the padding between fields as it found the memory: two messages
    of one stream then differ there, and the second still goes the kept way, with the
    ordinary path's bytes."""
    first = _image_bytes("mono16", 2, width=7)  # "camera" ends at byte 23: one pad byte
    second = bytearray(_image_bytes("mono16", 2, width=7, stamp=(1_700_000_001, 9), seed=3))
    assert second[23] == 0
    second[23] = 0xAB
    streamed, images = _sent(ros, [first, bytes(second)])
    assert images.convert(bytes(second)) is not None
    ordinary, _ = _sent(ros, [bytes(second)])
    assert _wire(streamed[1]) == _wire(ordinary[0])
