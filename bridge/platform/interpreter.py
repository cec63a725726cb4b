"""CPython's defaults tuned for a process whose threads pass streams to each other.

- The GIL switch interval: two busy threads (the ROS executor, the asyncio loop) share the
  interpreter's lock, and with the default 5 ms interval a frame handed to the loop under
  load waits up to 5 ms to be sent.
- The cyclic collector holds the interpreter while it walks. What start-up made (modules,
  ROS types, the nodes) lives as long as the daemon, so it is frozen out of the collector's
  sight; and the collector runs a hundred times less often, so that the tens of thousands of
  objects a large request makes for a moment (a megabyte of JSON, a cloud's points) are gone
  before it looks, instead of promoted and walked again (pauses of tens of ms with the
  default thresholds, every other thread waiting).
"""

from __future__ import annotations

import gc
import sys

__all__ = ["GC_THRESHOLDS", "GIL_SWITCH_INTERVAL_S", "settle_the_collector",
           "shorten_gil_switches"]

GIL_SWITCH_INTERVAL_S = 0.0005  # CPython's default: 0.005
GC_THRESHOLDS = (100_000, 50, 100)  # CPython's default: (700, 10, 10)


def shorten_gil_switches() -> None:
    """Before the threads start."""
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)


def settle_the_collector() -> None:
    """Once start-up has made what lives as long as the process."""
    gc.freeze()
    gc.set_threshold(*GC_THRESHOLDS)
