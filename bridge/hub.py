"""The daemon-wide switch between ROS-side bridges and connected OpenIGTLink clients.

Bridges are daemon-wide, as with an OpenIGTLink server in 3D Slicer: every client receives
every streamed device, and a client that connects gets the current state at once (the
newest value of each streamed device, and every persistent one-shot such as a robot mesh).

Threads: the asyncio loop owns all state here. ROS callbacks run in the executor's thread
and hand off through `post`: small messages queue in order (bounded), large ones (images,
point clouds) replace their device's waiting one, and the loop is woken at most once per
batch, so a burst of ROS messages costs one wake-up and each client gets the whole batch
in one socket write. A fast client receives every small message; only a slow client's own
outbox replaces its unsent values with newer ones.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections import deque
from typing import Callable, Protocol

from bridge.outbox import Frame
from protocol.messages import Message

log = logging.getLogger(__name__)

# Small stream messages waiting for the loop thread, in order: about 1 s at 4 kHz.
MAX_PENDING = 4096
# Larger messages (images, point clouds) are not queued: while the loop is behind, a newer
# one replaces the one waiting for its device, as a stale frame is not worth its encoding.
LARGE_MESSAGE_BYTES = 64 * 1024


def approximate_size(message: Message) -> int:
    """A cheap estimate of a message's encoded size, for bounding queues."""
    body = message.body
    for name in ("pixels", "points"):
        array = getattr(body, name, None)
        nbytes = getattr(array, "nbytes", None)
        if nbytes is not None:
            return int(nbytes) + 256
    text = getattr(body, "text", None)
    return len(text) + 256 if isinstance(text, str) else 256


class Subscriber(Protocol):
    """What the hub needs of a connected client (implemented by `ClientSession`)."""

    def send_stream(self, device: str, frame: Frame) -> None: ...
    def send_once(self, frame: Frame) -> None: ...
    def forget_device(self, device: str) -> None: ...
    def describe(self) -> dict[str, object]: ...
    def begin_batch(self) -> None: ...
    def end_batch(self) -> None: ...


class Replier(Protocol):
    """The client a message came from, to answer it."""

    def send_status(self, device: str, code: int, text: str) -> None: ...
    def send_message(self, message: Message) -> None: ...


InboundHandler = Callable[[Message, Replier], None]
# A client's RTS_COMMAND (a reply to a COMMAND the daemon sent it), and a client leaving.
ReplyListener = Callable[[Message, Replier], None]
ClosedListener = Callable[[Replier], None]


