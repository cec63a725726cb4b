"""Delivering a reset to a plain client whose link died, once the link is back.

The daemon resets a dead link's connection so that what sat in its send queue is never
delivered late (protocol/liveness.py). While the cable is out that reset is lost, and a
plain OpenIGTLink client (3D Slicer's connector) never sends and sets no keepalive: it
would sit on its half of the connection, showing the last pose as live, for good.

So the daemon knocks: from the connection's own address and port it opens a connection to
the client's. While the link is down the knock goes unanswered. Once it is back, the
client's kernel answers the knock on its still-open connection with an acknowledgement of
where that connection stands (RFC 5961's challenge ACK), which the daemon's kernel answers
with a reset in that connection's sequence: the client's connection ends, and its
connector reconnects and gets the newest state. A refusal means the client's side is gone
(reset, or closed by itself): the knocking stops.

Binding the listening port needs ``SO_REUSEPORT`` on the listener and the knock (Linux
shares such a port only between sockets of the same user). Elsewhere nothing is knocked.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import sys
from typing import Dict, Optional, Tuple

log = logging.getLogger(__name__)

Address = Tuple[str, int]

KNOCKS = sys.platform.startswith("linux") and hasattr(socket, "SO_REUSEPORT")
KNOCK_EVERY_S = 0.5  # the client's reset comes this soon after its link is back
KNOCK_FOR_S = 30 * 60.0  # a link out longer than this: the client is left to itself
MAX_KNOCKING = 256  # clients knocked at once; the longest-knocked gives way


class Knocker:
    """Knocks on the connections of plain clients cut for a dead link (loop thread)."""

    def __init__(self) -> None:
        self._knocking: Dict[Tuple[Address, Address], asyncio.Task[None]] = {}

    def knock(self, local: Address, peer: Address) -> None:
        if not KNOCKS:
            return
        if len(self._knocking) >= MAX_KNOCKING:
            oldest = next(iter(self._knocking))
            self._knocking.pop(oldest).cancel()
        key = (local, peer)
        if key not in self._knocking:
            task = asyncio.get_running_loop().create_task(self._knock_until_answered(
                local, peer))
            self._knocking[key] = task
            task.add_done_callback(lambda _: self._knocking.pop(key, None))

    @property
    def knocking(self) -> int:
        return len(self._knocking)

    async def _knock_until_answered(self, local: Address, peer: Address) -> None:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + KNOCK_FOR_S
        while loop.time() < deadline:
            outcome = await _knock_once(local, peer)
            if outcome is not None:
                log.info("client %s:%d: %s", peer[0], peer[1], outcome)
                return
            await asyncio.sleep(KNOCK_EVERY_S)
        log.info("client %s:%d: its link stayed dead for %.0f s; no longer knocking",
                 peer[0], peer[1], KNOCK_FOR_S)

    async def close(self) -> None:
        tasks = list(self._knocking.values())
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


async def _knock_once(local: Address, peer: Address) -> Optional[str]:
    """One knock: what it found, or None when nothing answered (the link is still down)."""
    family = socket.AF_INET6 if ":" in local[0] else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setblocking(False)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        try:
            sock.bind(local)
        except OSError as error:
            return f"cannot knock from {local[0]}:{local[1]} ({error}); not knocking"
        try:
            await asyncio.wait_for(asyncio.get_running_loop().sock_connect(sock, peer),
                                   KNOCK_EVERY_S)
        except ConnectionRefusedError:
            return "its connection, reset as its link died, is gone on its side too"
        except (asyncio.TimeoutError, OSError):
            return None  # unanswered or unreachable: the link is still down
        return "a knock was accepted (the client's port listens); not knocking"
    finally:
        sock.close()
