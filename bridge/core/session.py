"""One connected OpenIGTLink client: reads and decodes its bytes, writes its frames.

Reading: bytes go through the sans-I/O `Decoder`. A bad message (wrong CRC, malformed
body) gets a STATUS reply naming the problem and the stream goes on; a broken stream
(malformed header, oversized body) gets a STATUS and the connection is closed. Nothing a
client sends can raise out of here into the server.

Bounds on what a client holds: a frame that has started must be complete within
``frame_deadline_s`` (plus a second per ``min_receive_rate`` bytes of its declared body),
or the connection is closed; a client that never sends is not affected. Partly received
bodies count against the daemon-wide `ReceiveBudget`. At close the receive and send
buffers are dropped at once: nothing waits for the cyclic garbage collector.

Heavy bodies: a data message (not a command, status or query) whose body is larger than
`HEAVY_BODY_BYTES` is judged by its header first (a read-only daemon, a device nobody
receives: refused before a byte of it is decoded), then decoded in the client's lane of
the daemon's `HeavyWork`, never on the loop. Meanwhile the client's later messages wait,
in order, and its socket is not read (its own sending slows down, nobody else's).

Writing: frames go straight to the transport while it keeps up; once its buffer passes the
high-water mark, they wait in the client's `Outbox`, where a newer value of a device
replaces an unsent older one.

Direct writes (the hot path): while a client keeps up (nothing waiting anywhere on its
side), the hub may write a small stream frame to its socket from the ROS executor thread
(`write_direct`), which saves the loop a wake-up per message; a native lane writes a pose
through the session's `slot` without the interpreter at all (native_stream.py). Every
write to the socket, from any thread, holds the slot, so frames never interleave; whatever
a direct write could not finish is written by the loop before anything else, and a client
that is behind is never written directly: its frames take the loop's path (`hand_over`),
in order, and meet the outbox there.
"""

from __future__ import annotations

import asyncio
import logging
import operator
import os
import socket
import struct
import time
from dataclasses import dataclass
from functools import partial
from typing import Callable, Optional

from bridge.core.display import DisplayPacing
from bridge.core.heavy import HeavyWork
from bridge.core.hub import Hub
from bridge.core.logging_limits import RateLimitedLog
from bridge.core.native_stream import BROKEN, SENT, STASHED, new_slot
from bridge.core.outbox import WRITE_CHUNK, BulkFrame, Frame, Outbox, OutboxOverflow
from bridge.core.security import WRITES, WriteGrant, is_loopback_host
from protocol.crc64 import Buffer
from protocol.errors import CrcMismatchError, FramingError, MessageError, ReceiveBudgetError
from protocol.framing import Decoder, RawFrame, ReceiveBudget
from protocol.freshness import daemon_clock_ms
from protocol.liveness import (HEARTBEAT_DEVICE, TCP_INFO_BYTES, LinkState, link_is_dead,
                                read_link, socket_options)
from protocol.messages import Message, Status, StatusCode
from protocol.negotiation import HeaderVersionNegotiator

log = logging.getLogger(__name__)

CommandHandler = Callable[[Message, "ClientSession"], None]

# A data message with a larger body is decoded off the loop (see the module docstring).
HEAVY_BODY_BYTES = 64 * 1024
# What one loop turn writes to one client from its outbox before others get a turn.
FLUSH_TURN_BYTES = 4 * WRITE_CHUNK
KERNEL_UNSENT_BYTES = 16 * 1024  # TCP_NOTSENT_LOWAT: about 100 poses
# While a large frame (a video frame, a model) is written, the kernel may take that much of
# it at once: 16 KB at a time cost a VGA frame about 1.4 ms of loop turns.
LARGE_KERNEL_UNSENT_BYTES = 4 * 1024 * 1024
MAX_HANDED = 1024  # stream values handed to the loop for one client before coalescing
# Message types that are not data for a device: commands, statuses, queries, replies.
_CONTROL_TYPES = ("COMMAND", "STATUS", "GET_", "RTS_", "STT_", "STP_")



