"""Per-client send buffer: the newest value of each streamed device, plus one-shot frames.

A client that reads slowly must never delay ROS callbacks or other clients, and its memory
must stay bounded. So while a client's socket is backed up, a newer value of a streamed
device replaces its unsent older value (a viewer wants the latest pose, not the backlog),
and the buffer holds at most one frame per device. One-shot frames (meshes, command
replies) are never coalesced away; they are bounded in bytes instead, and a client that
lets them pile up past the bound is too slow to serve (`OutboxOverflow`).
"""

from __future__ import annotations

from collections import OrderedDict, deque
from dataclasses import replace
from typing import Any, Callable, Optional

from protocol.crc64 import Buffer, KnownCrc
from protocol.framing import Decoder, StreamTemplate, encode, encode_parts
from protocol.messages import Body, Message

__all__ = ["BulkFrame", "Frame", "Outbox", "OutboxOverflow", "SharedFrame", "TemplateBulkFrame",
           "TemplateFrame", "WRITE_CHUNK"]

# A larger one-shot (or stream value) is written this much at a time, as the transport
# drains: asyncio copies whatever the socket does not take at once into its own buffer,
# which for a 50 MB model and each client would be a copy of up to 50 MB per client.
WRITE_CHUNK = 256 * 1024


class Frame:
    """A message to send, encoded at most once per header version.

    Clients differ in the header version they can read (OpenIGTLink 1.11 peers need v1,
    3D Slicer takes v2 with metadata), so the bytes are made lazily and cached per version:
    one encode serves every client of that version.
    """

    __slots__ = ("_message", "_encoded", "clock")

    def __init__(self, message: Message) -> None:
        self._message = message
        self._encoded: dict[int, bytes] = {}
        # The daemon's clock when the hub took this stream value (protocol/freshness.py),
        # sent as the v2 message id; 0: not stamped (one-shots, replies).
        self.clock = 0

    @property
    def message(self) -> Message:
        return self._message

    def _stamped(self, message: Message) -> Message:
        if not self.clock or message.message_id:
            return message
        return replace(message, message_id=self.clock)

    def encoded(self, header_version: int) -> bytes:
        data = self._encoded.get(header_version)
        if data is None:
            data = encode(self._stamped(self.message), header_version=header_version)
            self._encoded[header_version] = data
        return data

    def encoded_parts(self, header_version: int) -> tuple[Buffer, ...]:
        """The wire bytes as consecutive parts (one, except for a `SharedFrame`)."""
        return (self.encoded(header_version),)


class SharedFrame(Frame):
    """A large message (a marker's model) whose content is kept once, shared with whoever
    made it: its wire bytes are its header, that content and its metadata
    (`protocol.framing.encode_parts`), written in turn, never joined."""

    __slots__ = ("_parts", "_content_crc")

    def __init__(self, message: Message, content_crc: Optional[KnownCrc] = None) -> None:
        super().__init__(message)
        self._parts: dict[int, tuple[bytes, Buffer, bytes]] = {}
        self._content_crc = content_crc  # known where the content was made: not redone

    def encoded_parts(self, header_version: int) -> tuple[Buffer, ...]:
        parts = self._parts.get(header_version)
        if parts is None:
            parts = self._parts[header_version] = encode_parts(
                self._message, header_version=header_version, content_crc=self._content_crc)
        return parts

    def encoded(self, header_version: int) -> bytes:
        return b"".join(self.encoded_parts(header_version))  # rare: a GET_ query


class BulkFrame(Frame):
    """A large message (an image, a point cloud) kept, once encoded, as its header-v2
    wire parts alone (`protocol.framing.encode_parts`: header, content, metadata), never
    joined: a video frame's pixels are copied once, into the content that is sent.

    The hub keeps each device's newest value for clients that connect later: holding the
    body's arrays beside their encoding would keep a 20 MB cloud twice. v2 bytes carry
    everything (metadata too), so a v1 peer's bytes or the `Message` (a GET_ query) are
    made from them again when asked for, which is rare, and not kept."""

    __slots__ = ("_parts",)
    _KEPT_VERSION = 2

    def __init__(self, message: Message) -> None:
        super().__init__(message)
        self._parts: Optional[tuple[bytes, Buffer, bytes]] = None

    @property
    def message(self) -> Message:
        message = self._message  # read once: another thread may encode it meanwhile
        if message is not None:
            return message
        data = self.encoded(self._KEPT_VERSION)
        decoder = Decoder(max_body_size=len(data))
        decoder.feed(data)
        message = decoder.next_message()
        assert message is not None, "a frame's own bytes decode"
        return message

    def _kept_parts(self) -> tuple[bytes, Buffer, bytes]:
        # The taking thread (a direct write) and the loop (a client that connects) may both
        # come first: the parts are set before the message is let go, so a thread that
        # finds no message finds the parts.
        parts = self._parts
        if parts is None:
            message = self._message
            if message is None:
                parts = self._parts
                assert parts is not None, "the parts are set before the message is let go"
                return parts
            parts = self._parts = encode_parts(self._stamped(message),
                                               header_version=self._KEPT_VERSION)
            self._message = None  # type: ignore[assignment]
        return parts

    def encoded_parts(self, header_version: int) -> tuple[Buffer, ...]:
        if header_version == self._KEPT_VERSION:
            return self._kept_parts()
        return (self.encoded(header_version),)

    def encoded(self, header_version: int) -> bytes:
        if header_version == self._KEPT_VERSION:
            return b"".join(self._kept_parts())  # rare: a GET_ query, a batch
        self._kept_parts()
        return encode(self.message, header_version=header_version)


