"""The OpenIGTLink TCP server: accepts any number of clients, one `ClientSession` each."""

from __future__ import annotations

import asyncio
import logging
from typing import Optional

from bridge.hub import Hub
from bridge.session import ClientSession, CommandHandler, SessionLimits

log = logging.getLogger(__name__)


class PortInUseError(OSError):
    """The address is taken: another daemon (or 3D Slicer's own server) listens there."""


class BridgeServer:
    def __init__(self, hub: Hub, commands: CommandHandler, *, host: str, port: int,
                 limits: SessionLimits) -> None:
        self._hub = hub
        self._commands = commands
        self._host = host
        self._port = port
        self._limits = limits
        self._server: Optional[asyncio.base_events.Server] = None
        self.sessions: set[ClientSession] = set()

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        try:
            self._server = await loop.create_server(self._new_session, self._host, self._port,
                                                    reuse_address=True)
        except OSError as error:
            if error.errno == 98:  # EADDRINUSE
                raise PortInUseError(error.errno, f"{self._host}:{self._port} is already in "
                                                  f"use (is another bridge or an OpenIGTLink "
                                                  f"server running?)") from None
            raise

    @property
    def port(self) -> int:
        assert self._server is not None and self._server.sockets
        return int(self._server.sockets[0].getsockname()[1])

    def _new_session(self) -> ClientSession:
        session = ClientSession(self._hub, self._commands, self._limits, self.sessions.discard)
        self.sessions.add(session)
        return session

    async def close(self) -> None:
        if self._server is None:
            return
        self._server.close()
        for session in tuple(self.sessions):
            session.close()
        await self._server.wait_closed()
