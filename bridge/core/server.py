"""The OpenIGTLink TCP server: accepts clients, one `ClientSession` each.

Both ports (plain and TLS) accept through one loop of their own (`_accept`) and judge each
peer by one rule (`_judge`) on the raw TCP connection, before a byte is read or a TLS
handshake begins: a peer outside ``--allow`` is closed at once, and so is one over
``--max-clients`` or over what the descriptor limit leaves room for. On the plain port a
refused peer first gets one STATUS saying why (naming only its own address); a TLS peer
could not read it, so it is only closed. Refusals are logged, rate-limited: a reconnect
storm must not flood the log. An admitted TLS peer holds a client slot from accept on, and
its handshake must end within `HANDSHAKE_TIMEOUT_S`.

Every connection costs descriptors, and the process has a fixed number (``ulimit -n``): at
start the server counts what is free and keeps `DESCRIPTOR_RESERVE` of it for ROS, files and
knocks, so accepting clients never runs the process out. Should ``accept`` still fail for
want of descriptors (or memory), one line says so per interval and the port pauses for
`ACCEPT_PAUSE_S`, then goes on.

A half-sent frame must not hold a client slot: when all slots are taken, the client whose
unfinished frame is the oldest (over `STALLED_FRAME_EVICT_S`) is closed to make room.
Clients that only receive, or that send whole messages, are never evicted. All sessions
share one `ReceiveBudget` for partly received bodies.

Every `LINK_CHECK_INTERVAL_S` each client's link is checked (protocol/liveness.py); a dead
one is reset, and a plain client's reset is delivered by knocking once its link is back
(bridge/core/knock.py). The listeners share their port for that (``SO_REUSEPORT``), so the port
is first claimed without it: another daemon's listener still makes this one fail to start.
"""

from __future__ import annotations

import asyncio
import errno
import logging
import os
import socket
import ssl
import time
from dataclasses import dataclass
from typing import Optional, Protocol

from bridge.core.heavy import HeavyWork
from bridge.core.hub import Hub
from bridge.core.knock import KNOCKS, Knocker
from bridge.core.logging_limits import RateLimitedLog
from bridge.core.security import SecurityPolicy, is_loopback_host
from bridge.core.session import ClientSession, CommandHandler, SessionLimits
from protocol.framing import ReceiveBudget
from protocol.framing import encode
from protocol.messages import Message, Status, StatusCode

log = logging.getLogger(__name__)

# An unfinished frame this old may be closed to admit a new client when all slots are
# taken: far above a frame's transit time on any working link, far below the deadline.
STALLED_FRAME_EVICT_S = 1.0
LINK_CHECK_INTERVAL_S = 0.1  # how often clients' links are checked for a dead peer
# A TLS handshake takes milliseconds on a LAN, a second on a slow link: one still unfinished
# after this is closed (asyncio's own default, 60 s, let idle peers hold descriptors).
HANDSHAKE_TIMEOUT_S = 10.0
# Descriptors kept for what is not a client (ROS's sockets and shared memory, robot files,
# knocks, a log file), out of those free when the server starts.
DESCRIPTOR_RESERVE = 128
DESCRIPTORS_PER_CLIENT = 2  # a plain client's socket and its duplicate (direct writes)
ACCEPT_PAUSE_S = 0.5  # a port whose accept failed for want of resources waits this long
ACCEPT_BURST = 64  # connections taken per wake-up of a port, so one port cannot hog the loop
LISTEN_BACKLOG = 1024  # connections waiting to be accepted (a storm must not drop good SYNs)


class TlsEndpoint(Protocol):
    """What the server needs of a TLS listener (`bridge.config.TlsListener` is one): its
    port, and its context (checked at start-up)."""

    @property
    def port(self) -> int: ...
    def context(self) -> ssl.SSLContext: ...


@dataclass(frozen=True)
class Refusal:
    """Why a just-accepted peer is not let in."""

    name: str  # the STATUS's error name, and the log's rate-limit key
    code: StatusCode
    reply: str  # the plain port's STATUS text (a refused TLS peer is only closed)
    logged: str  # what the log line says after "refused client ADDRESS:PORT: "


class PortInUseError(OSError):
    """The address is taken: another daemon (or 3D Slicer's own server) listens there."""


