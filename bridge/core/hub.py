"""The daemon-wide switch between ROS-side bridges and connected OpenIGTLink clients.

Bridges are daemon-wide, as with an OpenIGTLink server in 3D Slicer: every client receives
every streamed device, except a device with an audience. A bridge's devices (a capability
reports each, `bridge_device`) go to that bridge's audience, which the dispatcher derives
from who holds it (`set_bridge_audience`; docs/security.md, "Who owns a bridge"): a
client's bridge to its live holders, the operator's and kept ones to every client. A
client's own message stream goes to the clients that joined it (`join`). A client that
reads a subscriber's messages whole (message objects) may decline the topic's values
(`set_declined`): it then gets the device's condition (stale, live) but none of its values,
so it takes each message once, not twice. A client that
is added to an audience gets the device's current state at once, and a client that
connects gets the current state at once (the newest value of each streamed device, and
every persistent one-shot such as a robot mesh), except what a late ROS subscriber would
not get either: a large value (an image, a point cloud) of a volatile topic is not kept
once sent (`set_volatile`), as it may be tens of MB and the next one is on its way.
Whether a message is large is decided in one place, `is_large`.

Threads: the asyncio loop owns the clients and their buffers. ROS callbacks run in an
executor thread and hand values over through a `StreamChannel` (`post_frame`):

* the hot path: a value, with nothing waiting for the loop, is written from the executor
  thread to each client that keeps up, under that client's write lock
  (`Subscriber.write_direct`): no loop wake-up per message. A large one (an image) goes
  as its parts, its pixels from where they lie in the ROS message, and the kernel may
  hold it whole. A client that is behind gets the value through the loop instead
  (`hand_over`: in order, one wake-up for all handed meanwhile, an image replacing its
  device's older one), into its own outbox;
* hotter still: a streamed pose taken by a native lane (native_stream.py) is converted and
  written to each client of its audience (the lane's own slots) without the interpreter
  (to all of them in one system call, where io_uring is allowed), while they keep up and
  nothing waits for the loop (`fanout.hold`); otherwise it takes the path above;
* otherwise small values queue in order (bounded), large ones (images, point clouds)
  replace their device's waiting one, and the loop is woken at most once per batch, so a
  burst costs one wake-up and each client gets the whole batch in one socket write.

A client that keeps up receives every small message in order; only a slow client's own
outbox replaces its unsent values with newer ones. Behind means its kernel holds more
than `session.KERNEL_UNSENT_BYTES` unsent (TCP_NOTSENT_LOWAT): beyond what its own socket
buffer and the network hold, a client's backlog is the newest value of each device.

A closed channel drops what is posted through it, so a callback still running when its
bridge is removed cannot bring the device back.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections import deque
from contextlib import contextmanager
from typing import Any, Callable, Iterator, Optional, Protocol

from bridge.core.native_stream import PySlot, new_fanout, new_slot
from bridge.core.outbox import BulkFrame, Frame
from bridge.core.security import BridgeKey, WriteGrant
from protocol.crc64 import Buffer
from protocol.freshness import daemon_clock_ms
from protocol.messages import Message

log = logging.getLogger(__name__)

# Small stream messages waiting for the loop thread, in order: about 1 s at 4 kHz.
MAX_PENDING = 4096
# Larger messages (images, point clouds) are not queued: while the loop is behind, a newer
# one replaces the one waiting for its device, as a stale frame is not worth its encoding.
LARGE_MESSAGE_BYTES = 64 * 1024


def frame_for(message: Message) -> Frame:
    """The frame `message` is sent as: a `BulkFrame` if it is large (`is_large`), never
    queued behind another, kept as wire parts, not kept for later clients of a volatile
    device; otherwise a `Frame`."""
    if is_large(message):
        return BulkFrame(message)
    return Frame(message)


def is_large(message: Message) -> bool:
    """The one place that decides whether a message is large (see `frame_for`); a hot path
    that makes its own `BulkFrame`s makes them only for messages it says are."""
    return approximate_size(message) > LARGE_MESSAGE_BYTES


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
    # Direct writes from another thread (see `Hub.post_frame`).
    @property
    def header_version(self) -> int: ...
    def write_direct(self, data: bytes | tuple[Buffer, ...]) -> bool: ...
    @property
    def slot(self) -> Any: ...  # native_stream's Slot
    def hand_over(self, device: str, frame: Frame) -> None: ...


class Replier(Protocol):
    """The client a message came from, to answer it, and what that connection may do."""

    grant: WriteGrant  # may it change ROS, and why not
    challenge: Optional[str]  # the one its hello reply gave, until a key answers it
    reads_stamps: bool  # its hello said it drops late stream values itself

    def send_status(self, device: str, code: int, text: str) -> None: ...
    def send_message(self, message: Message) -> None: ...
    def granted(self, grant: WriteGrant) -> None: ...
    def start_heartbeat(self, interval: float) -> None: ...
    def pace_display(self, hz: float) -> None: ...


InboundHandler = Callable[[Message, Replier], None]
# A client's RTS_COMMAND (a reply to a COMMAND the daemon sent it), and a client leaving.
ReplyListener = Callable[[Message, Replier], None]
ClosedListener = Callable[[Replier], None]


class Hub:
    def __init__(self, loop: asyncio.AbstractEventLoop, *, direct_writes: bool = True,
                 send_batch: bool = True) -> None:
        """``send_batch``: the native lanes write a message to every client in one system
        call where the system allows (`native_stream.new_fanout`)."""
        self._loop = loop
        self._direct_writes = direct_writes
        self.clients: set[Subscriber] = set()
        self._client_tuple: tuple[Subscriber, ...] = ()  # what other threads iterate
        self._latest: dict[str, Frame] = {}
        self._volatile: set[str] = set()  # devices whose newest large value is not kept
        self._persistent: dict[str, Frame] = {}
        # A device's condition while it is not normal (a stale stream's STATUS): sent to
        # its clients when it changes, and to a client that connects or joins later.
        self._condition: dict[str, Frame] = {}
        # Who gets each device (`_refresh`), from the two sources below: devices that go
        # only to the clients listed (may be none); a device not listed goes to every
        # client. Tuples, replaced whole: other threads iterate them.
        self._audience: dict[str, tuple[Subscriber, ...]] = {}
        # Devices that go to the clients that `join` them (a client's message stream).
        self._joined: dict[str, tuple[Subscriber, ...]] = {}
        # Clients of a device's audience that take none of its values (`set_declined`).
        self._declined: dict[str, tuple[Subscriber, ...]] = {}
        # A bridge's audience (None: every client) and the bridges each device is of.
        self._bridges: dict[BridgeKey, Optional[tuple[Subscriber, ...]]] = {}
        self._device_bridges: dict[str, tuple[BridgeKey, ...]] = {}
        self._inbound: dict[str, InboundHandler] = {}
        self._reply_listeners: list[ReplyListener] = []
        self._closed_listeners: list[ClosedListener] = []
        # Rate caps: device -> minimum seconds between two sends, and what they hold back.
        self._min_interval: dict[str, float] = {}
        self._last_sent: dict[str, float] = {}
        self._held: dict[str, Frame] = {}
        # Hand-off from other threads.
        self._lock = threading.Lock()
        self._incoming: deque[tuple[str, Frame]] = deque()
        self._incoming_large: dict[str, Frame] = {}
        self._wake_pending = False
        self._draining = False
        self._batching = False
        self.dropped = 0  # stream values replaced or dropped before the loop took them
        self.streamed = 0
        self.batches = 0  # loop wake-ups that took posted values: streamed / batches per wake
        self.direct = 0  # values written to every client from the posting thread
        # The native lanes' clients (None where they are not built) and lanes: device ->
        # (lane, what makes a `Frame` of its `latest()`).
        self.fanout = new_fanout(batch=send_batch)
        self._lanes: dict[str, tuple[Any, Callable[[Any], Frame]]] = {}
        # Clients paced to a display (bridge/core/display.py): no lane writes to them.
        self._paced: set[Subscriber] = set()

    def send_mode(self) -> str:
        """How streamed values reach the clients, for the start-up log."""
        if self.fanout is None:
            return "from the loop (the native lane is not built here)"
        if self.fanout.batched:
            return "one io_uring call for all clients at a time (--send-batch on)"
        return ("one sendmsg per client (--send-batch off, or io_uring not allowed here)")

    # --- clients -------------------------------------------------------------------------
    def attach(self, client: Subscriber) -> None:
        # Under the hand-off lock: a direct write of a newer value cannot pass the current
        # state on its way to the new client.
        with self._lock:
            self.clients.add(client)
            self._client_tuple = tuple(self.clients)
            newest = self._set_slots()  # from now on the lanes see it (closed until it keeps up)
            for device, frame in self._persistent.items():
                if self._gets(client, device):
                    client.send_once(frame)
            for device, frame in newest.items():
                if self._gets_values(client, device):
                    client.send_stream(device, frame)
            for device, frame in self._condition.items():
                if self._gets(client, device):
                    client.send_once(frame)

    def detach(self, client: Subscriber) -> None:
        with self._lock:
            self.clients.discard(client)
            self._paced.discard(client)
            self._client_tuple = tuple(self.clients)
            for device, members in tuple(self._audience.items()):
                if client in members:
                    self._audience[device] = _without(members, client)
            for device, members in tuple(self._joined.items()):
                if client in members:
                    self._joined[device] = _without(members, client)
            for device, members in tuple(self._declined.items()):
                if client in members:
                    self._declined[device] = _without(members, client)
                    if not self._declined[device]:
                        del self._declined[device]
            for key, audience in tuple(self._bridges.items()):
                if audience is not None and client in audience:
                    self._bridges[key] = _without(audience, client)
            self._set_slots()

    # --- audiences (loop thread) -------------------------------------------------------------
    def limit_to_audience(self, device: str) -> None:
        """From now on `device` goes only to the clients that `join` it (none yet)."""
        with self._lock:
            self._joined.setdefault(device, ())
            self._refresh((device,))

    def join(self, device: str, client: Subscriber) -> None:
        """Stream `device` (limited to an audience) to `client` too; it gets the newest
        value at once, as a client that connects gets the others'."""
        with self._lock:
            members = self._joined.get(device, ())
            if client not in members:
                self._joined[device] = (*members, client)
                self._refresh((device,))

    def leave(self, device: str, client: Subscriber) -> None:
        with self._lock:
            members = self._joined.get(device)
            if members is not None and client in members:
                self._joined[device] = _without(members, client)
                self._refresh((device,))

    def set_declined(self, device: str, client: Subscriber, declined: bool) -> None:
        """`client` takes none of `device`'s values from now on (True: it reads the
        subscriber's messages whole instead), or takes them again (False: it gets the
        newest at once). Its audience, and so the device's condition, stay as they are."""
        with self._lock:
            members = self._declined.get(device, ())
            if declined == (client in members):
                return
            if declined:
                self._declined[device] = (*members, client)
            else:
                rest = _without(members, client)
                if rest:
                    self._declined[device] = rest
                else:
                    del self._declined[device]
            if device in self._lanes:
                if not declined:
                    _close_slot(client)  # no lane value may pass its catching up
                self._update_lane(device)
            if not declined and client in self.clients and self._gets(client, device):
                frame = self._newest(device)
                if frame is not None:
                    client.send_stream(device, frame)

    def bridge_device(self, key: BridgeKey, device: str) -> None:
        """`device` streams for the bridge `key`: the one hook through which a capability
        reports each device of its bridges (when it registers the device's name). It goes
        to the bridge's audience (`set_bridge_audience`); a device of several bridges (a
        frame several marker topics use) to each of theirs."""
        with self._lock:
            keys = self._device_bridges.get(device, ())
            if key not in keys:
                self._device_bridges[device] = (*keys, key)
                self._refresh((device,))

    def set_bridge_audience(self, key: BridgeKey,
                            members: Optional[tuple[Subscriber, ...]]) -> None:
        """Who gets the devices of the bridge `key` from now on (None: every client); the
        dispatcher's, from who holds the bridge. A client added gets each device's
        current state at once. A bridge the dispatcher never named (no dispatcher: a
        test's, a player's) goes to every client."""
        with self._lock:
            self._bridges[key] = members
            self._refresh(tuple(d for d, keys in self._device_bridges.items() if key in keys))

    def drop_bridge(self, key: BridgeKey) -> None:
        """The bridge `key` is gone: its devices (those another bridge shares) are no
        longer its."""
        with self._lock:
            self._bridges.pop(key, None)
            devices = []
            for device, keys in tuple(self._device_bridges.items()):
                if key in keys:
                    rest = tuple(k for k in keys if k != key)
                    if rest:
                        self._device_bridges[device] = rest
                    else:
                        del self._device_bridges[device]
                    devices.append(device)
            self._refresh(devices)

    def audience(self, device: str) -> tuple[Subscriber, ...]:
        """The clients that get `device` now."""
        return self._recipients(device)

    def _derived(self, device: str) -> Optional[tuple[Subscriber, ...]]:
        """Who may get `device` (None: every client): the clients that joined it, or the
        union of its bridges' audiences (every client once one of them goes to all)."""
        joined = self._joined.get(device)
        if joined is not None:
            return joined
        keys = self._device_bridges.get(device)
        if not keys:
            return None
        members: dict[Subscriber, None] = {}
        for key in keys:
            audience = self._bridges.get(key)
            if audience is None:
                return None
            members.update(dict.fromkeys(audience))
        return tuple(members)

    def _refresh(self, devices: tuple[str, ...] | list[str]) -> None:
        """Under the hand-off lock: `devices`' audiences as derived now; a client they
        gained gets each one's current state at once (its lanes' subsets hold the fanout,
        so no lane writes meanwhile)."""
        for device in devices:
            before = self._recipients(device)
            members = self._derived(device)
            if members is None:
                self._audience.pop(device, None)
            else:
                self._audience[device] = members
            gained = [c for c in self._recipients(device)
                      if c not in before and c in self.clients]
            if device in self._lanes:
                for client in gained:  # no lane value may pass its catching up
                    _close_slot(client)
            self._update_lane(device)
            for client in gained:
                self._catch_up(client, device)

    def _catch_up(self, client: Subscriber, device: str) -> None:
        """`client` gets `device` from now on: its current state at once, as a client that
        connects gets it."""
        persistent = self._persistent.get(device)
        if persistent is not None:
            client.send_once(persistent)
        frame = self._newest(device) if self._gets_values(client, device) else None
        if frame is not None:
            client.send_stream(device, frame)
        condition = self._condition.get(device)
        if condition is not None:
            client.send_once(condition)

    def _gets(self, client: Subscriber, device: str) -> bool:
        """Is `client` of `device`'s audience (its condition, its one-shots)?"""
        members = self._audience.get(device)
        return members is None or client in members

    def _gets_values(self, client: Subscriber, device: str) -> bool:
        """Does `client` get `device`'s values (of its audience, and not declined)?"""
        return self._gets(client, device) and client not in self._declined.get(device, ())

    def set_paced(self, client: Subscriber) -> None:
        """`client` takes its streams once a display frame (`lane_news` included, what its
        audiences give it): the lanes write to the others only."""
        with self._lock:
            self._paced.add(client)
            self._set_slots()

    # --- native lanes ------------------------------------------------------------------------
    def _set_slots(self) -> dict[str, Frame]:
        """Under the hand-off lock: the lanes write to the clients attached now (but the
        paced ones); returns the newest value of every device, lanes' included, as of
        that moment."""
        if self.fanout is None:
            return dict(self._latest)
        newest = dict(self._latest)
        with self.fanout:
            self.fanout.set_slots(self._lane_slots(self._client_tuple))
            for device, (lane, to_frame) in self._lanes.items():
                self._set_lane(device, lane)
                latest = lane.latest()
                if latest is not None:
                    newest[device] = to_frame(latest)
        return newest

    def _lane_slots(self, clients: tuple[Subscriber, ...]) -> list[Any]:
        """The native slots a lane writes to for `clients`: the paced ones' not (they take
        `lane_news`). A client without a native slot (a test's) stays closed: the lanes
        then leave every message to the Python path."""
        slots = [getattr(c, "slot", None) for c in clients if c not in self._paced]
        return [s if s is not None and not isinstance(s, PySlot) else _closed_slot()
                for s in slots]

    def add_lane(self, device: str, lane: Any, to_frame: Callable[[Any], Frame]) -> None:
        """`device`'s values may be written by a native lane (`PoseLane`) from now on, when
        nothing about the device needs the Python path (a bound), to its audience.
        `to_frame` runs holding the fanout, so the lane's template cannot change under it."""
        with self._lock:
            self._lanes[device] = (lane, to_frame)
            self._update_lane(device)

    def remove_lane(self, device: str) -> None:
        """The lane writes no more (once this returns); its newest value becomes the hub's."""
        with self._lock:
            entry = self._lanes.pop(device, None)
            if entry is None or self.fanout is None:
                return
            lane, to_frame = entry
            with self.fanout:
                lane.enabled = False
                latest = lane.latest()
                if latest is not None:
                    self._latest[device] = to_frame(latest)

    def lane_news(self, seen: dict[str, int],
                  client: Subscriber) -> list[tuple[str, Frame]]:
        """The newest value of each writing lane `client` gets whose count moved since
        `seen` (which this updates): what a paced client, which no lane writes to, takes
        at its frame."""
        if self.fanout is None:
            return []
        news = []
        with self.fanout:  # no template changes meanwhile
            for device, (lane, to_frame) in tuple(self._lanes.items()):
                count = int(lane.count)
                if (not lane.enabled or seen.get(device) == count
                        or not self._gets_values(client, device)):
                    continue
                seen[device] = count
                latest = lane.latest()
                if latest is not None:  # else the Python path took a later one: handed over
                    news.append((device, to_frame(latest)))
        return news

    def _update_lane(self, device: str) -> None:
        """`device`'s lane writes unless it is bound, to its audience (its own slots) or
        to every client (the fanout's)."""
        entry = self._lanes.get(device)
        if entry is None or self.fanout is None:
            return
        with self.fanout:
            self._set_lane(device, entry[0])

    def _set_lane(self, device: str, lane: Any) -> None:
        # Holding the fanout (and the hand-off lock, but for a rate cap's change).
        members = self._audience.get(device)
        lane.enabled = device not in self._min_interval
        if members is None and device not in self._declined:
            lane.set_slots(None)  # the fanout's: every client
            return
        lane.set_slots(self._lane_slots(tuple(c for c in self._value_recipients(device)
                                              if c in self.clients)))

    def _newest(self, device: str) -> Optional[Frame]:
        entry = self._lanes.get(device)
        if entry is not None and self.fanout is not None:
            with self.fanout:  # the lane's template cannot change meanwhile
                latest = entry[0].latest()
                if latest is not None:
                    return entry[1](latest)
        return self._latest.get(device)

    def has_audience(self, device: str) -> bool:
        """Does anyone get `device` (any thread: a bridge asks before making a value)?"""
        members = self._audience.get(device)
        return members is None or bool(members)

    def _recipients(self, device: str) -> tuple[Subscriber, ...]:
        """The clients of `device`'s audience (its condition, its one-shots)."""
        members = self._audience.get(device)
        return self._client_tuple if members is None else members

    def _value_recipients(self, device: str) -> tuple[Subscriber, ...]:
        """The clients that get `device`'s values: its audience but those that declined."""
        members = self._recipients(device)
        declined = self._declined.get(device)
        if declined is None:
            return members
        return tuple(c for c in members if c not in declined and c in self.clients)

    # --- outbound (loop thread) ------------------------------------------------------------
    def stream(self, message: Message) -> None:
        """Send the newest value of a streamed device to every client, respecting its cap."""
        self.stream_frame(message.device_name, frame_for(message))

    def stream_frame(self, device: str, frame: Frame) -> None:
        """`stream` for a value already made into a `Frame` (a hot path's `TemplateFrame`)."""
        if not frame.clock:  # stamped when taken (protocol/freshness.py)
            frame.clock = daemon_clock_ms()
        if self._min_interval:
            interval = self._min_interval.get(device)
            if interval:
                now = time.monotonic()
                wait = self._last_sent.get(device, 0.0) + interval - now
                if wait > 0:
                    if device not in self._held:
                        self._loop.call_later(wait, self._release_held, device)
                    self._held[device] = frame
                    return
                self._last_sent[device] = now
        self._keep_newest(device, frame)
        self.streamed += 1
        for client in self._value_recipients(device):
            client.send_stream(device, frame)

    def _keep_newest(self, device: str, frame: Frame) -> None:
        """What a client that connects later gets of `device` (see `set_volatile`)."""
        if isinstance(frame, BulkFrame) and device in self._volatile:
            self._latest.pop(device, None)  # a later client gets no stale copy of it either
        else:
            self._latest[device] = frame

    @contextmanager
    def batch(self) -> Iterator[None]:
        """Loop thread: what is streamed inside reaches each client in one socket write
        (a tf update of many lookups, for example), not one write per message."""
        if self._batching:
            yield
            return
        self._batching = True
        clients = tuple(self.clients)
        for client in clients:
            client.begin_batch()
        try:
            yield
        finally:
            self._batching = False
            for client in clients:
                client.end_batch()

    def _release_held(self, device: str) -> None:
        frame = self._held.pop(device, None)
        if frame is not None:
            self.stream_frame(device, frame)

    def publish_persistent(self, message: Message) -> None:
        """A one-shot every client gets once per connection (a mesh); replaces an older one."""
        frame = Frame(message)
        self._persistent[message.device_name] = frame
        for client in self._recipients(message.device_name):
            client.send_once(frame)

    def set_condition(self, device: str, kept: Frame | None, sent: Frame) -> None:
        """Loop thread: tell `device`'s clients `sent` (a STATUS), and keep `kept` for
        those that come later (None: the device is back to normal)."""
        if kept is None:
            self._condition.pop(device, None)
        else:
            self._condition[device] = kept
        for client in self._recipients(device):
            client.send_once(sent)

    def set_volatile(self, device: str, volatile: bool) -> None:
        """A volatile device (a volatile ROS topic's) keeps its newest value for clients
        that connect later only while it is small: a large one (an image, a cloud; tens of
        MB, and the next is on its way) is not kept, as a late ROS subscriber would not
        get it either. Devices are not volatile by default."""
        if volatile:
            self._volatile.add(device)
            if isinstance(self._latest.get(device), BulkFrame):
                self._latest.pop(device, None)
        else:
            self._volatile.discard(device)

    def set_rate_cap(self, device: str, max_hz: float | None) -> None:
        if max_hz:
            self._min_interval[device] = 1.0 / max_hz
        else:
            self._min_interval.pop(device, None)
        self._update_lane(device)

    def forget(self, device: str) -> None:
        """A bridge was removed: new clients no longer get its last value, and what it
        posted that the loop has not taken yet is dropped (it would bring the device back)."""
        with self._lock:
            if any(d == device for d, _ in self._incoming):
                self._incoming = deque(item for item in self._incoming if item[0] != device)
            self._incoming_large.pop(device, None)
            self._latest.pop(device, None)
            lane = self._lanes.pop(device, None)
            if lane is not None and self.fanout is not None:
                with self.fanout:
                    lane[0].enabled = False
        self._persistent.pop(device, None)
        self._condition.pop(device, None)
        with self._lock:
            self._audience.pop(device, None)
            self._joined.pop(device, None)
            self._declined.pop(device, None)
            self._device_bridges.pop(device, None)
        self._volatile.discard(device)
        self._held.pop(device, None)
        self._min_interval.pop(device, None)
        self._last_sent.pop(device, None)
        for client in tuple(self.clients):
            client.forget_device(device)

    def latest(self, device: str, client: Subscriber | None = None) -> Message | None:
        """The newest value of `device`; with `client`, only if that client gets it."""
        if client is not None and not self._gets_values(client, device):
            return None
        frame = self._newest(device) or self._persistent.get(device)
        return frame.message if frame else None

    def devices(self) -> list[str]:
        with self._lock:  # another thread may add a device to _latest
            lanes = [d for d in self._lanes if self._newest(d) is not None]
            return sorted(set(self._latest) | set(self._persistent) | set(lanes))

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
    def open_channel(self, device: str) -> StreamChannel:
        """A way in for one streamed device from another thread (a ROS callback)."""
        return StreamChannel(device)

    def close_channel(self, channel: StreamChannel) -> None:
        """Nothing posted through `channel` reaches clients any more, even from a callback
        that was already running, and the device is forgotten (`forget`)."""
        with self._lock:
            channel.closed = True
        self.forget(channel.device)

    def post(self, message: Message) -> None:
        """Thread-safe `stream` (see `post_frame`)."""
        self._post(message.device_name, frame_for(message), None)

    def post_frame(self, channel: StreamChannel, frame: Frame) -> None:
        """Thread-safe `stream_frame` through an open channel.

        A value, when nothing is waiting for the loop, is written at once from this thread
        to every client that keeps up (`Subscriber.write_direct`); a client that does not
        gets it through the loop (`hand_over`), in order. Otherwise values queue
        for the loop, in order; if it falls `MAX_PENDING` behind, the oldest go first. A
        large value replaces its device's waiting one. Memory stays bounded, the newest
        value always arrives, and the loop is woken once per batch."""
        device = channel.device
        if not frame.clock:
            frame.clock = daemon_clock_ms()
        if self._direct_writes and device not in self._min_interval:
            with self._lock:
                if channel.closed:
                    return
                if not (self._wake_pending or self._draining):
                    self._write_direct(device, frame)
                    return
        self._post(device, frame, channel)

    def post_frames(self, frames: list[tuple[str, Frame]],
                    channel: StreamChannel | None = None) -> None:
        """Thread-safe `stream_frame` of several small values at once (one tf update of
        many lookups, a burst of one stream's messages taken together): each client that
        keeps up gets them in one socket write from this thread; otherwise they go through
        the loop, in order, as `post_frame`'s do. With `channel` (all of them its device's),
        nothing is sent once it is closed; without, the caller keeps removed devices out
        (the tf capability's delivery lock)."""
        if not frames:
            return
        clock = daemon_clock_ms()
        direct = self._direct_writes
        for device, frame in frames:  # a plain loop: this runs per message on hot paths
            frame.clock = frame.clock or clock
            if direct and (device in self._min_interval or isinstance(frame, BulkFrame)):
                direct = False
        if direct:
            with self._lock:
                if channel is not None and channel.closed:
                    return
                if not (self._wake_pending or self._draining):
                    self._write_direct_many(frames)
                    return
        for device, frame in frames:
            self._post(device, frame, channel)

    def _write_direct_many(self, frames: list[tuple[str, Frame]]) -> None:
        # Under self._lock, with nothing queued for the loop (see _write_direct). Each
        # client gets, in one write, those of the frames whose devices it gets.
        for device, frame in frames:
            self._latest[device] = frame
        self.streamed += len(frames)
        self.direct += len(frames)
        audience, declined = self._audience, self._declined
        limited = (bool(audience) or bool(declined)) and any(
            device in audience or device in declined for device, _ in frames)
        joined: dict[int, bytes] = {}  # header version -> the whole update, encoded once
        for client in self._client_tuple:
            mine = frames
            if limited:
                mine = [(d, f) for d, f in frames if self._gets_values(client, d)]
                if not mine:
                    continue
            version = client.header_version
            data = joined.get(version) if mine is frames else None
            if data is None:
                data = (mine[0][1].encoded(version) if len(mine) == 1
                        else b"".join(f.encoded(version) for _, f in mine))
                if mine is frames:
                    joined[version] = data
            if not client.write_direct(data):
                for device, frame in mine:
                    client.hand_over(device, frame)

    def _write_direct(self, device: str, frame: Frame) -> None:
        # Under self._lock, with nothing queued for the loop: this value is the newest.
        self._keep_newest(device, frame)
        self.streamed += 1
        self.direct += 1
        large = isinstance(frame, BulkFrame)  # its parts, never joined: pixels where they lie
        for client in self._value_recipients(device):
            version = client.header_version
            if not client.write_direct(frame.encoded_parts(version) if large
                                       else frame.encoded(version)):
                client.hand_over(device, frame)

    def _post(self, device: str, frame: Frame, channel: StreamChannel | None) -> None:
        if not frame.clock:
            frame.clock = daemon_clock_ms()
        with self._lock:
            if channel is not None and channel.closed:
                return  # the bridge is gone: its device must not come back
            if isinstance(frame, BulkFrame):
                if self._incoming_large.pop(device, None) is not None:
                    self.dropped += 1
                self._incoming_large[device] = frame
            else:
                if len(self._incoming) >= MAX_PENDING:
                    self._incoming.popleft()
                    self.dropped += 1
                self._incoming.append((device, frame))
            if self._wake_pending:
                return
            self._wake_pending = True
            self._hold_lanes(True)  # nothing may pass what waits for the loop
        try:
            self._loop.call_soon_threadsafe(self._drain)
        except RuntimeError:  # the loop closed during shutdown: nobody to send to
            pass

    @property
    def pending(self) -> int:
        """Values posted from other threads that the loop has not taken yet."""
        return len(self._incoming) + len(self._incoming_large)

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
            self._draining = True  # no direct write may pass this batch
        self.batches += 1
        try:
            with self.batch():
                stream_frame = self.stream_frame
                for device, frame in batch:
                    stream_frame(device, frame)
                for device, frame in large.items():
                    stream_frame(device, frame)
        finally:
            with self._lock:
                self._draining = False
                if not self._wake_pending:
                    self._hold_lanes(False)

    def _hold_lanes(self, hold: bool) -> None:
        # Under the hand-off lock.
        if self.fanout is not None:
            with self.fanout:
                self.fanout.hold = hold


class StreamChannel:
    """One streamed device's hand-off to the hub (`Hub.open_channel`). Once closed, what is
    posted through it is dropped: a callback still running when its bridge was removed
    cannot bring the device back."""

    __slots__ = ("device", "closed")

    def __init__(self, device: str) -> None:
        self.device = device
        self.closed = False


def _without(members: tuple[Subscriber, ...], client: Subscriber) -> tuple[Subscriber, ...]:
    return tuple(m for m in members if m is not client)


def _close_slot(client: Subscriber) -> None:
    """No lane writes to `client` until its session opens its slot again (once nothing it
    was sent waits)."""
    slot = getattr(client, "slot", None)
    if slot is not None and not isinstance(slot, PySlot):
        with slot:
            slot.open = False


def _closed_slot() -> Any:
    """A slot no lane writes to (a client the lanes cannot serve)."""
    return new_slot(None)
