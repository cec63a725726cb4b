"""Run rclpy nodes until SIGINT, SIGTERM or SIGHUP, then exit cleanly (no traceback, exit
code 0); a child of `demo` also stops when its parent is gone, however it went.

rclpy's own signal handling raises out of `spin` (KeyboardInterrupt or
ExternalShutdownException, depending on timing). Here rclpy is told to leave signals
alone; Python handlers set a flag that a short `spin_once` loop checks, so shutdown is an
ordinary return and the nodes are destroyed in order. Once asked to stop, the process ends
within `STOP_TIMEOUT_S` whatever ROS's teardown does, and a second signal ends it at once.

Noticing a dead parent (``parent_pid``): on Linux the kernel sends SIGTERM when the parent
dies (``prctl(PR_SET_PDEATHSIG)``), even if it was killed with SIGKILL; everywhere, the
spin loop also checks that the parent pid is still ours (an orphan is re-parented).
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
from types import FrameType
from typing import Callable, Optional, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import ok, try_shutdown  # = rclpy.ok, rclpy.try_shutdown (re-exported)

from bridge.core.shutdown import STOP_SIGNALS, Watchdog, default_action_from_now

__all__ = ["PARENT_PID_ENV", "inherited_parent_pid", "ros_session", "spin_until_signal"]

POLL_S = 0.1  # how quickly a signal or a dead parent is noticed; a timed-out wait is free
STOP_TIMEOUT_S = 5.0
# Set by `demo` for its children: the pid whose death must end them.
PARENT_PID_ENV = "SLICER_ROS2_BRIDGE_PARENT_PID"
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def inherited_parent_pid() -> Optional[int]:
    """The parent pid `demo` passed down, or None when run on its own."""
    text = os.environ.get(PARENT_PID_ENV, "")
    return int(text) if text.isdigit() else None


def _signal_me_when_parent_dies(sig: int) -> None:
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, sig, 0, 0, 0)
    except (OSError, AttributeError):
        pass  # the pid check of the spin loop still notices


class ros_session:  # noqa: N801 - used as a context manager, like open()
    """``with ros_session(): ...`` initialises rclpy (with ``args``, a command line's ROS
    arguments) without its signal handlers and shuts it down at the end; SIGINT, SIGTERM
    and SIGHUP set `stop` instead of raising, and so does the death of ``parent_pid`` (if
    given)."""

    def __init__(self, *, parent_pid: Optional[int] = None,
                 args: Optional[Sequence[str]] = None) -> None:
        self.stop = threading.Event()
        self.parent_pid = parent_pid
        self.args = None if args is None else list(args)  # rclpy.init's (--ros-args ...)
        self.reason = ""
        self._previous: dict[int, object] = {}
        self._watchdog = Watchdog(timeout_s=STOP_TIMEOUT_S)

    def _on_signal(self, signum: int, frame: Optional[FrameType]) -> None:
        self.request_stop(signal.Signals(signum).name)
        default_action_from_now()  # a second signal ends the process at once

    def request_stop(self, reason: str) -> None:
        if not self.stop.is_set():
            self.reason = reason
            self.stop.set()
            self._watchdog.start()

    def parent_gone(self) -> bool:
        """Whether the parent we were started by has died (checked, and noted in `stop`)."""
        if self.parent_pid is not None and os.getppid() != self.parent_pid:
            self.request_stop(f"parent {self.parent_pid} gone")
            return True
        return False

    def __enter__(self) -> "ros_session":
        for sig in STOP_SIGNALS:
            self._previous[sig] = signal.signal(sig, self._on_signal)
        if self.parent_pid is not None:
            _signal_me_when_parent_dies(signal.SIGTERM)
            self.parent_gone()  # it may have died before the kernel was told to say so
        rclpy.init(args=self.args, signal_handler_options=SignalHandlerOptions.NO)
        return self

    def __exit__(self, *exc: object) -> None:
        try_shutdown()
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)  # type: ignore[arg-type]


def spin_until_signal(session: ros_session, nodes: Sequence[Node],
                      on_ready: Optional[Callable[[], None]] = None) -> None:
    """Spin ``nodes`` until a signal arrives, the parent dies (or rclpy is shut down
    elsewhere)."""
    executor = SingleThreadedExecutor()
    for node in nodes:
        executor.add_node(node)
    if on_ready is not None:
        on_ready()
    try:
        while not session.stop.is_set() and not session.parent_gone() and ok():
            executor.spin_once(timeout_sec=POLL_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown(timeout_sec=1.0)
        for node in nodes:
            node.destroy_node()