class BridgeServer:
    def __init__(self, hub: Hub, commands: CommandHandler, *, host: str, port: int,
                 limits: SessionLimits, policy: SecurityPolicy | None = None,
                 heavy: HeavyWork | None = None, tls: TlsEndpoint | None = None) -> None:
        self._hub = hub
        self._heavy = heavy  # decodes clients' heavy bodies off the loop
        self._commands = commands
        self._host = host
        self._port = port
        self._limits = limits
        self._policy = policy or SecurityPolicy()
        self._refusals = RateLimitedLog(log)
        self._incidents = RateLimitedLog(log)  # deadlines and budget, over all sessions
        self.budget: ReceiveBudget = limits.receive_budget()
        self._tls = tls
        self._listeners: list[_Listener] = []
        self._link_check: Optional[asyncio.TimerHandle] = None
        self.knocker = Knocker()
        # Every admitted connection, from accept on: those still in their TLS handshake
        # (also in `_handshakes`) hold a slot as clients do.
        self.sessions: set[ClientSession] = set()
        self._handshakes: dict[ClientSession, _Handshake] = {}
        self.client_room = descriptor_room()  # clients the descriptor limit leaves room for
        self.refused = 0

    async def start(self, *, serving: bool = True) -> None:
        """Bind the port (a port in use fails here); accept clients now, or only once
        `serve` is called (``serving`` False: the daemon first makes its start-up bridges,
        and nothing may connect before they exist)."""
        self._listeners.append(await self._listen(self._port, None))
        if self._tls is not None:
            self._listeners.append(await self._listen(self._tls.port, self._tls.context()))
        if not is_loopback_host(self._host):
            log.warning("listening on %s, reachable from other machines; %s%s", self._host,
                        "who may change ROS: " + self._policy.grant_summary(),
                        "" if self._policy.allowed_networks else
                        " (restrict who may connect at all with --allow CIDR)")
        if self.client_room < self._policy.max_clients:
            log.warning("the descriptor limit (ulimit -n %d) leaves room for %d clients, "
                        "fewer than --max-clients %d: the others are refused",
                        descriptor_limit(), self.client_room, self._policy.max_clients)
        if serving:
            self._accepting()

    async def _listen(self, port: int, tls: Optional[ssl.SSLContext]) -> _Listener:
        loop = asyncio.get_running_loop()
        sockets: list[socket.socket] = []
        try:
            if KNOCKS and port:
                await _claim(self._host, port)
            for family, kind, proto, _, address in await loop.getaddrinfo(
                    self._host or None, port, type=socket.SOCK_STREAM,
                    flags=socket.AI_PASSIVE):
                sock = socket.socket(family, kind, proto)
                sockets.append(sock)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                if KNOCKS:
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
                if family == socket.AF_INET6 and hasattr(socket, "IPPROTO_IPV6"):
                    sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
                sock.bind(address)
                sock.listen(LISTEN_BACKLOG)
                sock.setblocking(False)
        except OSError as error:
            for sock in sockets:
                sock.close()
            if error.errno == errno.EADDRINUSE:
                raise PortInUseError(error.errno, f"{self._host}:{port} is already in "
                                                  f"use (is another bridge or an OpenIGTLink "
                                                  f"server running?)") from None
            raise
        return _Listener(sockets, tls)

    def _accepting(self) -> None:
        for listener in self._listeners:
            for sock in listener.sockets:
                self._resume(sock, listener.tls)

    async def serve(self) -> None:
        """Start listening (after `start` with ``serving`` False)."""
        self._accepting()
        if self._link_check is None:
            self._link_check = asyncio.get_running_loop().call_later(LINK_CHECK_INTERVAL_S,
                                                                     self._check_links)

    @property
    def port(self) -> int:
        return self._listeners[0].port

    @property
    def tls_port(self) -> int:
        assert len(self._listeners) > 1
        return self._listeners[1].port

    # --- accept ------------------------------------------------------------------------------
    def _resume(self, sock: socket.socket, tls: Optional[ssl.SSLContext]) -> None:
        if sock.fileno() >= 0:  # not closed meanwhile
            asyncio.get_running_loop().add_reader(sock, self._accept, sock, tls)

    def _accept(self, sock: socket.socket, tls: Optional[ssl.SSLContext]) -> None:
        """A port is readable: take what waits there (`ACCEPT_BURST` at most)."""
        for _ in range(ACCEPT_BURST):
            try:
                conn, peer = sock.accept()
            except (BlockingIOError, InterruptedError, ConnectionAbortedError):
                return
            except OSError as error:
                # Out of descriptors or memory (or worse): what waits stays in the backlog;
                # one line per interval, not asyncio's traceback per connection.
                loop = asyncio.get_running_loop()
                self._incidents.warning(
                    "accept", time.monotonic(), "cannot accept a connection on port %d: %s "
                    "(%s); trying again in %.1f s", sock.getsockname()[1],
                    error.strerror or error, descriptor_use(), ACCEPT_PAUSE_S)
                loop.remove_reader(sock)
                loop.call_later(ACCEPT_PAUSE_S, self._resume, sock, tls)
                return
            self._arrived(conn, peer, tls)

    def _arrived(self, conn: socket.socket, peer: object,
                 tls: Optional[ssl.SSLContext]) -> None:
        address = str(peer[0]) if isinstance(peer, tuple) else str(peer)
        who = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else address
        refusal = self._judge(address, who)
        if refusal is not None:
            self.refused += 1
            self._refusals.warning(refusal.name, time.monotonic(), "refused client %s: %s",
                                   who, refusal.logged)
            if tls is None:
                _say_and_close(conn, refusal)
            else:
                conn.close()  # no handshake: nothing of the peer's is read or answered
            return
        session = ClientSession(self._hub, self._commands, self._limits, self.sessions.discard,
                                grant=self._policy.grant_at_accept(address),
                                budget=self.budget,
                                incidents=self._incidents, heavy=self._heavy)
        self.sessions.add(session)
        loop = asyncio.get_running_loop()
        task = loop.create_task(self._open(conn, session, who, tls))
        # Cancelled (evicted, or the server closes) before it ran, it never closed `conn`.
        task.add_done_callback(lambda done: conn.close() if done.cancelled() else None)
        self._handshakes[session] = _Handshake(loop.time(), task, who)

    def _judge(self, address: str, who: str) -> Optional[Refusal]:
        """May the peer at `address` (just accepted on either port) become a client? The
        one rule of both ports, judged before anything of the peer's is read."""
        if not self._policy.admits(address):
            # The peer learns only that its own address is not allowed, not which are.
            return Refusal("allow", StatusCode.ACCESS_DENIED, f"client address: expected "
                           f"an allowed one (--allow), got {address}; closing",
                           "not in the allowed networks (--allow)")
        limit = min(self._policy.max_clients, self.client_room)
        if len(self.sessions) < limit or self._evict_stalled(who):
            return None
        if limit == self._policy.max_clients:
            return Refusal("max_clients", StatusCode.RESOURCE_ERROR, f"clients: expected "
                           f"at most {limit} (--max-clients), got one more; closing",
                           f"{len(self.sessions)} clients already connected (--max-clients)")
        return Refusal("descriptors", StatusCode.RESOURCE_ERROR, f"clients: expected at "
                       f"most {limit} (what the daemon's descriptor limit leaves room for), "
                       f"got one more; closing", f"{len(self.sessions)} clients already "
                       f"connected, all the descriptor limit (ulimit -n) leaves room for")

    async def _open(self, conn: socket.socket, session: ClientSession, who: str,
                    tls: Optional[ssl.SSLContext]) -> None:
        """Make `session` the protocol of `conn`, after its TLS handshake if on that port
        (which must end within `HANDSHAKE_TIMEOUT_S`)."""
        loop = asyncio.get_running_loop()
        try:
            if tls is None:
                await loop.connect_accepted_socket(lambda: session, conn)
            else:
                await loop.connect_accepted_socket(lambda: session, conn, ssl=tls,
                                                   ssl_handshake_timeout=HANDSHAKE_TIMEOUT_S)
        except OSError as error:  # ssl.SSLError and a timed-out handshake are OSErrors
            self.sessions.discard(session)
            conn.close()
            self._incidents.warning("handshake", time.monotonic(), "client %s: %s; closed",
                                    who, _handshake_failure(error))
        finally:
            self._handshakes.pop(session, None)

    def _check_links(self) -> None:
        """Close the clients whose link is dead (a pulled cable): their slot and buffers
        are free within seconds, and nothing they held arrives late."""
        for session in tuple(self.sessions):
            if session.link_is_dead():
                ends = session.abort_dead()
                self.sessions.discard(session)
                if ends is not None and not session.reads_stamps:
                    self.knocker.knock(*ends)  # its connector would never hear the reset
        self._link_check = asyncio.get_running_loop().call_later(LINK_CHECK_INTERVAL_S,
                                                                 self._check_links)

    def _evict_stalled(self, newcomer: str) -> bool:
        """Close the client with the oldest unfinished frame or TLS handshake, if one is
        old enough, to make room for ``newcomer``; whether a slot was freed."""
        now = asyncio.get_running_loop().time()
        stalled = [(s.frame_started, id(s), s) for s in self.sessions
                   if s.frame_started is not None and now - s.frame_started
                   >= STALLED_FRAME_EVICT_S]
        stalled += [(h.begun, id(s), s) for s, h in self._handshakes.items()
                    if now - h.begun >= STALLED_FRAME_EVICT_S]
        if not stalled:
            return False
        started, _, victim = min(stalled, key=lambda item: (item[0], item[1]))
        handshake = self._handshakes.pop(victim, None)
        self._incidents.warning("evict", time.monotonic(), "all %d client slots taken: "
                                "closing client %s, whose %s has been unfinished for "
                                "%.1f s, to admit %s", len(self.sessions),
                                victim.peer if handshake is None else handshake.peer,
                                "frame" if handshake is None else "TLS handshake",
                                now - started, newcomer)
        if handshake is not None:
            handshake.task.cancel()  # its socket is closed with the unfinished transport
        else:
            victim.close_stalled()
        self.sessions.discard(victim)  # its slot is free now, not once its socket is gone
        return True

    async def close(self) -> None:
        if self._link_check is not None:
            self._link_check.cancel()
        loop = asyncio.get_running_loop()
        for listener in self._listeners:
            for sock in listener.sockets:
                if sock.fileno() >= 0:
                    loop.remove_reader(sock)
                    sock.close()
        handshakes = [handshake.task for handshake in self._handshakes.values()]
        for task in handshakes:
            task.cancel()
        for session in tuple(self.sessions):
            session.close()
        await self.knocker.close()
        await asyncio.gather(*handshakes, return_exceptions=True)