@dataclass(frozen=True)
class SessionLimits:
    max_message_bytes: int = 64 * 1024 * 1024
    max_oneshot_bytes: int = 256 * 1024 * 1024
    # Above this many bytes in the transport's own buffer (what the kernel did not take),
    # frames wait in the outbox, where a stream's newer value replaces its older one. 1: a
    # client's backlog is never a queue of stale stream values, only the newest of each.
    write_high_water: int = 1
    # The same for a TLS connection (a project client, which drops late values itself):
    # asyncio's TLS transport with a high water of 0 or 1 left clients' replies and
    # heartbeats waiting for a resume_writing that never came.
    tls_write_high_water: int = 256 * 1024
    # How long a new client may take to show it reads header v2 (3D Slicer sends a STATUS
    # at once) before it gets the current state as v1; OpenIGTLink 1.11 peers never send.
    negotiation_grace_s: float = 0.25
    # A started frame must be complete this long after its first byte (slowloris), plus a
    # second per `min_receive_rate` bytes of its declared body (a 64 MiB body: 13 s).
    frame_deadline_s: float = 5.0
    min_receive_rate: int = 8 * 1024 * 1024
    # Bytes of partly received bodies all clients together may hold; None: twice
    # max_message_bytes, so one client can send the largest message while another does.
    receive_budget_bytes: Optional[int] = None

    def receive_budget(self) -> ReceiveBudget:
        total = self.receive_budget_bytes
        return ReceiveBudget(2 * self.max_message_bytes if total is None else total)


