"""How both ends notice a dead link within seconds (a pulled cable, a host gone), the one
set of timings the daemon and its clients share.

* TCP keepalive with short timers: an idle connection whose peer is gone is found after
  ``KEEPALIVE_IDLE_S + KEEPALIVE_INTERVAL_S * KEEPALIVE_COUNT`` seconds.
* A sender's watch on acknowledgements (`read_link`, from the kernel's ``TCP_INFO``;
  `link_is_dead` decides): while data waits for the peer and the peer has acknowledged
  nothing, the link is dead, and the sender resets the connection, so that what sat in its
  send buffer goes with it instead of arriving late as if it were new.
  - A client that reads the freshness stamps (its hello said `stamps`: it drops late
    values itself) is cut after ``PEER_SILENT_AFTER_S``.
  - A plain client (3D Slicer's connector shows whatever arrives) is cut sooner, under the
    freshness bound: after ``PLAIN_SILENT_AFTER_S`` with TCP retransmitting, unless it is on
    this machine (a loopback link cannot be pulled, and a busy local reader's kernel can
    leave data unacknowledged that long). Its connector never sends, so the reset is
    delivered by a knock once the link is back (bridge/core/knock.py), and it reconnects.
  A peer that is alive but not reading (a stalled GUI) closes its receive window: nothing
  is in flight, so it is not taken for dead. (``TCP_USER_TIMEOUT`` cannot tell the two
  apart: it also ends a connection whose reader paused for that long.)
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
from dataclasses import dataclass
from typing import List, Optional, Tuple

from protocol.messages import Message, Status, StatusCode

__all__ = ["LIVE", "STALE", "condition_status", "stream_condition",
           "DEAD_AFTER_S", "HEARTBEAT_DEVICE", "HEARTBEAT_INTERVAL_S", "KEEPALIVE_COUNT",
           "KEEPALIVE_IDLE_S", "KEEPALIVE_INTERVAL_S",
           "LinkState", "PEER_SILENT_AFTER_S", "PLAIN_SILENT_AFTER_S", "TCP_INFO_BYTES",
           "link_is_dead", "read_link", "socket_options"]

KEEPALIVE_IDLE_S = 2
KEEPALIVE_INTERVAL_S = 1
KEEPALIVE_COUNT = 3
PEER_SILENT_AFTER_S = 5.0
# Under the 0.5 s freshness bound (protocol/freshness.py) with the daemon's 0.1 s check:
# a link back sooner brings values younger than the bound, a later one finds it reset.
PLAIN_SILENT_AFTER_S = 0.4
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


# Linux's struct tcp_info: 8 one-byte fields (tcpi_retransmits, the RTO's unanswered
# retransmissions, is the 3rd), then u32s: tcpi_unacked is the 5th, tcpi_last_ack_recv (ms
# since the last ACK came) the 13th.
TCP_INFO_BYTES = 60
_RETRANSMITS_AT = 2
_UNACKED_AT = 8 + 4 * 4
_LAST_ACK_RECV_AT = 8 + 12 * 4


@dataclass(frozen=True)
class LinkState:
    """A connection with sent data waiting for the peer's acknowledgement."""

    silent_s: float  # since the peer acknowledged anything
    retransmitting: bool  # TCP's retransmission timer fired with no answer since


def read_link(tcp_info: bytes) -> Optional[LinkState]:
    """The kernel's ``TCP_INFO`` read; None when nothing waits for the peer (or the
    kernel's answer is too short)."""
    if len(tcp_info) < TCP_INFO_BYTES:
        return None
    unacked = int.from_bytes(tcp_info[_UNACKED_AT:_UNACKED_AT + 4], sys.byteorder)
    if not unacked:
        return None
    silent_ms = int.from_bytes(tcp_info[_LAST_ACK_RECV_AT:_LAST_ACK_RECV_AT + 4],
                               sys.byteorder)
    return LinkState(silent_s=silent_ms / 1000,
                     retransmitting=tcp_info[_RETRANSMITS_AT] > 0)


def link_is_dead(state: Optional[LinkState], *, reads_stamps: bool, loopback: bool) -> bool:
    """Whether a client's link is dead and must be reset (see the module's text)."""
    if state is None:
        return False
    if state.silent_s >= PEER_SILENT_AFTER_S:
        return True
    return (not reads_stamps and not loopback and state.retransmitting
            and state.silent_s >= PLAIN_SILENT_AFTER_S)
