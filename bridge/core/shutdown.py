"""A stop that always ends: the first SIGTERM/SIGINT/SIGHUP asks the daemon to stop; from
then on the process exits within ``timeout_s`` whatever its teardown does, and a second
signal ends it at once.

Why a thread and the signals' default action: ROS's teardown can spin in C++ inside the
main thread (Fast DDS's participant teardown was seen spinning for 15 minutes). Python
signal handlers, and the asyncio loop that runs ours, only run between bytecodes of the
main thread, so nothing in it can react; the kernel's default action and another thread
can. If the stuck code also holds the GIL, no Python thread can run either: then
faulthandler's watchdog, a C thread that needs no GIL, dumps every thread's stack (where
it hung) and exits with code 1, `_BACKSTOP_S` after the Python watchdog's turn.
"""

from __future__ import annotations

import asyncio
import faulthandler
import logging
import os
import signal
import threading
import time

__all__ = ["STOP_SIGNALS", "StopSignals", "Watchdog", "default_action_from_now"]

from bridge.core.threads import OnFailure, start_thread

log = logging.getLogger("bridge")

STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)

# The GIL-free backstop fires this long after the Python watchdog should have (that one
# may be waiting for a GIL the stuck thread holds, or for a logging lock it holds).
_BACKSTOP_S = 2.0


def default_action_from_now() -> None:
    """A stop signal from now on ends the process at once: the kernel does it, so it works
    even while the main thread is stuck in C code. Main thread only."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_DFL)


class Watchdog:
    """Ends the process ``timeout_s`` after `start` (logged) unless it has ended by then.

    Never disarmed: it also bounds what comes after a teardown (asyncio's executor
    shutdown, the interpreter joining a stuck thread), and it dies with the process when
    everything ends in time.
    """

    def __init__(self, *, timeout_s: float, exit_code: int = 0,
                 logger: logging.Logger = log) -> None:
        self._timeout_s = timeout_s
        self._exit_code = exit_code
        self._log = logger
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Idempotent: the bound runs from the first call."""
        if self._thread is None:
            faulthandler.dump_traceback_later(self._timeout_s + _BACKSTOP_S, exit=True)
            self._thread = start_thread("stop-watchdog", self._watch, OnFailure.STOP)

    def _watch(self) -> None:
        time.sleep(self._timeout_s)
        self._log.warning("the teardown did not finish within %g s of the stop request "
                          "(ROS's teardown is stuck?): cut short, exiting now",
                          self._timeout_s)
        for handler in (*self._log.handlers, *logging.getLogger().handlers):
            handler.flush()
        os._exit(self._exit_code)


class StopSignals:
    """Installs the stop signals on ``loop``; `requested` is set by the first one, which
    also starts the watchdog (``timeout_s``, --stop-timeout) and lets a second signal end
    the process at once."""

    def __init__(self, loop: asyncio.AbstractEventLoop, *, timeout_s: float) -> None:
        self._loop = loop
        self.watchdog = Watchdog(timeout_s=timeout_s)
        self.requested = asyncio.Event()
        self.signal_name = ""

    def install(self) -> None:
        for sig in STOP_SIGNALS:
            self._loop.add_signal_handler(sig, self._on_first_signal, sig)

    def _on_first_signal(self, sig: signal.Signals) -> None:
        self.signal_name = sig.name
        self.requested.set()
        for other in STOP_SIGNALS:
            self._loop.remove_signal_handler(other)
        default_action_from_now()
        self.watchdog.start()