class ClientSession(asyncio.Protocol):
    def __init__(self, hub: Hub, commands: CommandHandler, limits: SessionLimits,
                 on_close: Callable[[ClientSession], None], *, grant: WriteGrant = WRITES,
                 budget: Optional[ReceiveBudget] = None,
                 incidents: Optional[RateLimitedLog] = None,
                 heavy: Optional[HeavyWork] = None) -> None:
        self._hub = hub
        self._heavy = heavy  # None: every body is decoded on the loop (tests)
        self._decoding = False  # a heavy body of this client is being decoded
        # May this connection change ROS (commands that write, data to publishers)? Set at
        # accept by the policy; a key presented (the authenticate op) may widen it.
        self.grant = grant
        self.challenge: Optional[str] = None  # the hello reply's, until a key answers it
        self._heartbeat: Optional[asyncio.TimerHandle] = None
        # Its hello said it drops late stream values by their stamps (a project client);
        # a plain connector shows whatever arrives, so its dead link is cut sooner.
        self.reads_stamps = False
        self._commands = commands
        self._limits = limits
        self._on_close: Optional[Callable[[ClientSession], None]] = on_close
        self._incidents = incidents or RateLimitedLog(log)  # shared by the server's sessions
        self._decoder = Decoder(max_body_size=limits.max_message_bytes,
                                budget=budget or limits.receive_budget())
        self._negotiator = HeaderVersionNegotiator()
        # Over the negotiator, not over self: a lambda over self would make a reference
        # cycle and leave a closed session (and its buffers) to the cyclic GC.
        self._outbox = Outbox(max_oneshot_bytes=limits.max_oneshot_bytes,
                              header_version=partial(operator.attrgetter("outgoing_version"),
                                                     self._negotiator))
        self._frame_timer: Optional[asyncio.TimerHandle] = None
        self.frame_started: Optional[float] = None  # loop time of an unfinished frame's start
        self._transport: Optional[asyncio.Transport] = None
        self._paused = False
        self._closing = False
        self._attached = False
        self._attach_timer: Optional[asyncio.TimerHandle] = None
        self._batch: Optional[list[Buffer]] = None  # frames gathered for one write
        self._flush_scheduled = False  # the outbox is written on from the next loop turn
        # Direct writes from other threads (see the module docstring). The slot is this
        # session's write lock, and what the native lanes write through (native_stream.py):
        # open only while nothing of this client waits anywhere. It keeps the rest of a
        # direct write taken in part, which goes before anything else.
        self.slot = new_slot(self)
        self._direct: Optional[socket.socket] = None  # a dup of the transport's socket
        # Stream values `write_direct` refused, in order, for the loop to send; `_handed` is
        # set while the loop has yet to take them (one wake-up for any number handed).
        self._handed_frames: list[tuple[str, Frame]] = []
        self._handed = False
        # A display's pacing (`pace_display`): its streams' newest values once a frame.
        self._display: Optional[DisplayPacing] = None
        self._display_timer: Optional[asyncio.TimerHandle] = None
        self._unrouted_warned: set[str] = set()
        self._bad_log = RateLimitedLog(log)
        self.peer = "?"
        self.on_loopback = False  # a loopback link cannot be pulled (protocol/liveness.py)
        self._kernel_unsent = 0  # TCP_NOTSENT_LOWAT as set (0: not yet)
        self._manages_unsent = False  # a plain TCP client's (TLS keeps the kernel's own)
        self.received = 0
        self._sent = 0

    # --- asyncio.Protocol ------------------------------------------------------------------
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport
        peer = transport.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)
        self.on_loopback = isinstance(peer, tuple) and is_loopback_host(str(peer[0]))
        sock = transport.get_extra_info("socket")
        if sock is not None and sock.family in (socket.AF_INET, socket.AF_INET6):
            # Latency matters more than packet count: no Nagle delay. A dead peer is found
            # in seconds, and what its send buffer held is dropped, not delivered late.
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            for level, option, value in socket_options():
                sock.setsockopt(level, option, value)
        tls = transport.get_extra_info("sslcontext") is not None
        transport.set_write_buffer_limits(high=self._limits.tls_write_high_water if tls
                                          else self._limits.write_high_water)
        if not tls:
            # The kernel takes little beyond what is in flight: the rest of a backlog
            # waits in the outbox, coalesced, not in the kernel as a queue of old poses.
            self._manages_unsent = True
            self._limit_kernel_unsent(KERNEL_UNSENT_BYTES)
        if sock is not None and not tls:
            # Its own descriptor: closed in connection_lost, under the write lock, before
            # the transport closes its own, so a direct write can never reach a reused fd.
            try:
                duplicate = os.dup(sock.fileno())
            except OSError as error:  # the process is out of descriptors: so is this client
                self._incidents.warning("descriptors", time.monotonic(), "client %s: %s "
                                        "(its second descriptor); closing it", self.peer,
                                        error.strerror or error)
                transport.abort()
                return
            direct = socket.socket(fileno=duplicate)
            direct.setblocking(False)
            self._direct = direct
            with self.slot:
                self.slot.connect(direct)
        log.info("client %s connected", self.peer)
        # Streams start once the header version is known: the current state sent as v1
        # would reach 3D Slicer without metadata, and meshes are sent only once.
        self._attach_timer = asyncio.get_running_loop().call_later(
            self._limits.negotiation_grace_s, self._attach)

    def _attach(self) -> None:
        if self._attached or self._closing:
            return
        self._attached = True
        if self._attach_timer is not None:
            self._attach_timer.cancel()
        self._hub.attach(self)

    def connection_lost(self, exc: Optional[Exception]) -> None:
        with self.slot:  # other threads write directly: nothing after this
            self._closing = True
            self.slot.disconnect()
            self.slot.take_stash()
            if self._direct is not None:
                self._direct.close()
                self._direct = None
            self._release()
        if self._attached:
            self._hub.detach(self)
        if self._on_close is not None:
            on_close, self._on_close = self._on_close, None
            on_close(self)
        self._hub.client_closed(self)
        self._transport = None
        log.info("client %s disconnected%s", self.peer, f" ({exc})" if exc else "")

    def _release(self) -> None:
        """Drop what the session holds (buffers, budget, timers) at once. Idempotent."""
        for timer in (self._attach_timer, self._frame_timer, self._heartbeat,
                      self._display_timer):
            if timer is not None:
                timer.cancel()
        self._attach_timer = self._frame_timer = self._heartbeat = None
        self._display_timer = None
        self.frame_started = None
        self._decoder.close()
        self._outbox.clear()
        self._batch = None
        if self._heavy is not None:
            self._heavy.forget(self)

    def pause_writing(self) -> None:
        # Called from within transport.write, which runs holding the slot (already closed).
        self._paused = True

    def resume_writing(self) -> None:
        # Called from within the transport's write handler, which goes on after this
        # returns: a write from here that fails (the client gone) made asyncio end the
        # connection twice, an error and a traceback in the log (CPython gh-156512, seen
        # in ci70). The outbox is written from the next loop turn instead.
        self._paused = False
        if not self._flush_scheduled:
            self._flush_scheduled = True
            asyncio.get_running_loop().call_soon(self._flush_turn)

    def data_received(self, data: bytes) -> None:
        if self._closing:
            return  # the rest of a stream we gave up on
        frames_before = self._decoder.frames
        try:
            self._decoder.feed(data)
        except FramingError as error:
            self._broken(error)
            return
        self._take_frames(frames_before)

    def _take_frames(self, frames_before: int) -> None:
        """Handle the complete frames received, in order, until a heavy one goes off the
        loop (`_decoded` goes on from there)."""
        try:
            while not self._closing and not self._decoding:
                frame = self._decoder.next_frame()
                if frame is None:
                    break
                if (self._heavy is not None and len(frame.body) > HEAVY_BODY_BYTES
                        and not frame.type_name.startswith(_CONTROL_TYPES)):
                    if not self._data_refused(frame.type_name, frame.device_name):
                        self._decode_off_loop(frame)
                    continue
                try:
                    message = frame.decode(self._decoder.verify_crc)
                except MessageError as error:
                    self._bad_message(error)
                    continue
                self.received += 1
                self._handle(message)
        except FramingError as error:
            self._broken(error)
        self._watch_frame(frames_before)

    def _decode_off_loop(self, frame: RawFrame) -> None:
        assert self._heavy is not None
        self._decoding = True
        if self._transport is not None:
            self._transport.pause_reading()
        verify = self._decoder.verify_crc
        self._heavy.run(self, lambda: frame.decode(verify)).add_done_callback(self._decoded)

    def _decoded(self, outcome: asyncio.Future[Message]) -> None:
        """A heavy body's decoding ended (loop thread): handle it, go on with the rest."""
        self._decoding = False
        if self._closing or outcome.cancelled():
            return
        error = outcome.exception()
        if isinstance(error, MessageError):
            self._bad_message(error)
        elif error is not None:
            log.error("decoding a message of client %s failed", self.peer, exc_info=error)
            self.send_status("", StatusCode.UNKNOWN_ERROR, f"the message could not be "
                             f"decoded: {type(error).__name__}")
        else:
            self.received += 1
            self._handle(outcome.result())
        if self._closing:
            return
        if self._transport is not None:
            self._transport.resume_reading()
        self._take_frames(self._decoder.frames)

    def _bad_message(self, error: MessageError) -> None:
        self._warn_bad_message(error)
        self.send_status(getattr(error, "device_name", "") or "", _status_of(error),
                         str(error))

    def _broken(self, error: FramingError) -> None:
        """The stream cannot go on: say why and close."""
        if isinstance(error, ReceiveBudgetError):
            self._incidents.warning("budget", time.monotonic(), "client %s: body refused, "
                                    "closing: %s", self.peer, error)
            self.send_status("", StatusCode.RESOURCE_ERROR, f"closing the connection: {error}")
        else:
            log.warning("client %s broke the OpenIGTLink framing, closing: %s", self.peer, error)
            self.send_status("", StatusCode.UNKNOWN_ERROR, f"closing the connection: {error}")
        self.close()

    def _watch_frame(self, frames_before: int) -> None:
        """Keep a deadline on the unfinished frame, if any (the decoder has no clock)."""
        decoder = self._decoder
        # While a heavy body is decoded the socket is not read: no deadline meanwhile.
        if self._closing or self._decoding or not decoder.frame_in_progress:
            if self._frame_timer is not None:
                self._frame_timer.cancel()
                self._frame_timer = None
            self.frame_started = None
            return
        loop = asyncio.get_running_loop()
        if self.frame_started is None or decoder.frames != frames_before:
            self.frame_started = loop.time()  # a new frame began in this chunk
        deadline = self.frame_started + self._frame_allowance(decoder.pending_body_size)
        if self._frame_timer is None or self._frame_timer.when() != deadline:
            if self._frame_timer is not None:
                self._frame_timer.cancel()
            self._frame_timer = loop.call_at(deadline, self._frame_overdue)

    def _frame_allowance(self, body_size: Optional[int]) -> float:
        return self._limits.frame_deadline_s + (body_size or 0) / self._limits.min_receive_rate

    def _frame_overdue(self) -> None:
        self._frame_timer = None
        if self._closing:
            return
        body = self._decoder.pending_body_size
        allowance = self._frame_allowance(body)
        what = "header" if body is None else f"{body}-byte body"
        self._incidents.warning(
            "deadline", time.monotonic(), "client %s: a frame (%s) unfinished %.1f s after its "
            "first byte, closing (--frame-deadline)", self.peer, what, allowance)
        self.send_status("", StatusCode.TIME_OUT,
                         f"closing the connection: frame deadline: expected a complete "
                         f"message within {allowance:.1f} s of its first byte, got "
                         f"{self._decoder.buffered} bytes of it")
        self.close()

    def close_stalled(self) -> None:
        """Close for a newcomer's sake: all slots are taken and this frame is unfinished."""
        if self._closing:
            return
        self.send_status("", StatusCode.RESOURCE_ERROR,
                         "closing the connection: all client slots are taken and this "
                         "connection's frame is unfinished (expected a complete message)")
        self.close()

    def _warn_bad_message(self, error: MessageError) -> None:
        """Every bad message gets its STATUS reply, but a client sending thousands must not
        flood the log: one line per interval, with the count of the others."""
        self._bad_log.warning("bad message", None, "client %s sent a bad message: %s",
                              self.peer, error)

    # --- incoming messages -----------------------------------------------------------------
    def _handle(self, message: Message) -> None:
        announced = not self._negotiator.peer_speaks_v2
        self._negotiator.observe(message)
        announced = announced and self._negotiator.peer_speaks_v2
        if not self._attached and self._negotiator.peer_speaks_v2:
            self._attach()
        elif announced and self._attached:
            with self.slot:  # frames of the old header version must not go out any more
                self.slot.open = False
            # v2 came after the grace time: the state went out as v1, without the metadata
            # 3D Slicer names and places nodes by, and meshes go once per connection.
            log.info("client %s announced header v2 late: sending the state again",
                     self.peer)
            self._hub.attach(self)
        type_name = message.type_name
        if type_name == "COMMAND":
            self._commands(message, self)
        elif type_name == "STATUS":
            pass  # 3D Slicer announces header v2 with a STATUS; the negotiator saw it
        elif type_name.startswith("GET_"):
            self._answer_query(message)
        elif type_name == "RTS_COMMAND":
            self._hub.deliver_reply(message, self)  # answers a COMMAND the daemon sent
        elif type_name.startswith(("STT_", "STP_", "RTS_")):
            pass  # streaming control and replies to queries we never make
        elif not self._data_refused(type_name, message.device_name):
            handler = self._hub.inbound_handler(message.device_name)
            assert handler is not None
            try:
                handler(message, self)
            except Exception as error:  # a bridge's bug must not take the connection down
                log.exception("handling %s for device %r failed", type_name, message.device_name)
                self.send_status(message.device_name, StatusCode.UNKNOWN_ERROR, str(error))

    def _data_refused(self, type_name: str, device: str) -> bool:
        """Whether a data message to ``device`` is refused, judged by its header alone
        (before its body is decoded): a read-only daemon, or a device no publisher or
        broadcaster receives. The client is told once per device."""
        if not self.grant.writes:
            # Checked here, at data routing, as the dispatcher checks commands.
            if device not in self._unrouted_warned:
                self._unrouted_warned.add(device)
                log.warning("client %s sent %s to device %r and may not write; refused "
                            "(said once per device)", self.peer, type_name, device)
                self.send_status(device, StatusCode.ACCESS_DENIED,
                                 f"this connection cannot send data to ROS: {self.grant.why}")
            return True
        if self._hub.inbound_handler(device) is not None:
            return False
        if device not in self._unrouted_warned:
            self._unrouted_warned.add(device)
            log.warning("client %s sent %s to device %r, which no publisher or broadcaster "
                        "receives; ignored (said once per device)", self.peer, type_name,
                        device)
            self.send_status(device, StatusCode.NOT_FOUND,
                             f"no publisher or broadcaster receives device {device!r}")
        return True

    def _answer_query(self, message: Message) -> None:
        """GET_<TYPE> asks for the current value of a device (empty name: all of that type)."""
        wanted = message.type_name[len("GET_"):]
        devices = [message.device_name] if message.device_name else self._hub.devices()
        found = 0
        for device in devices:
            latest = self._hub.latest(device, self)
            if latest is not None and latest.type_name == wanted:
                self.send_once(Frame(latest))
                found += 1
        if not found:
            self.send_status(message.device_name, StatusCode.NOT_FOUND,
                             f"no {wanted} device named {message.device_name!r}")

    # --- outgoing --------------------------------------------------------------------------
    @property
    def sent(self) -> int:
        """Frames written (or gathered for a batch write) to this client."""
        return self._sent + int(self.slot.sent)

    @property
    def header_version(self) -> int:
        return self._negotiator.outgoing_version

    def send_stream(self, device: str, frame: Frame) -> None:
        if self._closing:
            return
        if self._display is not None:
            with self.slot:
                self._display.hold(device, frame)
            return
        self._send_now(device, frame)

    def _send_now(self, device: str, frame: Frame) -> None:
        if self._paused or len(self._outbox):
            self._outbox.put_latest(device, frame)
            return
        parts = frame.encoded_parts(self.header_version)
        if len(parts) == 1 and len(parts[0]) <= WRITE_CHUNK:
            self._write(parts[0])
        else:
            self._write_large(parts)

    def send_once(self, frame: Frame) -> None:
        if self._closing:
            return
        parts = frame.encoded_parts(self.header_version)
        if self._paused or len(self._outbox):
            try:
                self._outbox.put_once(*parts)
            except OutboxOverflow as error:
                log.warning("client %s is too slow, closing it: %s", self.peer, error)
                self.close()
        elif len(parts) == 1 and len(parts[0]) <= WRITE_CHUNK:
            self._write(parts[0])
        else:
            self._write_large(parts)

    def _write_large(self, parts: tuple[Buffer, ...]) -> None:
        """A frame over `WRITE_CHUNK`: written a chunk at a time as the socket drains
        (the outbox holds the rest, shared, not copied), after what a batch gathered."""
        if self._batch:
            gathered, self._batch = self._batch, []
            self._transport_write(b"".join(gathered))
        self._outbox.put_once(*parts)  # the outbox was empty: within any bound
        self._limit_kernel_unsent(LARGE_KERNEL_UNSENT_BYTES)  # until the outbox is empty
        self._flush()

    def _limit_kernel_unsent(self, nbytes: int) -> None:
        """How much the kernel may hold unsent for this client (TCP_NOTSENT_LOWAT)."""
        sock = self._tcp_socket()
        if sock is None or not self._manages_unsent or nbytes == self._kernel_unsent \
                or not hasattr(socket, "TCP_NOTSENT_LOWAT"):
            return
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NOTSENT_LOWAT, nbytes)
        except OSError:
            return
        self._kernel_unsent = nbytes

    def send_message(self, message: Message) -> None:
        self.send_once(Frame(message))

    def send_status(self, device: str, code: int, text: str) -> None:
        self.send_message(Message(device_name=device[:20],
                                  body=Status(code=code, error_name="slicer-ros2-bridge"[:20],
                                              text=text)))

    def granted(self, grant: WriteGrant) -> None:
        """A key was presented: what this connection may do now."""
        self.grant = grant
        self.challenge = None  # one answer per challenge
        self._unrouted_warned.clear()  # refusals said before may not hold now

    def pace_display(self, hz: float) -> None:
        """From now on this client gets its streams' newest values `hz` times a second at
        most (bridge/core/display.py); the native lanes no longer write to it."""
        if self._closing:
            return
        with self.slot:
            self.slot.open = False
            self._display = DisplayPacing(hz)
        self._hub.set_paced(self)
        if self._display_timer is None:
            self._display_timer = asyncio.get_running_loop().call_later(
                self._display.interval_s, self._display_frame)

    def _display_frame(self) -> None:
        display = self._display
        if display is None or self._closing:
            self._display_timer = None
            return
        self._display_timer = asyncio.get_running_loop().call_later(display.interval_s,
                                                                    self._display_frame)
        lanes = self._hub.lane_news(display.lanes_seen, self)
        with self.slot:
            frames = display.take(lanes)
        if frames:
            self.begin_batch()
            try:
                for device, frame in frames:
                    self._send_now(device, frame)
            finally:
                self.end_batch()

    def start_heartbeat(self, interval: float) -> None:
        """Send a STATUS on `HEARTBEAT_DEVICE` every `interval` seconds (the client asked
        for it in hello), as a stream value: a client that does not read holds one."""
        if self._heartbeat is not None:
            self._heartbeat.cancel()
        loop = asyncio.get_running_loop()

        def beat() -> None:
            if self._closing:
                return
            self.send_stream(HEARTBEAT_DEVICE, Frame(Message(
                device_name=HEARTBEAT_DEVICE, message_id=daemon_clock_ms(),
                body=Status(code=StatusCode.OK, error_name="heartbeat", text=""))))
            self._heartbeat = loop.call_later(interval, beat)

        self._heartbeat = loop.call_later(interval, beat)

    def _tcp_socket(self) -> Optional[socket.socket]:
        transport = self._transport
        sock: Optional[socket.socket] = (transport.get_extra_info("socket")
                                         if transport is not None else None)
        if sock is None or sock.family not in (socket.AF_INET, socket.AF_INET6):
            return None
        return sock

    def link_state(self) -> Optional[LinkState]:
        """What waits for the peer's acknowledgement (None: nothing, or not a TCP socket):
        see protocol/liveness.py."""
        sock = self._tcp_socket()
        if sock is None or not hasattr(socket, "TCP_INFO"):
            return None
        try:
            return read_link(sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO,
                                             TCP_INFO_BYTES))
        except OSError:
            return None

    def link_is_dead(self) -> bool:
        return link_is_dead(self.link_state(), reads_stamps=self.reads_stamps,
                            loopback=self.on_loopback)

    def abort_dead(self) -> Optional[tuple[tuple[str, int], tuple[str, int]]]:
        """The link is dead: reset the connection now, dropping what waits in the kernel
        too (it would arrive stale). Returns the connection's (local, peer) addresses."""
        state = self.link_state()
        log.warning("client %s has acknowledged nothing for %.1f s while data waits: the "
                    "link is dead; closing it", self.peer, state.silent_s if state else 0.0)
        with self.slot:
            self._closing = True
            self.slot.open = False
        sock = self._tcp_socket()
        ends = None
        if sock is not None:
            try:
                ends = sock.getsockname()[:2], sock.getpeername()[:2]
                # Linger 0: close sends a reset and drops the send queue.
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            except OSError:
                pass
        if self._transport is not None:
            self._transport.abort()
        return ends

    def forget_device(self, device: str) -> None:
        self._outbox.discard(device)
        if self._display is not None:
            with self.slot:
                self._display.forget(device)

    def close(self) -> None:
        """Close the connection. What the transport already holds is still flushed; the
        receive buffer and the frames not yet handed to the transport go now."""
        with self.slot:
            self._closing = True
            self.slot.open = False
            if self._frame_timer is not None:
                self._frame_timer.cancel()
                self._frame_timer = None
            self.frame_started = None
            self._decoder.close()
            self._outbox.clear()
        if self._transport is not None:
            self._transport.close()

    def begin_batch(self) -> None:
        """Gather the frames of one hub batch, to write them in one system call."""
        self._batch = []

    def end_batch(self) -> None:
        batch, self._batch = self._batch, None
        if batch and not self._closing:
            self._transport_write(b"".join(batch) if len(batch) > 1 else batch[0])

    def _write(self, data: Buffer) -> None:
        assert self._transport is not None
        self._sent += 1
        if self._batch is not None:
            self._batch.append(data)
        else:
            self._transport_write(data)

    def _transport_write(self, data: Buffer) -> None:
        assert self._transport is not None
        with self.slot:
            self.slot.open = False  # the transport may hold data now: direct writes wait
            stash = self.slot.take_stash()
            if stash is not None:  # the rest of a direct write goes first
                self._transport.write(stash)
            self._transport.write(data)

    def _flush(self) -> None:
        """Write what waits while the transport takes it, at most `FLUSH_TURN_BYTES` a
        loop turn: a client that reads 50 MB models as fast as they are written would
        otherwise keep the loop (every other client's replies and streams) for as long."""
        self._flush_scheduled = False
        written = 0
        while not self._paused and not self._closing:
            if written >= FLUSH_TURN_BYTES:
                if self._outbox:
                    self._flush_scheduled = True
                    asyncio.get_running_loop().call_soon(self._flush_turn)
                return
            data = self._outbox.pop(WRITE_CHUNK)
            if data is None:
                self._limit_kernel_unsent(KERNEL_UNSENT_BYTES)  # a large frame went
                return
            self._sent += 1
            written += len(data)
            self._transport_write(data)

    def _flush_turn(self) -> None:
        if self._flush_scheduled:
            self._flush()

    # --- direct writes (ROS executor thread) -------------------------------------------------
    def write_direct(self, data: bytes | tuple[Buffer, ...]) -> bool:
        """Write a stream frame now, from another thread, if nothing of this client waits
        anywhere; False (nothing written) if it must take the loop's path (`hand_over`).
        A frame written whole opens the slot to the native lanes. ``data``: its bytes, or
        a large frame's parts (an image's pixels where they lie), which the kernel may
        hold whole (`LARGE_KERNEL_UNSENT_BYTES`) while it goes."""
        slot = self.slot
        with slot:
            transport = self._transport
            direct = self._direct
            if (direct is None or transport is None or self._closing or self._paused
                    or self._display is not None
                    or self._handed or slot.has_stash or self._batch is not None
                    or len(self._outbox) or transport.is_closing()
                    or transport.get_write_buffer_size()):
                slot.open = False
                return False
            if not isinstance(data, bytes) and _size(data) > LARGE_KERNEL_UNSENT_BYTES:
                # More than the kernel takes at once (a VGA point cloud: 9 MB): written here,
                # its rest would be copied three times (the stash, a bytes, asyncio's
                # buffer), 12 ms of the loop's time a cloud; the loop writes it from its own
                # parts instead, a chunk at a time (`_write_large`).
                slot.open = False
                return False
            slot.header_version = self.header_version
            if isinstance(data, bytes):
                result = slot.send(data)
            else:
                result = self._send_large_direct(direct, data)
            if result == SENT:
                slot.open = True
                return True
            if result == STASHED:
                self._hub.call_soon(self._write_stash)
                return True
            if result == BROKEN:  # the loop's transport meets the same error and closes
                slot.disconnect()
                direct.close()
                self._direct = None
            return False

    def _send_large_direct(self, direct: socket.socket, parts: tuple[Buffer, ...]) -> int:
        # Under the slot: the kernel's limit is raised for this frame alone. Later frames
        # then wait (the loop's path, coalesced) until it has mostly gone.
        try:
            direct.setsockopt(socket.IPPROTO_TCP, socket.TCP_NOTSENT_LOWAT,
                              LARGE_KERNEL_UNSENT_BYTES)
            try:
                return int(self.slot.send(parts))
            finally:
                direct.setsockopt(socket.IPPROTO_TCP, socket.TCP_NOTSENT_LOWAT,
                                  KERNEL_UNSENT_BYTES)
        except OSError:  # the socket failed: the loop's transport meets the same error
            return BROKEN

    def hand_over(self, device: str, frame: Frame) -> None:
        """A stream frame `write_direct` refused: the loop sends it, after any handed before
        it, and until then this client gets no direct write. The loop is woken once for
        all that are handed meanwhile; past `MAX_HANDED` of them only the newest of each
        device is kept (the loop is that far behind). A large frame replaces its device's
        handed one at once: no image waits behind a stale one."""
        with self.slot:
            self.slot.open = False
            if self._display is not None:  # its next frame takes it
                self._display.hold(device, frame)
                return
            handed = self._handed_frames
            if isinstance(frame, BulkFrame):
                handed[:] = [(d, f) for d, f in handed if d != device]
            handed.append((device, frame))
            if len(handed) > MAX_HANDED:
                seen: set[str] = set()
                newest: list[tuple[str, Frame]] = []
                for d, f in reversed(handed):
                    if d not in seen:
                        seen.add(d)
                        newest.append((d, f))
                handed[:] = newest[::-1]  # each device's newest value, in their order
            if self._handed:
                return
            self._handed = True
        self._hub.call_soon(self._take_handed)

    def _take_handed(self) -> None:
        while True:
            with self.slot:
                frames = self._handed_frames
                if not frames:
                    self._handed = False
                    return
                self._handed_frames = []
            try:
                for device, frame in frames:
                    self.send_stream(device, frame)
            except Exception:
                with self.slot:  # never left refusing direct writes for good
                    self._handed_frames.clear()
                    self._handed = False
                raise

    def _write_stash(self) -> None:
        with self.slot:
            self.slot.open = False
            stash = self.slot.take_stash()
            if stash is not None and not self._closing and self._transport is not None:
                self._transport.write(stash)

    def stash_left(self) -> None:
        """A native lane wrote part of a frame to this client (any thread): the loop writes
        the rest."""
        self._hub.call_soon(self._write_stash)

    def describe(self) -> dict[str, object]:
        return {"peer": self.peer, "header_version": self.header_version,
                "received": self.received, "sent": self.sent,
                "coalesced": self._outbox.coalesced, "waiting": self._outbox.frames_waiting,
                "waiting_bytes": self._outbox.pending_bytes,
                "receiving_bytes": self._decoder.buffered, "decoding": self._decoding,
                "display_hz": self._display.hz if self._display is not None else None}


def _size(parts: tuple[Buffer, ...]) -> int:
    """The bytes of a frame's parts (a memoryview's len counts items, not bytes)."""
    return sum(p.nbytes if isinstance(p, memoryview) else len(p) for p in parts)


def _status_of(error: MessageError) -> int:
    if isinstance(error, CrcMismatchError):
        return StatusCode.CHECKSUM_ERROR
    return StatusCode.UNKNOWN_ERROR
