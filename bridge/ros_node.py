"""The daemon's one rclpy node, with its executor spinning in a thread of its own.

This is the only module that starts or stops ROS. It keeps rclpy's global state out of the
way (a private `Context`) and leaves signal handling to the daemon's event loop.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Optional

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

log = logging.getLogger(__name__)

# How often an idle executor thread looks at the stop flag.
_SPIN_TIMEOUT_S = 0.1


@dataclass(frozen=True)
class RosOptions:
    node_name: str = "slicer_bridge"
    namespace: str = ""


class RosNode:
    def __init__(self, options: RosOptions) -> None:
        self.options = options
        self.context = Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        try:
            # Undeclared parameters are refused: clients declare them (parameter server).
            self.node = Node(options.node_name, namespace=options.namespace or None,
                             context=self.context)
        except Exception:
            rclpy.try_shutdown(context=self.context)
            raise
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread: Optional[threading.Thread] = None
        self._stopping = threading.Event()

    @property
    def fully_qualified_name(self) -> str:
        return self.node.get_fully_qualified_name()

    def start(self) -> None:
        self._thread = threading.Thread(target=self._spin, name="ros-executor", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            while not self._stopping.is_set() and self.context.ok():
                self.executor.spin_once(timeout_sec=_SPIN_TIMEOUT_S)
        except ExternalShutdownException:
            pass
        except Exception:  # keep the daemon's log honest if the executor dies
            log.exception("the ROS executor stopped with an error")

    def stop(self) -> None:
        # The executor thread must be out of its callbacks before the executor's handles
        # are destroyed: shutting down under a running callback raises InvalidHandle.
        self._stopping.set()
        self.executor.wake()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=2.0)
        try:
            self.node.destroy_node()
        finally:
            rclpy.try_shutdown(context=self.context)

    def subscriber_count(self, topic: str) -> int:
        return self.node.count_subscribers(topic)

    def topic_types(self, topic: str) -> list[str]:
        """The types the ROS graph knows for `topic` (any node's publishers or subscribers)."""
        for name, types in self.node.get_topic_names_and_types():
            if name == topic:
                return list(types)
        return []

    def resolve_topic(self, topic: str) -> str:
        """The fully qualified name of `topic` for this node (namespace, ~ expansion);
        raises `rclpy.exceptions.InvalidTopicNameException` for an invalid name."""
        from rclpy.expand_topic_name import expand_topic_name
        from rclpy.validate_full_topic_name import validate_full_topic_name

        full = expand_topic_name(topic, self.node.get_name(), self.node.get_namespace())
        validate_full_topic_name(full)
        return full