class Hub:
    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self.clients: set[Subscriber] = set()
        self._latest: dict[str, Frame] = {}
        self._persistent: dict[str, Frame] = {}
        self._inbound: dict[str, InboundHandler] = {}
        self._reply_listeners: list[ReplyListener] = []
        self._closed_listeners: list[ClosedListener] = []
        # Rate caps: device -> minimum seconds between two sends, and what they hold back.
        self._min_interval: dict[str, float] = {}
        self._last_sent: dict[str, float] = {}
        self._held: dict[str, Message] = {}
        # Hand-off from other threads.
        self._lock = threading.Lock()
        self._incoming: deque[Message] = deque()
        self._incoming_large: dict[str, Message] = {}
        self._wake_pending = False
        self.dropped = 0  # stream values replaced or dropped before the loop took them
        self.streamed = 0

    # --- clients -------------------------------------------------------------------------
    def attach(self, client: Subscriber) -> None:
        self.clients.add(client)
        for frame in self._persistent.values():
            client.send_once(frame)
        for device, frame in self._latest.items():
            client.send_stream(device, frame)

    def detach(self, client: Subscriber) -> None:
        self.clients.discard(client)

    # --- outbound (loop thread) ------------------------------------------------------------
    def stream(self, message: Message) -> None:
        """Send the newest value of a streamed device to every client, respecting its cap."""
        device = message.device_name
        interval = self._min_interval.get(device)
        if interval:
            now = time.monotonic()
            wait = self._last_sent.get(device, 0.0) + interval - now
            if wait > 0:
                if device not in self._held:
                    self._loop.call_later(wait, self._release_held, device)
                self._held[device] = message
                return
            self._last_sent[device] = now
        frame = Frame(message)
        self._latest[device] = frame
        self.streamed += 1
        for client in tuple(self.clients):
            client.send_stream(device, frame)

    def _release_held(self, device: str) -> None:
        message = self._held.pop(device, None)
        if message is not None:
            self.stream(message)

    def publish_persistent(self, message: Message) -> None:
        """A one-shot every client gets once per connection (a mesh); replaces an older one."""
        frame = Frame(message)
        self._persistent[message.device_name] = frame
        for client in tuple(self.clients):
            client.send_once(frame)

    def set_rate_cap(self, device: str, max_hz: float | None) -> None:
        if max_hz:
            self._min_interval[device] = 1.0 / max_hz
        else:
            self._min_interval.pop(device, None)

    def forget(self, device: str) -> None:
        """A bridge was removed: new clients no longer get its last value, and what it
        posted that the loop has not taken yet is dropped (it would bring the device back)."""
        with self._lock:
            if any(m.device_name == device for m in self._incoming):
                self._incoming = deque(m for m in self._incoming if m.device_name != device)
            self._incoming_large.pop(device, None)
        self._latest.pop(device, None)
        self._persistent.pop(device, None)
        self._held.pop(device, None)
        self._min_interval.pop(device, None)
        self._last_sent.pop(device, None)
        for client in tuple(self.clients):
            client.forget_device(device)

    def latest(self, device: str) -> Message | None:
        frame = self._latest.get(device) or self._persistent.get(device)
        return frame.message if frame else None

    def devices(self) -> list[str]:
        return sorted(set(self._latest) | set(self._persistent))

    # --- inbound ---------------------------------------------------------------------------
    def route(self, device: str, handler: InboundHandler) -> None:
        """Messages clients send to `device` go to `handler(message, client)`."""
        self._inbound[device] = handler

    def unroute(self, device: str) -> None:
        self._inbound.pop(device, None)

    def inbound_handler(self, device: str) -> InboundHandler | None:
        return self._inbound.get(device)

    # --- replies to the daemon's own COMMANDs, clients leaving (loop thread) -------------
    def add_reply_listener(self, listener: ReplyListener) -> None:
        """`listener(message, client)` gets every RTS_COMMAND clients send (it matches the
        command ids it is waiting for and ignores the rest)."""
        self._reply_listeners.append(listener)

    def add_closed_listener(self, listener: ClosedListener) -> None:
        """`listener(client)` runs when a client's connection is gone."""
        self._closed_listeners.append(listener)

    def deliver_reply(self, message: Message, client: Replier) -> None:
        for listener in tuple(self._reply_listeners):
            try:
                listener(message, client)
            except Exception:  # one capability's bug must not starve the others
                log.exception("a reply listener failed on %s", message.device_name)

    def client_closed(self, client: Replier) -> None:
        for listener in tuple(self._closed_listeners):
            try:
                listener(client)
            except Exception:
                log.exception("a closed-client listener failed")

    # --- hand-off from other threads -----------------------------------------------------
    def post(self, message: Message) -> None:
        """Thread-safe `stream`. Small messages queue in order; if the loop falls
        `MAX_PENDING` behind, the oldest go first. A large message replaces its device's
        waiting one. Memory stays bounded and the newest value always arrives."""
        large = approximate_size(message) > LARGE_MESSAGE_BYTES
        with self._lock:
            if large:
                if self._incoming_large.pop(message.device_name, None) is not None:
                    self.dropped += 1
                self._incoming_large[message.device_name] = message
            else:
                if len(self._incoming) >= MAX_PENDING:
                    self._incoming.popleft()
                    self.dropped += 1
                self._incoming.append(message)
            if self._wake_pending:
                return
            self._wake_pending = True
        try:
            self._loop.call_soon_threadsafe(self._drain)
        except RuntimeError:  # the loop closed during shutdown: nobody to send to
            pass

    def call_soon(self, callback: Callable[..., object], *args: object) -> None:
        """Run `callback(*args)` on the loop thread (from any thread)."""
        try:
            self._loop.call_soon_threadsafe(callback, *args)
        except RuntimeError:
            pass

    def _drain(self) -> None:
        with self._lock:
            batch, self._incoming = self._incoming, deque()
            large, self._incoming_large = self._incoming_large, {}
            self._wake_pending = False
        clients = tuple(self.clients)
        for client in clients:
            client.begin_batch()
        try:
            for message in batch:
                self.stream(message)
            for message in large.values():
                self.stream(message)
        finally:
            for client in clients:
                client.end_batch()
