"""One rate-limited logger for warnings that a peer can repeat at will (bad messages, refused
transforms, refused clients): at most one line per key and interval, and the next line
says how many were left out, so a flood costs the log nothing and hides nothing."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Optional

__all__ = ["DEFAULT_INTERVAL_S", "RateLimitedLog"]

DEFAULT_INTERVAL_S = 5.0


@dataclass
class RateLimitedLog:
    """Logs a repeated warning at most once per ``interval_s`` per key, counting the rest.

    Thread-safe enough for its job: a lost count under a race only shortens a "more like
    it" number, it never drops a first warning."""

    logger: logging.Logger
    interval_s: float = DEFAULT_INTERVAL_S
    _last: dict[str, float] = field(default_factory=dict)
    _suppressed: dict[str, int] = field(default_factory=dict)

    def warning(self, key: str, now: Optional[float], message: str, *args: object,
                count: int = 1) -> bool:
        """Log ``message % args`` unless `key` was logged less than an interval ago (then
        count it: `count` events). `now` is ``time.monotonic()`` (None: read it here).
        True if the line was written."""
        now = time.monotonic() if now is None else now
        last = self._last.get(key)
        if last is not None and now - last < self.interval_s:
            self._suppressed[key] = self._suppressed.get(key, 0) + count
            return False
        self._last[key] = now
        suppressed = self._suppressed.pop(key, 0)
        if suppressed:
            message += f" ({suppressed} more like it not logged)"
        self.logger.warning(message, *args)
        return True
