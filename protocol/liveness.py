"""How both ends notice a dead link within seconds (a pulled cable, a host gone), the one
set of timings the daemon and its clients share.

* TCP keepalive with short timers: an idle connection whose peer is gone is found after
  ``KEEPALIVE_IDLE_S + KEEPALIVE_INTERVAL_S * KEEPALIVE_COUNT`` seconds.
* ``TCP_USER_TIMEOUT``: data unacknowledged for ``USER_TIMEOUT_S`` closes the connection,
  so a sender finds a dead link as fast, and what sat in its send buffer is dropped with
  the connection instead of arriving minutes late as if it were new.
* ``TCP_NOTSENT_LOWAT``: the kernel keeps little unsent data, so a backlog stays in the
  sender's own buffer, where a newer value of a stream replaces an older one.
* A heartbeat: the daemon sends a client that asks for it a STATUS every
  ``HEARTBEAT_INTERVAL_S``; a client that hears nothing for ``DEAD_AFTER_S`` takes the
  link for dead, closes it and reconnects (then gets the newest state, not the backlog).

* Stale streams: the daemon sends a STATUS named ``stale`` (code NOT_READY, the reason in
  its text) on a stream's device when its publisher is gone or it fell silent, and one
  named ``live`` (code OK) when it comes back; `stream_condition` reads them.

`socket_options` lists the options as ``(level, option, value)`` for ``setsockopt``; the
ones an operating system lacks (macOS, Windows) are left out. No socket is touched here.
"""

from __future__ import annotations

import socket
from typing import List, Optional, Tuple

from protocol.messages import Message, Status, StatusCode

__all__ = ["LIVE", "STALE", "condition_status", "stream_condition",
           "DEAD_AFTER_S", "HEARTBEAT_DEVICE", "HEARTBEAT_INTERVAL_S", "KEEPALIVE_COUNT",
           "KEEPALIVE_IDLE_S", "KEEPALIVE_INTERVAL_S", "NOTSENT_LOWAT_BYTES", "USER_TIMEOUT_S",
           "socket_options"]

KEEPALIVE_IDLE_S = 2
KEEPALIVE_INTERVAL_S = 1
KEEPALIVE_COUNT = 3
USER_TIMEOUT_S = 5.0
NOTSENT_LOWAT_BYTES = 32 * 1024
HEARTBEAT_INTERVAL_S = 1.0
DEAD_AFTER_S = 3.0
HEARTBEAT_DEVICE = "heartbeat"


def socket_options() -> List[Tuple[int, int, int]]:
    """The options for a connected TCP socket, where this system has them."""
    wanted = [(socket.SOL_SOCKET, "SO_KEEPALIVE", 1),
              (socket.IPPROTO_TCP, "TCP_KEEPIDLE", KEEPALIVE_IDLE_S),
              (socket.IPPROTO_TCP, "TCP_KEEPINTVL", KEEPALIVE_INTERVAL_S),
              (socket.IPPROTO_TCP, "TCP_KEEPCNT", KEEPALIVE_COUNT),
              (socket.IPPROTO_TCP, "TCP_USER_TIMEOUT", int(USER_TIMEOUT_S * 1000)),
              (socket.IPPROTO_TCP, "TCP_NOTSENT_LOWAT", NOTSENT_LOWAT_BYTES)]
    return [(level, int(getattr(socket, name)), value) for level, name, value in wanted
            if hasattr(socket, name)]


STALE = "stale"
LIVE = "live"


def condition_status(reason: Optional[str], topic: str) -> Status:
    """The STATUS that says a stream is stale (`reason`) or live again (None)."""
    if reason is None:
        return Status(code=StatusCode.OK, error_name=LIVE, text=f"{topic} is live again")
    return Status(code=StatusCode.NOT_READY, error_name=STALE, text=reason)


def stream_condition(message: Message) -> Optional[str]:
    """For a stale/live STATUS: the reason it is stale, or "" when live again; None for
    any other message."""
    body = message.body
    if not isinstance(body, Status) or body.error_name not in (STALE, LIVE):
        return None
    return body.text if body.error_name == STALE else ""
