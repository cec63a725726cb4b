"""The hot path of a streamed image: CDR bytes in, the IMAGE's wire parts out (its own
header, its pixels where they lie in the bytes, the stream's `StreamTemplate`), with no
numpy array, `Image` body or `Message` built.

A video stream's messages differ in their stamp and pixels only: every other byte (frame
id, size, encoding, step) repeats. So the ordinary codec converts a message, and what it
made (the IMAGE header, the metadata) is kept with the bytes it came from (`learn`); a
later message whose bytes match them there reuses it with its own stamp and pixels
(`convert`). One rule stays with the codec: a message it must copy or reorder (padded
rows, blue first, big-endian) is never kept, and one that differs takes the ordinary path
again. The bytes are the ones `protocol.framing.encode_parts` makes for the same message
(tests compare them).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Optional

import numpy as np

from bridge.codecs.cdr import CdrError, read_image
from protocol.conversions import igtl_stamp_or_now
from protocol.crc64 import Buffer
from protocol.errors import ProtocolError
from protocol.framing import StreamTemplate
from protocol.messages import Image, Message

__all__ = ["RawImageStream"]

_SEC_NANOSEC = struct.Struct("<iI")
_STAMP_END = 12  # the encapsulation header, then the stamp (int32 sec, uint32 nanosec)


@dataclass(frozen=True)
class _Kept:
    """What the ordinary path made of one message, and the bytes it depends on."""

    encapsulation: bytes  # the first 4 bytes
    fields: bytes  # the bytes after the stamp, up to the pixels
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
        if (len(data) < end or data[_STAMP_END:start] != kept.fields
                or data[:4] != kept.encapsulation):
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
        start = raw.data_start
        self._kept = _Kept(data[:4], data[_STAMP_END:start], start, len(raw.data), template,
                           lead)


def _same_bytes(a: Buffer, b: Buffer) -> bool:
    """Whether two buffers are the same memory (not only equal bytes)."""
    x = np.frombuffer(a, dtype=np.uint8)
    y = np.frombuffer(b, dtype=np.uint8)
    return x.size == y.size and x.ctypes.data == y.ctypes.data
