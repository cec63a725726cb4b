"""How old a streamed value is when it reaches a client, without synchronized clocks.

The daemon stamps each streamed message, as it takes the value, with its own clock: the
OpenIGTLink v2 header's ``message_id`` holds `daemon_clock_ms()` (milliseconds, modulo
2**32; 0 means "not stamped": header v1, replies, one-shots). Its `hello` reply and its
heartbeats carry the clock too.

A client cannot read the daemon's clock directly (another machine, another clock), but it
knows the smallest difference it has seen between its own clock at arrival and the
daemon's stamp: that is the two clocks' offset plus the fastest transit. A message whose
difference is larger by more than the bound came late: it sat in a send queue, or in a
link that stalled, or it was the newest value of a stream that has stopped. `Freshness`
keeps that smallest difference (over a window of the daemon's heartbeats, so a slow drift
of either clock is followed) and judges each stamped message by it.

Sans-I/O: the caller passes both clocks' readings.
"""

from __future__ import annotations

import time
from collections import deque
from typing import Deque, Optional, Tuple

__all__ = ["CLOCK_MODULUS", "DEFAULT_FRESHNESS_S", "Freshness", "daemon_clock_ms"]

DEFAULT_FRESHNESS_S = 0.5
_MOD = 1 << 32
CLOCK_MODULUS = _MOD  # the clock wraps within it (the native lane's clock follows it)
_HALF = 1 << 31
_WINDOW_MS = 30_000  # heartbeats this recent set the baseline (drift is followed)


def daemon_clock_ms() -> int:
    """The daemon's clock as it stamps messages: monotonic milliseconds, never 0."""
    return (time.monotonic_ns() // 1_000_000) % (_MOD - 1) + 1


def _signed(value: int) -> int:
    value %= _MOD
    return value - _MOD if value >= _HALF else value


class Freshness:
    """One connection's judge: reset at each hello, fed by heartbeats."""

    def __init__(self, bound_s: float = DEFAULT_FRESHNESS_S) -> None:
        if not bound_s > 0:
            raise ValueError(f"bound_s: expected a positive number of seconds, got {bound_s!r}")
        self.bound_ms = bound_s * 1000.0
        self._baseline: Optional[int] = None
        self._samples: Deque[Tuple[int, int]] = deque()  # (arrival ms, difference)

    def reset(self, daemon_ms: int, now_ms: int) -> None:
        """A new connection: its hello reply said the daemon's clock."""
        self._samples.clear()
        self._baseline = None
        self.heartbeat(daemon_ms, now_ms)

    def heartbeat(self, daemon_ms: int, now_ms: int) -> None:
        """A message the daemon stamped as it sent it (hello, heartbeat)."""
        if not daemon_ms:
            return
        difference = (now_ms - daemon_ms) % _MOD
        samples = self._samples
        samples.append((now_ms, difference))
        while samples and now_ms - samples[0][0] > _WINDOW_MS:
            samples.popleft()
        base = samples[0][1]
        for _, seen in samples:
            if _signed(seen - base) < 0:
                base = seen
        self._baseline = base

    def age_ms(self, daemon_ms: int, now_ms: int) -> Optional[float]:
        """How much later than the fastest this stamped message came (None: unstamped, or
        no baseline yet). A message faster than all before lowers the baseline."""
        if not daemon_ms or self._baseline is None:
            return None
        difference = (now_ms - daemon_ms) % _MOD
        age = _signed(difference - self._baseline)
        if age < 0:
            self._baseline = difference
            return 0.0
        return float(age)

    def is_late(self, daemon_ms: int, now_ms: int) -> bool:
        age = self.age_ms(daemon_ms, now_ms)
        return age is not None and age > self.bound_ms
