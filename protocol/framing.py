"""Sans-I/O OpenIGTLink framing: `encode` a `Message` to bytes, `Decoder` turns a byte
stream back into messages. No sockets here: a transport feeds received bytes in and writes
encoded bytes out (the asyncio daemon, a blocking client and a Qt timer in Slicer share it).

Decoder error contract (see protocol.errors):

* `MessageError` (`CrcMismatchError`, `BodyError`): raised by `next_message` after the bad
  message was consumed; call again to go on with the next one.
* `FramingError` (`HeaderError`, `BodyTooLargeError`, `ReceiveBudgetError`): message
  boundaries are lost; the decoder stays broken and raises the same error on every later
  call. Close the connection.

Bounding what clients hold: a `ReceiveBudget` shared by many decoders caps the bytes of
bodies announced and not yet complete, so N slow senders cannot pin N x ``max_body_size``.
The decoder reports `frame_in_progress` and `frames` so its owner can put a deadline on a
frame (the decoder has no clock), and `close` gives its buffer and budget back at once.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import NamedTuple, cast

import numpy as np
import numpy.typing as npt

from protocol.crc64 import Buffer, KnownCrc, crc64, crc64_continue
from protocol.errors import (
    BodyError,
    BodyTooLargeError,
    CrcMismatchError,
    EncodeError,
    FramingError,
    ProtocolError,
    ReceiveBudgetError,
)
from protocol.header import (
    EXT_HEADER_SIZE,
    HEADER_SIZE,
    TYPE_NAME_SIZE,
    DEVICE_NAME_SIZE,
    ExtendedHeader,
    Header,
    decode_name,
    encode_name,
    pack_metadata,
    unpack_metadata,
    unpack_raw,
)
from protocol.messages import Image, Message, PolyData, RawBody, unpack_body

__all__ = ["DEFAULT_MAX_BODY_SIZE", "DEFAULT_UNCOUNTED_BODY_BYTES", "Decoder", "RawFrame",
           "ReceiveBudget", "StreamTemplate", "encode", "encode_parts"]

DEFAULT_MAX_BODY_SIZE = 64 * 1024 * 1024  # 64 MiB: a 512^3 uint8 volume with room to spare
# Bodies up to this size are not counted against a `ReceiveBudget`: commands and poses must
# get through while large senders have used it up (64 clients x 256 KiB = 16 MiB at most).
DEFAULT_UNCOUNTED_BODY_BYTES = 256 * 1024
# A body this large is received into a buffer of its own (`Decoder`): an image, a model.
LARGE_BODY_BYTES = 4 * 1024 * 1024

_U32_MAX = 0xFFFFFFFF
_U64_MAX = (1 << 64) - 1


def encode(message: Message, *, header_version: int = 1) -> bytes:
    """The complete wire bytes of ``message`` (header + body) with its CRC.

    ``header_version`` 1 drops ``metadata`` and ``message_id`` (OpenIGTLink 1.x/2.x peers
    cannot read more); 2 writes the extended header and metadata. The timestamp is written
    as given: setting it (0 means "unset") is the caller's business.
    """
    head, content, tail = encode_parts(message, header_version=header_version)
    return b"".join((head, content, tail))


def encode_parts(message: Message, *, header_version: int = 1,
                 content_crc: KnownCrc | None = None) -> tuple[bytes, Buffer, bytes]:
    """`encode` as three parts whose concatenation is the message's wire bytes: the header
    (and v2's extended header), the content, and v2's metadata. The content is the body's
    own bytes where it has them (a `RawBody`): a large model is then neither copied nor
    held twice, and the CRC is computed over the parts as they are. ``content_crc``: the
    content's, made beforehand, saves going over it again."""
    type_name = message.type_name
    body = message.body
    content: Buffer
    lead = b""  # the content's first bytes, sent with the header (an image's own header)
    if isinstance(body, RawBody):
        content = body.data
    elif isinstance(body, Image):
        lead, content = body.pack_parts()  # a video frame's pixels, where they lie
    elif isinstance(body, PolyData):
        content = body.pack_view()  # a model of tens of MB: no final copy
    else:
        content = body.pack()
    if header_version == 1:
        ext, tail = b"", b""
    elif header_version == 2:
        if isinstance(message.message_id, bool) or not isinstance(message.message_id, int) \
                or not 0 <= message.message_id <= _U32_MAX:
            raise EncodeError("message_id", "an integer in [0, 2**32)", message.message_id)
        meta_header, meta = _packed_metadata(message.metadata)
        ext = _EXT_HEADER.pack(EXT_HEADER_SIZE, len(meta_header), len(meta),
                               message.message_id)
        tail = meta_header + meta
    else:
        raise EncodeError("header_version", "1 or 2", header_version)
    size = len(ext) + len(lead) + len(content) + len(tail)
    # ``content_crc`` is the whole content's (lead included).
    crc = (crc64_continue(crc64_continue(crc64(ext), lead), content) if content_crc is None
           else content_crc.after(crc64(ext)))
    crc = crc64_continue(crc, tail)
    timestamp = message.timestamp
    if isinstance(timestamp, int) and 0 <= timestamp <= _U64_MAX:
        # The names' checks, once per distinct name; then one struct pack.
        header = _HEADER.pack(header_version, _name_raw(type_name, "type_name"),
                              _name_raw(message.device_name, "device_name"), timestamp,
                              size, crc)
    else:
        # Raises the EncodeError that says what is wrong.
        header = Header(header_version, type_name, message.device_name, timestamp, size,
                        crc).pack()
    return header + ext + lead, content, tail


# Streams repeat the same metadata and names thousands of times a second: their packed
# forms are kept (bounded; an LRU would cost more than it saves at these sizes).
_METADATA_CACHE: dict[tuple[tuple[str, str], ...], tuple[bytes, bytes]] = {}
_NAME_CACHE: dict[tuple[str, str], bytes] = {}
_CACHE_LIMIT = 4096


def _packed_metadata(metadata: dict[str, str]) -> tuple[bytes, bytes]:
    try:
        key = tuple(metadata.items())
        packed = _METADATA_CACHE.get(key)
    except TypeError:  # an unhashable value: pack_metadata says what is wrong
        key, packed = (), None
    if packed is None:
        meta_header, meta = pack_metadata(metadata)
        if len(meta_header) > 0xFFFF or len(meta) > _U32_MAX:
            raise EncodeError("metadata", "a header under 64 KiB and values under 4 GiB",
                              f"{len(meta_header)} + {len(meta)} bytes")
        packed = (meta_header, meta)
        if key and len(meta) < 4096:
            if len(_METADATA_CACHE) >= _CACHE_LIMIT:
                _METADATA_CACHE.clear()
            _METADATA_CACHE[key] = packed
    return packed


def _name_raw(name: str, field: str) -> bytes:
    key = (name, field)
    raw = _NAME_CACHE.get(key)
    if raw is None:
        size = TYPE_NAME_SIZE if field == "type_name" else DEVICE_NAME_SIZE
        raw = encode_name(name, field, size)
        if field == "type_name" and not raw:
            raise EncodeError("type_name", "a non-empty message type", "''")
        if len(_NAME_CACHE) >= _CACHE_LIMIT:
            _NAME_CACHE.clear()
        _NAME_CACHE[key] = raw
    return raw


_HEADER = struct.Struct(">H12s20sQQQ")
_EXT_HEADER = struct.Struct(">HHII")


class StreamTemplate:
    """The constant part of a stream's messages (type, device name, metadata), checked and
    packed once, so that each message costs one CRC and two struct packs: what `encode`
    gives for the same `Message`, byte for byte, without building one.

    A streamed device sends thousands of messages a second whose header fields and metadata
    do not change; only the content and the time stamp do.
    """

    __slots__ = ("type_name", "device_name", "metadata", "_type_raw", "_name_raw",
                 "_meta_tail", "_ext_v2", "_meta_sizes")

    def __init__(self, type_name: str, device_name: str, metadata: dict[str, str]) -> None:
        self.type_name = type_name
        self.device_name = device_name
        self.metadata = dict(metadata)
        type_raw = encode_name(type_name, "type_name", TYPE_NAME_SIZE)
        if not type_raw:
            raise EncodeError("type_name", "a non-empty message type", "''")
        self._type_raw = type_raw
        self._name_raw = encode_name(device_name, "device_name", DEVICE_NAME_SIZE)
        meta_header, meta = pack_metadata(metadata)
        if len(meta_header) > 0xFFFF or len(meta) > _U32_MAX:
            raise EncodeError("metadata", "a header under 64 KiB and values under 4 GiB",
                              f"{len(meta_header)} + {len(meta)} bytes")
        self._meta_tail = meta_header + meta
        self._meta_sizes = (len(meta_header), len(meta))
        self._ext_v2 = _EXT_HEADER.pack(EXT_HEADER_SIZE, len(meta_header), len(meta), 0)

    def wire_parts(self) -> tuple[bytes, bytes, int, int, bytes]:
        """(type, device name, metadata header size, metadata size, metadata), packed: what
        a native writer needs to make `encode`'s bytes (bridge/core/_native_stream.pyx)."""
        return (self._type_raw, self._name_raw, *self._meta_sizes, self._meta_tail)

    def encode(self, content: bytes, timestamp: int, header_version: int,
               message_id: int = 0) -> bytes:
        """The wire bytes of one message with this content (a packed body), time stamp
        (a u64, as in `Message.timestamp`) and v2 message id."""
        if header_version == 2:
            body = b"".join((self._ext(message_id), content, self._meta_tail))
        elif header_version == 1:
            body = content
        else:
            raise EncodeError("header_version", "1 or 2", header_version)
        if not 0 <= timestamp <= _U64_MAX:
            raise EncodeError("timestamp", "an integer in [0, 2**64)", timestamp)
        return _HEADER.pack(header_version, self._type_raw, self._name_raw, timestamp,
                            len(body), crc64(body)) + body

    def encode_parts(self, lead: bytes, content: Buffer, timestamp: int,
                     message_id: int = 0) -> tuple[bytes, Buffer, bytes]:
        """`encode_parts`'s header-v2 parts of one message whose content is ``lead`` then
        ``content`` (an image's own header, then its pixels where they lie), never joined:
        the same bytes as for the `Message`, without building one."""
        if not 0 <= timestamp <= _U64_MAX:
            raise EncodeError("timestamp", "an integer in [0, 2**64)", timestamp)
        ext = self._ext(message_id)
        tail = self._meta_tail
        crc = crc64_continue(crc64_continue(crc64(ext + lead), content), tail)
        size = len(ext) + len(lead) + memoryview(content).nbytes + len(tail)
        return (_HEADER.pack(2, self._type_raw, self._name_raw, timestamp, size, crc) + ext
                + lead, content, tail)

    def _ext(self, message_id: int) -> bytes:
        # v2's extended header: the message id is the only part that changes.
        if not message_id:
            return self._ext_v2
        return _EXT_HEADER.pack(EXT_HEADER_SIZE, *self._meta_sizes, message_id)


class ReceiveBudget:
    """Bytes of partly received bodies that the decoders sharing it may hold together.

    A decoder claims a body's size (minus ``uncounted_body_bytes``) when its header is read,
    before any body byte is stored, and releases it when the body is complete or the
    decoder is closed. Not thread-safe: one event loop owns the decoders sharing it.
    """

    def __init__(self, total_bytes: int, *,
                 uncounted_body_bytes: int = DEFAULT_UNCOUNTED_BODY_BYTES) -> None:
        if total_bytes <= 0 or uncounted_body_bytes < 0:
            raise ValueError(f"total_bytes > 0 and uncounted_body_bytes >= 0 expected, got "
                             f"{total_bytes}, {uncounted_body_bytes}")
        self.total_bytes = total_bytes
        self.uncounted_body_bytes = uncounted_body_bytes
        self.in_use = 0

    @property
    def available(self) -> int:
        return self.total_bytes - self.in_use

    def cost(self, body_size: int) -> int:
        """What a body of ``body_size`` bytes counts against the budget."""
        return max(0, body_size - self.uncounted_body_bytes)

    def claim(self, body_size: int) -> int:
        """Claim a body's cost and return it, or raise `ReceiveBudgetError`."""
        cost = self.cost(body_size)
        if cost > self.available:
            raise ReceiveBudgetError(
                "BODY_SIZE", f"a body that fits in the {self.available} bytes left of the "
                f"shared budget for partly received bodies ({self.total_bytes} bytes, the "
                f"rest held by other connections' unfinished bodies)", body_size)
        self.in_use += cost
        return cost

    def release(self, cost: int) -> None:
        self.in_use -= cost


class Decoder:
    """Incremental decoder: `feed` bytes of any chunk size, then take messages with
    `next_message` (or iterate `messages`).

    Bytes are appended to one buffer and consumed by advancing an offset; the consumed prefix
    is dropped once it is at least half of the buffer, so each byte is moved O(1) times
    whatever the chunking. A BODY_SIZE above ``max_body_size`` is refused from the header
    alone, before any body byte is awaited or stored; so is one that does not fit in
    ``budget`` (shared with other decoders). A buffer whose bytes were all consumed is
    dropped, so an idle decoder holds nothing of the last large message.
    """

    def __init__(self, *, max_body_size: int = DEFAULT_MAX_BODY_SIZE,
                 verify_crc: bool = True, budget: ReceiveBudget | None = None) -> None:
        self.max_body_size = max_body_size
        self.verify_crc = verify_crc
        self._budget = budget
        self._claimed = 0
        self._buffer = bytearray()
        self._offset = 0
        self._header: tuple[int, bytes, bytes, int, int, int] | None = None
        self._broken: FramingError | None = None
        # A large body is received into a buffer of its own, its size known from its
        # header: no copy when it is complete, none when the shared buffer grows.
        self._body: npt.NDArray[np.uint8] | None = None
        self._filled = 0
        self.frames = 0  # frames consumed, good or bad: a deadline restarts with each

    @property
    def frame_in_progress(self) -> bool:
        """Part of a frame has arrived (after the complete ones were taken)."""
        return len(self._buffer) > self._offset or self._body is not None

    @property
    def pending_body_size(self) -> int | None:
        """BODY_SIZE of the frame whose header has been read, None before its header."""
        return None if self._header is None else self._header[4]

    @property
    def buffered(self) -> int:
        """Bytes received and not yet returned as part of a message."""
        large = 0 if self._body is None else HEADER_SIZE + self._filled
        return len(self._buffer) - self._offset + large

    @property
    def broken(self) -> FramingError | None:
        """The framing error that stopped this decoder, if any."""
        return self._broken

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        """Append received bytes (any size, including 1 byte or none)."""
        if self._broken is not None:
            raise self._broken
        if self._body is not None and self._filled < len(self._body):
            n = min(len(data), len(self._body) - self._filled)
            self._body[self._filled:self._filled + n] = np.frombuffer(data, np.uint8, n)
            self._filled += n
            data = memoryview(data)[n:]
            if not data:
                return
        if self._offset and self._offset * 2 >= len(self._buffer):
            del self._buffer[: self._offset]
            self._offset = 0
        self._buffer += data

    def close(self) -> None:
        """Drop buffered bytes and give back the budget claimed; later calls raise
        `FramingError`. Idempotent."""
        self._release_claim()
        self._buffer = bytearray()
        self._offset = 0
        self._header = None
        self._body = None
        if self._broken is None:
            self._broken = FramingError("decoder", "an open decoder", "a closed one")
        # Its traceback holds the frames that raised it, and with them their owners.
        self._broken.__traceback__ = None

    def _release_claim(self) -> None:
        if self._claimed and self._budget is not None:
            self._budget.release(self._claimed)
        self._claimed = 0

    def _break(self, error: FramingError) -> FramingError:
        self._broken = error
        self._release_claim()
        return error

    def _receive_apart(self, body_size: int) -> None:
        """The body just announced is large: it goes into its own buffer (not zeroed),
        with what of it has arrived already; the shared buffer goes on after it."""
        self._body = np.empty(body_size, dtype=np.uint8)
        start = self._offset + HEADER_SIZE
        n = min(len(self._buffer) - start, body_size)
        with memoryview(self._buffer) as view:
            self._body[:n] = np.frombuffer(view[start:start + n], np.uint8)
        self._filled = n
        self._offset = start + n

    def _take(self, size: int) -> bytes:
        start = self._offset
        self._offset = start + size
        with memoryview(self._buffer) as view:  # one copy, and the view is released at once
            return bytes(view[start:self._offset])

    def next_message(self) -> Message | None:
        """The next complete message, or None if more bytes are needed.

        Raises `MessageError` for a bad message (already consumed: call again) and
        `FramingError` when the stream cannot continue (then raised again on every call).
        """
        frame = self.next_frame()
        return None if frame is None else frame.decode(self.verify_crc)

    def next_frame(self) -> RawFrame | None:
        """The next complete frame, its body not checked or decoded yet (`RawFrame.decode`
        does both), or None if more bytes are needed. A receiver can then judge a message
        by its header alone (its type, its device) before it spends anything on the body.
        Raises `FramingError` as `next_message` does."""
        if self._broken is not None:
            raise self._broken
        if self._header is None:
            if self.buffered < HEADER_SIZE:
                return None
            start = self._offset
            try:
                fields = unpack_raw(self._buffer[start:start + HEADER_SIZE])
            except FramingError as exc:
                raise self._break(exc) from None
            body_size = fields[4]
            if body_size > self.max_body_size:
                raise self._break(BodyTooLargeError(
                    "BODY_SIZE", f"<= {self.max_body_size} bytes (max_body_size)", body_size))
            if self._budget is not None:
                try:
                    self._claimed = self._budget.claim(body_size)
                except ReceiveBudgetError as exc:
                    raise self._break(exc) from None
            self._header = fields
            if body_size >= LARGE_BODY_BYTES:
                self._receive_apart(body_size)
        version, type_raw, name_raw, timestamp, body_size, crc = self._header
        body: Buffer
        if self._body is not None:
            if self._filled < body_size:
                return None
            body = self._body.data.toreadonly()
            self._body = None
        else:
            if self.buffered < HEADER_SIZE + body_size:
                return None
            self._offset += HEADER_SIZE
            body = self._take(body_size)
        self._header = None
        self.frames += 1
        self._release_claim()
        if self._offset == len(self._buffer):
            # All consumed: let the (possibly 64 MiB) buffer go now, not at the next feed.
            self._buffer = bytearray()
            self._offset = 0
        return RawFrame(version, type_raw, name_raw, timestamp, body, crc)

    def messages(self) -> Iterator[Message]:
        """Yield messages until more bytes are needed (errors as in `next_message`)."""
        while True:
            message = self.next_message()
            if message is None:
                return
            yield message


class RawFrame(NamedTuple):
    """One complete frame as received (`Decoder.next_frame`): the header's fields and the
    body's bytes (a large one's: a read-only view of its own buffer), neither checked nor
    decoded."""

    version: int
    type_raw: bytes
    name_raw: bytes
    timestamp: int
    body: Buffer
    crc: int

    @property
    def type_name(self) -> str:
        """The header's type name, as sent (the name `decode` checks)."""
        return self.type_raw.split(b"\0", 1)[0].decode("latin-1")

    @property
    def device_name(self) -> str:
        """The header's device name, as sent (`decode` checks its encoding)."""
        return self.name_raw.split(b"\0", 1)[0].decode("utf-8", "replace")

    def decode(self, verify_crc: bool = True) -> Message:
        """The message: CRC checked, body decoded; `MessageError` if either fails."""
        return _decode(self.version, self.type_raw, self.name_raw, self.timestamp, self.body,
                       self.crc, verify_crc)


def _decode(version: int, type_raw: bytes, name_raw: bytes, timestamp: int, body: Buffer,
            crc: int, verify_crc: bool) -> Message:
    if verify_crc:
        actual = crc64(body)
        if actual != crc:
            raise CrcMismatchError("CRC", f"0x{actual:016x} (computed over the body)",
                                   f"0x{crc:016x}")
    try:
        type_name = decode_name(type_raw, "type_name")
        device_name = decode_name(name_raw, "device_name", type_name)
        metadata: dict[str, str] = {}
        message_id = 0
        content = body
        if version == 2:
            ext = ExtendedHeader.unpack(body, type_name)
            content_end = len(body) - ext.meta_header_size - ext.meta_size
            content = body[ext.ext_header_size:content_end]
            metadata = unpack_metadata(
                body[content_end:content_end + ext.meta_header_size],
                body[content_end + ext.meta_header_size:], type_name)
            message_id = ext.message_id
        # A large body is a memoryview: every unpacker reads with struct and numpy.
        parsed = unpack_body(type_name, cast(bytes, content))
    except ProtocolError:
        raise
    except (ValueError, IndexError, TypeError, UnicodeDecodeError) as exc:
        # Safety net: nothing untyped may escape the decoder.
        raise BodyError("body", "a well-formed message", f"{type(exc).__name__}: {exc}",
                        type_name=type_raw.split(b"\0", 1)[0].decode("latin-1")) from exc
    return Message(device_name, parsed, timestamp, metadata, message_id, version)