@dataclass(frozen=True)
class _Handshake:
    """A connection admitted but not yet a client: its TLS handshake (or, for a plain one,
    the loop turn that makes its transport) runs in `task`."""

    begun: float  # loop time
    task: asyncio.Task[None]
    peer: str


@dataclass(frozen=True)
class _Listener:
    """One port's listening sockets (one per address of ``--host``), and its TLS context."""

    sockets: list[socket.socket]
    tls: Optional[ssl.SSLContext]

    @property
    def port(self) -> int:
        return int(self.sockets[0].getsockname()[1])


def _say_and_close(conn: socket.socket, refusal: Refusal) -> None:
    """A refused plain peer gets one STATUS saying why, then is closed. The STATUS is far
    smaller than a fresh socket's send buffer, so one non-blocking send takes it whole."""
    conn.setblocking(False)
    try:
        conn.send(encode(Message(device_name="", body=Status(
            code=refusal.code, error_name=refusal.name, text=refusal.reply))))
    except OSError:
        pass  # the peer is gone already
    conn.close()


def _handshake_failure(error: OSError) -> str:
    if isinstance(error, ssl.SSLError):
        return f"TLS handshake failed ({error.reason or error})"
    if isinstance(error, ConnectionAbortedError) and "handshake" in str(error):
        return f"TLS handshake unfinished after {HANDSHAKE_TIMEOUT_S:g} s"
    return f"gone during the TLS handshake ({error.strerror or type(error).__name__})"


