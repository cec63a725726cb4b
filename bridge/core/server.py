"""The OpenIGTLink TCP server: accepts clients, one `ClientSession` each.

At accept, the security policy decides: a peer outside ``--allow`` is closed at once, and a
client over ``--max-clients`` gets a STATUS saying so, then is closed. Both are logged
(rate-limited: a reconnect storm must not flood the log).

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
import logging
import socket
import ssl
import time
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


class TlsEndpoint(Protocol):
    """What the server needs of a TLS listener (`bridge.config.TlsListener` is one): its
    port, and its context (checked at start-up)."""

    @property
    def port(self) -> int: ...
    def context(self) -> ssl.SSLContext: ...


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
        self._server: Optional[asyncio.base_events.Server] = None
        self._tls = tls
        self._tls_server: Optional[asyncio.base_events.Server] = None
        self._link_check: Optional[asyncio.TimerHandle] = None
        self.knocker = Knocker()
        self.sessions: set[ClientSession] = set()
        self.refused = 0

    async def start(self, *, serving: bool = True) -> None:
        """Bind the port (a port in use fails here); accept clients now, or only once
        `serve` is called (``serving`` False: the daemon first makes its start-up bridges,
        and nothing may connect before they exist)."""
        self._server = await self._listen(self._port, None, serving)
        if self._tls is not None:
            self._tls_server = await self._listen(self._tls.port, self._tls.context(), serving)
        if not is_loopback_host(self._host):
            log.warning("listening on %s, reachable from other machines; %s%s", self._host,
                        "who may change ROS: " + self._policy.grant_summary(),
                        "" if self._policy.allowed_networks else
                        " (restrict who may connect at all with --allow CIDR)")

    async def _listen(self, port: int, tls: Optional[ssl.SSLContext],
                      serving: bool) -> asyncio.base_events.Server:
        loop = asyncio.get_running_loop()
        try:
            if KNOCKS and port:
                await _claim(self._host, port)
            return await loop.create_server(self._new_session, self._host, port,
                                            reuse_address=True, reuse_port=KNOCKS,
                                            start_serving=serving, ssl=tls)
        except OSError as error:
            if error.errno == 98:  # EADDRINUSE
                raise PortInUseError(error.errno, f"{self._host}:{port} is already in "
                                                  f"use (is another bridge or an OpenIGTLink "
                                                  f"server running?)") from None
            raise

    async def serve(self) -> None:
        """Start listening (after `start` with ``serving`` False)."""
        assert self._server is not None
        await self._server.start_serving()
        self._link_check = asyncio.get_running_loop().call_later(LINK_CHECK_INTERVAL_S,
                                                                 self._check_links)
        if self._tls_server is not None:
            await self._tls_server.start_serving()

    @property
    def port(self) -> int:
        assert self._server is not None and self._server.sockets
        return int(self._server.sockets[0].getsockname()[1])

    @property
    def tls_port(self) -> int:
        assert self._tls_server is not None and self._tls_server.sockets
        return int(self._tls_server.sockets[0].getsockname()[1])

    def _new_session(self) -> asyncio.Protocol:
        # The peer's address is known only once connected: the gate decides then.
        return _Gate(self)

    def _admit(self, transport: asyncio.Transport) -> None:
        peer = transport.get_extra_info("peername")
        address = str(peer[0]) if isinstance(peer, tuple) else str(peer)
        who = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else address
        if not self._policy.admits(address):
            self.refused += 1
            self._refusals.warning("allow", time.monotonic(), "refused client %s: not in the "
                                   "allowed networks (--allow)", who)
            # One STATUS says why (the address is all it reveals: the peer knows it).
            self._refuse(transport, "allow", f"client address: expected one in the allowed "
                         f"networks (--allow {', '.join(map(str, self._policy.allowed_networks))}"
                         f"), got {address}; closing")
            return
        if len(self.sessions) >= self._policy.max_clients and not self._evict_stalled(who):
            self.refused += 1
            self._refusals.warning("max_clients", time.monotonic(), "refused client %s: "
                                   "%d clients already connected (--max-clients)", who,
                                   len(self.sessions))
            self._refuse(transport, "max_clients", f"clients: expected at most "
                         f"{self._policy.max_clients} (--max-clients), got one more; closing")
            return
        session = ClientSession(self._hub, self._commands, self._limits, self.sessions.discard,
                                grant=self._policy.grant_at_accept(address),
                                budget=self.budget,
                                incidents=self._incidents, heavy=self._heavy)
        self.sessions.add(session)
        transport.set_protocol(session)
        session.connection_made(transport)

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

    @staticmethod
    def _refuse(transport: asyncio.Transport, name: str, text: str) -> None:
        """Say why in one STATUS, then close (after it is written)."""
        code = StatusCode.ACCESS_DENIED if name == "allow" else StatusCode.RESOURCE_ERROR
        transport.write(encode(Message(device_name="", body=Status(
            code=code, error_name=name, text=text))))
        transport.close()

    def _evict_stalled(self, newcomer: str) -> bool:
        """Close the client with the oldest unfinished frame, if one is old enough, to make
        room for ``newcomer``; whether a slot was freed."""
        now = asyncio.get_running_loop().time()
        stalled = [(s.frame_started, id(s), s) for s in self.sessions
                   if s.frame_started is not None and now - s.frame_started
                   >= STALLED_FRAME_EVICT_S]
        if not stalled:
            return False
        started, _, victim = min(stalled, key=lambda item: (item[0], item[1]))
        self._incidents.warning("evict", time.monotonic(), "all %d client slots taken: "
                                "closing client %s, whose frame has been unfinished for "
                                "%.1f s, to admit %s", len(self.sessions), victim.peer,
                                now - started, newcomer)
        victim.close_stalled()
        self.sessions.discard(victim)  # its slot is free now, not once its socket is gone
        return True

    async def close(self) -> None:
        if self._link_check is not None:
            self._link_check.cancel()
        servers = [s for s in (self._server, self._tls_server) if s is not None]
        for server in servers:
            server.close()
        for session in tuple(self.sessions):
            session.close()
        await self.knocker.close()
        for server in servers:
            await server.wait_closed()


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


class _Gate(asyncio.Protocol):
    """The protocol of a just-accepted connection: hands it to a `ClientSession` if the
    policy admits the peer (the transport then talks to the session directly)."""

    def __init__(self, server: BridgeServer) -> None:
        self._server = server

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._server._admit(transport)

    def data_received(self, data: bytes) -> None:
        pass  # a refused peer's bytes, until its transport is gone
