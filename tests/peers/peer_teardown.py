"""How a peer ends its ROS session: stop signals are ignored from the first step of the
teardown on, so the teardown always runs to its end.

Why: a test's cleanup sends SIGINT to every peer still running, and a peer that already
finished its job is then often tearing down. Interrupted there, it died midway with its
Fast DDS shared-memory port half closed. The next process given the same participant id
replaces that port, and Fast DDS 2.14 in a long-lived process that wrote to it (the
daemon) keeps writing into the replaced one: nothing it sends reaches the newcomer, nor
any later one with that id (eProsima/Fast-DDS#5053; seen as NO_RESPONSE in
test_served_action_answers.py). A teardown takes tens of milliseconds; the harness kills
a peer that takes longer than its stop timeout anyway.
"""

from __future__ import annotations

import signal
from typing import Optional

import rclpy
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.node import Node


def end_ros(node: Node, executor: Optional[Executor] = None) -> None:
    """Destroy `node` (after shutting `executor` down) and shut rclpy down, deaf to
    SIGINT and SIGTERM."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    if executor is not None:
        executor.shutdown(timeout_sec=0)
    node.destroy_node()
    rclpy.try_shutdown()


def spin_until_stopped(node: Node) -> None:
    """Spin `node` until SIGINT (the harness's stop) or an external shutdown, then
    `end_ros`."""
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        end_ros(node)
