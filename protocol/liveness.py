"""How both ends notice a dead link within seconds (a pulled cable, a host gone), the one
set of timings the daemon and its clients share.

* TCP keepalive with short timers: an idle connection whose peer is gone is found after
  ``KEEPALIVE_IDLE_S + KEEPALIVE_INTERVAL_S * KEEPALIVE_COUNT`` seconds.
* A sender's watch on acknowledgements: while data waits for the peer and the peer has
  acknowledged nothing for ``PEER_SILENT_AFTER_S`` (`peer_silence`, from the kernel's
  ``TCP_INFO``), the link is dead: the sender closes the connection, and what sat in its
  send buffer goes with it instead of arriving minutes later as if it were new. A peer
  that is alive but not reading (a stalled GUI) still acknowledges the kernel's window
  probes, so it is not taken for dead. (``TCP_USER_TIMEOUT`` cannot tell the two apart:
  it also ends a connection whose reader paused for that long.)
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
import sys
from typing import List, Optional, Tuple

from protocol.messages import Message, Status, StatusCode

__all__ = ["LIVE", "STALE", "condition_status", "stream_condition",
           "DEAD_AFTER_S", "HEARTBEAT_DEVICE", "HEARTBEAT_INTERVAL_S", "KEEPALIVE_COUNT",
           "KEEPALIVE_IDLE_S", "KEEPALIVE_INTERVAL_S",
           "PEER_SILENT_AFTER_S", "TCP_INFO_BYTES", "peer_silence", "socket_options"]

KEEPALIVE_IDLE_S = 2
KEEPALIVE_INTERVAL_S = 1
KEEPALIVE_COUNT = 3
PEER_SILENT_AFTER_S = 5.0
HEARTBEAT_INTERVAL_S = 1.0
DEAD_AFTER_S = 3.0
HEARTBEAT_DEVICE = "heartbeat"


def socket_options() -> List[Tuple[int, int, int]]:
    """The options for a connected TCP socket, where this system has them."""
    wanted = [(socket.SOL_SOCKET, "SO_KEEPALIVE", 1),
              (socket.IPPROTO_TCP, "TCP_KEEPIDLE", KEEPALIVE_IDLE_S),
              (socket.IPPROTO_TCP, "TCP_KEEPINTVL", KEEPALIVE_INTERVAL_S),
              (socket.IPPROTO_TCP, "TCP_KEEPCNT", KEEPALIVE_COUNT)]
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


# Linux's struct tcp_info: 8 one-byte fields, then u32s; tcpi_unacked is the 5th u32 and
# tcpi_last_ack_recv (ms since the last ACK came) the 13th.
TCP_INFO_BYTES = 60
_UNACKED_AT = 8 + 4 * 4
_LAST_ACK_RECV_AT = 8 + 12 * 4


def peer_silence(tcp_info: bytes) -> Optional[float]:
    """Seconds since the peer acknowledged anything, while sent data waits for its
    acknowledgement; None when nothing waits (or the kernel's answer is too short)."""
    if len(tcp_info) < TCP_INFO_BYTES:
        return None
    unacked = int.from_bytes(tcp_info[_UNACKED_AT:_UNACKED_AT + 4], sys.byteorder)
    if not unacked:
        return None
    return int.from_bytes(tcp_info[_LAST_ACK_RECV_AT:_LAST_ACK_RECV_AT + 4],
                          sys.byteorder) / 1000