class TemplateBulkFrame(BulkFrame):
    """A `BulkFrame` made from its stream's `StreamTemplate` without a `Message`: ``lead``
    (an image's own header, kept from the stream's last conversion) and ``content`` (the
    new pixels, where they lie in the ROS message), stamped with the hub's ``clock``."""

    __slots__ = ()

    def __init__(self, template: StreamTemplate, lead: bytes, content: Buffer,
                 timestamp: int, clock: int) -> None:
        self._message = None  # type: ignore[assignment]
        self._encoded = {}
        self.clock = clock
        self._parts = template.encode_parts(lead, content, timestamp, clock)


class TemplateFrame(Frame):
    """A streamed message kept as its packed content and time stamp, from a hot path that
    never built a `Message`: its bytes come from the stream's `StreamTemplate` (the same as
    `encode` gives), and the `Message` is made only if something asks for it (a GET_
    query, a client that connects later and reads header v1)."""

    __slots__ = ("_template", "_content", "_timestamp", "_values", "_body_of")

    def __init__(self, template: StreamTemplate, content: bytes, timestamp: int,
                 values: Any, body_of: Callable[[Any], Body]) -> None:
        self._message = None  # type: ignore[assignment]
        self._encoded = {}
        self.clock = 0
        self._template = template
        self._content = content
        self._timestamp = timestamp
        self._values = values
        self._body_of = body_of

    @property
    def template(self) -> StreamTemplate:
        return self._template

    @property
    def message(self) -> Message:
        if self._message is None:
            t = self._template
            self._message = Message(device_name=t.device_name, body=self._body_of(self._values),
                                    timestamp=self._timestamp, metadata=dict(t.metadata))
        return self._message

    def encoded(self, header_version: int) -> bytes:
        data = self._encoded.get(header_version)
        if data is None:
            data = self._template.encode(self._content, self._timestamp, header_version,
                                         self.clock)
            self._encoded[header_version] = data
        return data


class OutboxOverflow(Exception):
    """One-shot frames waiting for a client exceed the configured bound."""

    def __init__(self, limit: int, pending: int) -> None:
        super().__init__(f"send buffer over its bound: expected at most {limit} bytes of "
                         f"unsent one-shot messages, got {pending}")
        self.limit = limit
        self.pending = pending


class Outbox:
    """Unsent frames of one client. Not thread-safe: the event loop owns it.

    Stream values wait as `Frame`s and are encoded only when written: a stalled client
    then costs nothing per update, however many updates replace each other meanwhile.
    """

    def __init__(self, *, max_oneshot_bytes: int, header_version: Callable[[], int]) -> None:
        self._max_oneshot_bytes = max_oneshot_bytes
        self._header_version = header_version
        self._latest: OrderedDict[str, Frame] = OrderedDict()
        # One entry per frame: the parts not written yet (the first one may be the rest of
        # a part a chunk was taken from).
        self._oneshots: deque[list[Buffer]] = deque()
        self._started = False  # the first one-shot is partly written
        self._oneshot_bytes = 0
        self.coalesced = 0  # older values replaced before they were sent

    def __len__(self) -> int:
        return len(self._latest) + len(self._oneshots)

    @property
    def frames_waiting(self) -> int:
        """Frames not begun yet (a frame partly written is not waiting: it is going)."""
        return len(self._latest) + len(self._oneshots) - self._started

    @property
    def pending_bytes(self) -> int:
        """Bytes of waiting one-shots (stream values are bounded by the number of devices)."""
        return self._oneshot_bytes

    def put_latest(self, device: str, frame: Frame) -> None:
        # A replaced value keeps its place in the queue, so a device updated at 1 kHz
        # cannot starve a slower one queued before it.
        if device in self._latest:
            self.coalesced += 1
        self._latest[device] = frame

    def put_once(self, *parts: Buffer) -> None:
        """One frame's bytes (in consecutive parts, each kept as it is, not copied)."""
        size = sum(len(part) for part in parts)
        if self._oneshot_bytes + size > self._max_oneshot_bytes:
            raise OutboxOverflow(self._max_oneshot_bytes, self._oneshot_bytes + size)
        self._oneshots.append(list(parts))
        self._oneshot_bytes += size

    def discard(self, device: str) -> None:
        self._latest.pop(device, None)

    def pop(self, limit: Optional[int] = None) -> Optional[Buffer]:
        """The next bytes to write: one-shots first (replies are awaited), then streams.
        With ``limit``, at most that many: the rest of a frame stays first in line (a
        frame is never interleaved with another)."""
        if not self._oneshots and self._latest:
            frame = self._latest.popitem(last=False)[1]
            parts = frame.encoded_parts(self._header_version())
            if limit is None or sum(len(part) for part in parts) <= limit:
                return parts[0] if len(parts) == 1 else b"".join(parts)
            self._oneshots.append(list(parts))  # written in turn, before anything else
            self._oneshot_bytes += sum(len(part) for part in parts)
        if not self._oneshots:
            return None
        head = self._oneshots[0]
        data = head[0]
        if limit is not None and len(data) > limit:
            view = memoryview(data)
            head[0] = view[limit:]
            self._oneshot_bytes -= limit
            self._started = True
            return view[:limit]
        del head[0]
        self._oneshot_bytes -= len(data)
        if head:
            self._started = True
        else:
            self._oneshots.popleft()
            self._started = False
        return data

    def clear(self) -> None:
        """Drop every waiting frame (the client is gone)."""
        self._latest.clear()
        self._oneshots.clear()
        self._oneshot_bytes = 0
        self._started = False
