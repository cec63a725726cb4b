"""The hot path of a streamed image: CDR bytes in, the IMAGE's wire parts out (its own
header, its pixels where they lie in the bytes, the stream's `StreamTemplate`), with no
numpy array, `Image` body or `Message` built.

A video stream's messages differ in their stamp and pixels only: every other field (frame
id, size, encoding, step) repeats. So the ordinary codec converts a message, and what it
made (the IMAGE header, the metadata) is kept with the fields' bytes (`learn`); a later
message whose fields hold the same bytes reuses it with its own stamp and pixels
(`convert`). The alignment padding between fields is not compared: a serializer may leave
it unset. One rule stays with the codec: a message it must copy or reorder (padded rows,
blue first, big-endian) is never kept, and one that differs takes the ordinary path
again. The bytes are the ones `protocol.framing.encode_parts` makes for the same message
(tests compare them).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Optional

import numpy as np

from bridge.codecs.cdr import CdrError, plain_little_endian, read_image
from protocol.conversions import igtl_stamp_or_now
from protocol.crc64 import Buffer
from protocol.errors import ProtocolError
from protocol.framing import StreamTemplate
from protocol.messages import Image, Message

__all__ = ["RawImageStream"]

_SEC_NANOSEC = struct.Struct("<iI")  # the stamp, after the 4-byte encapsulation header


@dataclass(frozen=True)
class _Kept:
    """What the ordinary path made of one message, and the bytes it depends on."""

    spans: tuple[tuple[int, int], ...]  # where its fields lie (`RawImage.field_spans`)
    fields: tuple[bytes, ...]  # their bytes
    start: int  # where the pixels begin
    count: int  # how many bytes they take
    template: StreamTemplate
    lead: bytes  # the IMAGE header


class RawImageStream:
    """One streamed sensor_msgs/Image topic's conversion from its CDR bytes."""

    def __init__(self) -> None:
        self._kept: Optional[_Kept] = None

    def convert(self, data: bytes) -> Optional[tuple[StreamTemplate, bytes, memoryview, int]]:
        """(template, IMAGE header, pixels, IGTL time stamp) of a message laid out as the
        one kept; None: it takes the ordinary path (then `learn`)."""
        kept = self._kept
        if kept is None:
            return None
        start, end = kept.start, kept.start + kept.count
        if len(data) < end or not plain_little_endian(data):
            return None
        for (first, last), value in zip(kept.spans, kept.fields):
            if data[first:last] != value:
                return None
        sec, nanosec = _SEC_NANOSEC.unpack_from(data, 4)
        return (kept.template, kept.lead, memoryview(data)[start:end],
                igtl_stamp_or_now(sec, nanosec))

    def learn(self, data: bytes, message: Message) -> None:
        """Keep what the ordinary path made of ``data`` (``message``) if it sends the pixels
        where they lie in ``data``; otherwise keep nothing."""
        self._kept = None
        if not isinstance(message.body, Image):
            return
        try:
            raw = read_image(data)
            lead, pixels = message.body.pack_parts()
            template = StreamTemplate(message.type_name, message.device_name,
                                      message.metadata)
        except (CdrError, ProtocolError):
            return
        if not _same_bytes(pixels, raw.data):
            return  # the codec copied or reordered them
        spans = raw.field_spans
        self._kept = _Kept(spans, tuple(data[first:last] for first, last in spans),
                           raw.data_start, len(raw.data), template, lead)


def _same_bytes(a: Buffer, b: Buffer) -> bool:
    """Whether two buffers are the same memory (not only equal bytes)."""
    x = np.frombuffer(a, dtype=np.uint8)
    y = np.frombuffer(b, dtype=np.uint8)
    return x.size == y.size and x.ctypes.data == y.ctypes.data
