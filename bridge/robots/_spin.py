"""Run rclpy nodes until SIGINT or SIGTERM, then exit cleanly (no traceback, exit code 0).

rclpy's own signal handling raises out of `spin` (KeyboardInterrupt or
ExternalShutdownException, depending on timing). Here rclpy is told to leave signals
alone; Python handlers set a flag that a short `spin_once` loop checks, so shutdown is an
ordinary return and the nodes are destroyed in order.
"""

from __future__ import annotations

import signal
import threading
from types import FrameType
from typing import Callable, Optional, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

__all__ = ["ros_session", "spin_until_signal"]

POLL_S = 0.1  # how quickly a signal is noticed; a timed-out wait costs nothing


class ros_session:  # noqa: N801 - used as a context manager, like open()
    """``with ros_session(): ...`` initialises rclpy without its signal handlers and
    shuts it down at the end; SIGINT and SIGTERM set `stop` instead of raising."""

    def __init__(self) -> None:
        self.stop = threading.Event()
        self._previous: dict[int, object] = {}

    def _on_signal(self, signum: int, frame: Optional[FrameType]) -> None:
        self.stop.set()

    def __enter__(self) -> "ros_session":
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.signal(sig, self._on_signal)
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        return self

    def __exit__(self, *exc: object) -> None:
        rclpy.try_shutdown()
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)  # type: ignore[arg-type]


def spin_until_signal(session: ros_session, nodes: Sequence[Node],
                      on_ready: Optional[Callable[[], None]] = None) -> None:
    """Spin ``nodes`` until a signal arrives (or rclpy is shut down elsewhere)."""
    executor = SingleThreadedExecutor()
    for node in nodes:
        executor.add_node(node)
    if on_ready is not None:
        on_ready()
    try:
        while not session.stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=POLL_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown(timeout_sec=1.0)
        for node in nodes:
            node.destroy_node()


