"""The daemon's background threads, all started by `start_thread`, so that none dies
silently (issue 43: the shared-memory port watch died on "Too many open files" and never
came back, and nothing said so but a traceback).

Each thread declares what its failure means (`OnFailure`):

- ``RESTART``: what it works on is still there (a port watch, a marker topic's worker, a ROS
  executor): a failure is logged in one line (rate-limited: one per interval, then a count)
  and the thread's function runs again after `RESTART_PAUSE_S`. One that fails
  `GIVE_UP_AFTER` times in a row, each within `GIVE_UP_WINDOW_S` of the last, is not
  getting better: it is handled as ``STOP``.
- ``STOP``: the daemon cannot do its job without it (a raw reader whose ROS wait failed: its
  topics would go silent for good): the failure is logged at CRITICAL and the daemon stops
  (SIGTERM to itself, then exit code 1: `fatal_failure` says why).

A function that returns has finished its work (its stop flag was set): the thread ends.
"""

from __future__ import annotations

import enum
import logging
import os
import signal
import threading
import time
import traceback
from typing import Callable, Optional

from bridge.core.logging_limits import RateLimitedLog

__all__ = ["GIVE_UP_AFTER", "GIVE_UP_WINDOW_S", "OnFailure", "RESTART_PAUSE_S",
           "fatal_failure", "start_thread"]

log = logging.getLogger(__name__)

RESTART_PAUSE_S = 1.0  # a failed thread's function runs again after this
GIVE_UP_AFTER = 20  # failures in a row (each soon after the last) before the daemon stops
GIVE_UP_WINDOW_S = 60.0

# The folder holding bridge/: a failure is located in the project's own code.
_PROJECT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_OURS = tuple(os.path.join(_PROJECT, folder) + os.sep for folder in ("bridge", "protocol"))
_failures = RateLimitedLog(log)
_fatal: list[str] = []  # why a STOP thread stopped the daemon (first one)
_fatal_lock = threading.Lock()


class OnFailure(enum.Enum):
    RESTART = "restart"
    STOP = "stop"


def start_thread(name: str, run: Callable[[], None], on_failure: OnFailure, *,
                 stop_process: Optional[Callable[[], None]] = None) -> threading.Thread:
    """Start a daemon thread running `run` under `on_failure`'s rule. `stop_process`: how
    a ``STOP`` ends the daemon (default: SIGTERM to this process; tests pass their own)."""
    thread = threading.Thread(target=_guarded, args=(name, run, on_failure, stop_process),
                              name=name, daemon=True)
    thread.start()
    return thread


def fatal_failure() -> Optional[str]:
    """Why a thread stopped the daemon, if one did."""
    with _fatal_lock:
        return _fatal[0] if _fatal else None


def _guarded(name: str, run: Callable[[], None], on_failure: OnFailure,
             stop_process: Optional[Callable[[], None]]) -> None:
    in_a_row, last_failure = 0, -GIVE_UP_WINDOW_S
    while True:
        try:
            run()
            return
        except Exception as error:  # noqa: BLE001 - every failure is handled by the rule
            now = time.monotonic()
            in_a_row = in_a_row + 1 if now - last_failure < GIVE_UP_WINDOW_S else 1
            last_failure = now
            if on_failure is OnFailure.STOP or in_a_row >= GIVE_UP_AFTER:
                why = (f"thread {name} failed ({describe(error)})"
                       + (f", {in_a_row} times in a row" if in_a_row > 1 else ""))
                with _fatal_lock:
                    _fatal.append(why)
                log.critical("%s: the daemon cannot go on without it; stopping", why)
                (stop_process or _terminate)()
                return
            _failures.warning(name, now, "thread %s failed (%s); it runs again in %g s",
                              name, describe(error), RESTART_PAUSE_S)
        time.sleep(RESTART_PAUSE_S)


def describe(error: BaseException) -> str:
    """One line: the error, and where the project's code met it (file:line, function)."""
    frames = [f for f in traceback.extract_tb(error.__traceback__)
              if os.path.abspath(f.filename) != os.path.abspath(__file__)]
    ours = [f for f in frames if f.filename.startswith(_OURS)] or frames
    at = (f" at {os.path.relpath(ours[-1].filename, _PROJECT)}:{ours[-1].lineno} in "
          f"{ours[-1].name}" if ours else "")
    return f"{type(error).__name__}: {error}{at}"


def _terminate() -> None:
    os.kill(os.getpid(), signal.SIGTERM)  # the daemon's stop: its teardown runs as usual