def descriptor_limit() -> int:
    """The process's descriptor limit (soft ``RLIMIT_NOFILE``); 0: none known."""
    try:
        import resource
    except ImportError:  # not Unix
        return 0
    soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    return 0 if soft == resource.RLIM_INFINITY else int(soft)


def open_descriptors() -> int:
    """Descriptors the process has open now (0 where /proc is absent)."""
    try:
        return len(os.listdir("/proc/self/fd")) - 1  # less listdir's own
    except OSError:
        return 0


def descriptor_use() -> str:
    """What the log says of the process's descriptors: how many are open, of how many."""
    limit = descriptor_limit()
    try:
        used = str(len(os.listdir("/proc/self/fd")) - 1)
    except OSError as error:  # EMFILE: reading the list needs one more
        used = "all" if error.errno == errno.EMFILE else "?"
    return f"{used} of {limit or 'unlimited'} descriptors open (ulimit -n)"


def descriptor_room() -> int:
    """Clients that fit in the descriptors free now, `DESCRIPTOR_RESERVE` kept aside."""
    limit = descriptor_limit()
    if not limit:
        return 1 << 30
    return max(1, (limit - open_descriptors() - DESCRIPTOR_RESERVE) // DESCRIPTORS_PER_CLIENT)


async def _claim(host: str, port: int) -> None:
    """Bind `host`:`port` as a plain listener would, and let go: raises EADDRINUSE when
    another socket listens there (a shared listener would not see it)."""
    loop = asyncio.get_running_loop()
    for family, kind, proto, _, address in await loop.getaddrinfo(
            host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE):
        with socket.socket(family, kind, proto) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6 and hasattr(socket, "IPPROTO_IPV6"):
                probe.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            probe.bind(address)
