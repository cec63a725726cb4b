"""A subscriber's message stream (``create_subscriber`` with ``messages``): the clients
that asked get the topic's newest message whole, as generic JSON, at most `DISPLAY_HZ`
times a second.

A whole message is made when it is due, not for every message: what it is read for (a
message object in a script, YAML in a GUI) is read at display rate, and a 1 kHz stream
then costs about 60 conversions a second. The topic's native stream (TRANSFORM, STRING...)
still goes out per message by its own route, a pose's C lane included. Each whole message
carries the subscription's own count (``KEY_COUNT``), so a client's GetNumberOfMessages
stays exact.

One thread serves every bridge (`WholeMessages`). A bridge that took a message in Python
pokes it: the stream's newest goes at once if its last went out a frame ago or more (a lone
message waits for nothing), else at the next frame. Messages a lane wrote in C poke
nothing: while any client listens, a stream a lane feeds is looked at once a frame.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

from bridge.core.hub import Hub, StreamChannel, frame_for
from bridge.core.logging_limits import RateLimitedLog
from bridge.core.threads import OnFailure, start_thread
from protocol.commands import DISPLAY_HZ
from protocol.conversions import igtl_stamp_or_now, igtl_timestamp_now
from protocol.messages import Message, document_body
from protocol.naming import KEY_COUNT

__all__ = ["DISPLAY_HZ", "Document", "WholeMessages", "WholeStream"]

log = logging.getLogger(__name__)

_FRAME_S = 1.0 / DISPLAY_HZ

# A whole message: its generic JSON, and its header stamp (sec, nanosec), None without one.
Document = tuple[str, Optional[tuple[int, int]]]


@dataclass(eq=False)
class WholeStream:
    """One bridge's message stream. `count` gives the subscription's count; `newest` its
    newest message as generic JSON with its header stamp (None: the type has none), or None
    when it was too large to keep."""

    channel: StreamChannel
    metadata: dict[str, str]
    count: Callable[[], int]
    newest: Callable[[], Optional[Document]]
    polled: bool = False  # messages may come without a poke (a lane writes them in C)
    sent_count: int = 0
    sent_at: float = -_FRAME_S
    poked: bool = False
    _pacer: Optional[WholeMessages] = field(default=None, repr=False)

    def poke(self) -> None:
        """A ROS thread took a message for this stream (cheap after the first: one flag)."""
        if not self.poked and self._pacer is not None:
            self.poked = True
            self._pacer.wake()

    def close(self) -> None:
        pacer = self._pacer
        if pacer is not None:
            pacer.remove(self)

    def message(self, count: int, document: Document) -> Message:
        text, stamp = document
        metadata = dict(self.metadata)
        metadata[KEY_COUNT] = str(count)
        timestamp = (igtl_stamp_or_now(*stamp) if stamp is not None
                     else igtl_timestamp_now())
        return Message(device_name=self.channel.device, body=document_body(text),
                       timestamp=timestamp, metadata=metadata)


class WholeMessages:
    """The pacing thread of every message stream; started with the first stream."""

    def __init__(self, hub: Hub) -> None:
        self._hub = hub
        self._streams: list[WholeStream] = []
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closed = False
        self._thread: Optional[threading.Thread] = None
        self._bad = RateLimitedLog(log)

    def add(self, stream: WholeStream) -> None:
        with self._lock:
            stream._pacer = self
            self._streams.append(stream)
            if self._thread is None and not self._closed:
                self._thread = start_thread("whole-messages", self._run, OnFailure.RESTART)
        self._wake.set()

    def remove(self, stream: WholeStream) -> None:
        with self._lock:
            stream._pacer = None
            if stream in self._streams:
                self._streams.remove(stream)

    def wake(self) -> None:
        self._wake.set()

    def close(self) -> None:
        with self._lock:
            self._closed = True
            self._streams.clear()
        self._wake.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)

    def _run(self) -> None:
        timeout: Optional[float] = None
        while True:
            self._wake.wait(timeout)
            self._wake.clear()
            with self._lock:
                if self._closed:
                    return
                streams = tuple(self._streams)
            timeout = None
            for stream in streams:
                wait = self._serve(stream)
                if wait is not None:
                    timeout = wait if timeout is None else min(timeout, wait)

    def _serve(self, stream: WholeStream) -> Optional[float]:
        """Send `stream`'s newest if it is new and due; how long until it should be looked
        at again (None: only when poked)."""
        if not self._hub.has_audience(stream.channel.device):
            stream.poked = False
            return None
        now = time.monotonic()
        wait = stream.sent_at + _FRAME_S - now
        if wait > 0:
            return wait
        stream.poked = False  # a message taken from here on pokes again
        count = stream.count()
        if count != stream.sent_count:
            stream.sent_count = count
            stream.sent_at = now
            self._post(stream, count)
        return _FRAME_S if stream.polled else None  # a lane's messages poke nothing

    def _post(self, stream: WholeStream, count: int) -> None:
        try:
            document = stream.newest()
            if document is None:
                return
            message = stream.message(count, document)
        except Exception as error:  # noqa: BLE001 - bytes rclpy cannot read: one line, go on
            self._bad.warning(stream.channel.device, None, "the whole message on %s is "
                              "not sent: %s", stream.channel.device, error)
            return
        self._hub.post_frame(stream.channel, frame_for(message))
