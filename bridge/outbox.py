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
from typing import Any, Callable, Optional

from protocol.framing import Decoder, StreamTemplate, encode
from protocol.messages import Body, Message

__all__ = ["BulkFrame", "Frame", "Outbox", "OutboxOverflow", "TemplateFrame"]


class Frame:
    """A message to send, encoded at most once per header version.

    Clients differ in the header version they can read (OpenIGTLink 1.11 peers need v1,
    3D Slicer takes v2 with metadata), so the bytes are made lazily and cached per version:
    one encode serves every client of that version.
    """

    __slots__ = ("_message", "_encoded")

    def __init__(self, message: Message) -> None:
        self._message = message
        self._encoded: dict[int, bytes] = {}

    @property
    def message(self) -> Message:
        return self._message

    def encoded(self, header_version: int) -> bytes:
        data = self._encoded.get(header_version)
        if data is None:
            data = encode(self.message, header_version=header_version)
            self._encoded[header_version] = data
        return data


class BulkFrame(Frame):
    """A large message (an image, a point cloud) kept, once encoded, as its header-v2
    bytes alone.

    The hub keeps each device's newest value for clients that connect later: holding the
    body's arrays beside their encoding would keep a 20 MB cloud twice. v2 bytes carry
    everything (metadata too), so a v1 peer's bytes or the `Message` (a GET_ query) are
    made from them again when asked for, which is rare, and not kept."""

    __slots__ = ()
    _KEPT_VERSION = 2

    @property
    def message(self) -> Message:
        if self._message is not None:
            return self._message
        data = self._encoded[self._KEPT_VERSION]
        decoder = Decoder(max_body_size=len(data))
        decoder.feed(data)
        message = decoder.next_message()
        assert message is not None, "a frame's own bytes decode"
        return message

    def encoded(self, header_version: int) -> bytes:
        kept = self._encoded.get(self._KEPT_VERSION)
        if kept is None:
            kept = encode(self._message, header_version=self._KEPT_VERSION)
            self._encoded[self._KEPT_VERSION] = kept
            self._message = None  # type: ignore[assignment]
        if header_version == self._KEPT_VERSION:
            return kept
        return encode(self.message, header_version=header_version)


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
        self._template = template
        self._content = content
        self._timestamp = timestamp
        self._values = values
        self._body_of = body_of

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
            data = self._template.encode(self._content, self._timestamp, header_version)
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
        self._oneshots: deque[bytes] = deque()
        self._oneshot_bytes = 0
        self.coalesced = 0  # older values replaced before they were sent

    def __len__(self) -> int:
        return len(self._latest) + len(self._oneshots)

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

    def put_once(self, data: bytes) -> None:
        if self._oneshot_bytes + len(data) > self._max_oneshot_bytes:
            raise OutboxOverflow(self._max_oneshot_bytes, self._oneshot_bytes + len(data))
        self._oneshots.append(data)
        self._oneshot_bytes += len(data)

    def discard(self, device: str) -> None:
        self._latest.pop(device, None)

    def pop(self) -> Optional[bytes]:
        """The next frame to write: one-shots first (replies are awaited), then streams."""
        if self._oneshots:
            data = self._oneshots.popleft()
            self._oneshot_bytes -= len(data)
            return data
        if self._latest:
            return self._latest.popitem(last=False)[1].encoded(self._header_version())
        return None

    def clear(self) -> None:
        """Drop every waiting frame (the client is gone)."""
        self._latest.clear()
        self._oneshots.clear()
        self._oneshot_bytes = 0
