"""The daemon's rclpy nodes, each with its executor spinning in a thread of its own.

This is the only module that starts or stops ROS. It keeps rclpy's global state out of the
way (a private `Context`) and leaves signal handling to the daemon's event loop.

Two nodes, two executors:

* ``node`` (``<name>``): services, parameters, tf, robots, publishers; rclpy's
  SingleThreadedExecutor, which runs the coroutine callbacks the served services need;
* ``stream_node`` (``<name>_streams``): the subscriptions streamed to clients, under
  rclpy's C++ EventsExecutor. The SingleThreadedExecutor rebuilds its wait set in Python on
  every wake-up (about 0.35 ms of CPU per message received, and a share of a core for a
  thousand idle subscriptions); the EventsExecutor queues events in C++ and calls Python
  only for the callback (about 0.05 ms). Jazzy's EventsExecutor cannot run coroutine
  service callbacks (ros2/rclpy#1473, fixed after 7.1.x), hence the split.

Raw readers (bridge/ros/raw_reader.py) take some of ``stream_node``'s raw subscriptions in
threads of their own, without the interpreter's lock: /tf (`raw_reader`), and up to
`MAX_READ_STREAMS` streamed poses, all in one thread (`read_stream`). `stop` closes them
before the nodes go.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from functools import partial
from typing import Optional, Sequence, Union

import rclpy
from rclpy.client import Client
from rclpy.context import Context
from rclpy.executors import (ConditionReachedException, Executor, ExternalShutdownException,
                             ShutdownException, SingleThreadedExecutor, TimeoutException)
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.service import Service
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from rclpy.utilities import try_shutdown

from bridge.core.threads import OnFailure, start_thread
from bridge.ros.ros_args import domain_id_from_environment
from bridge.platform.shm_locks import ports_of_domains
from bridge.platform.shm_ports import release_left_locks
from bridge.ros.raw_reader import (BatchTopic, RawReader, RawSubscription, RawTopic,
                                   ReaderError)
from protocol.commands import OutOfRangeError
from bridge.ros.raw_reader import available as raw_reader_available

log = logging.getLogger(__name__)

# How often the idle EventsExecutor's thread looks at the stop flag.
_SPIN_TIMEOUT_S = 0.1
# After an error escaping a callback, a pause so that a repeating one cannot spin the CPU.
_ERROR_PAUSE_S = 0.05
# A callback failing on every message is reported once per interval, with a count.
_ERROR_LOG_INTERVAL_S = 5.0

# Topics the one stream reader takes (`read_stream`); more go through the EventsExecutor:
# the reader tries each of its topics in turn when woken, which costs more as they grow.
MAX_READ_STREAMS = 64

RosEntity = Union[Subscription, Publisher, Client, Service]


def _topic_remaps(ros_args: tuple[str, ...]) -> Optional[list[str]]:
    """The topic remapping rules of `ros_args` (not __node/__ns, not parameters)."""
    rules: list[str] = []
    for flag, value in zip(ros_args, ros_args[1:]):
        if flag in ("-r", "--remap") and not value.startswith(("__node:=", "__ns:=",
                                                                  "__name:=")):
            rules += ["-r", value]
    return ["--ros-args", *rules] if rules else None


@dataclass(frozen=True)
class RosOptions:
    node_name: str = "slicer_bridge"
    namespace: str = ""
    # What followed --ros-args: remaps (__node, __ns, topics), parameters, ... for `node`.
    ros_args: tuple[str, ...] = ()
    # Raw subscriptions taken by rcl in reader threads where built (--ros-take rcl).
    rcl_take: bool = True


class RosArgumentsError(Exception):
    """rcl refused the --ros-args (an unknown flag, a bad remap); its text says which."""


class RosNode:
    def __init__(self, options: RosOptions) -> None:
        self.options = options
        self.context = Context()
        # Not sys.argv: its --ros-args are the main node's alone (a global __node remap would
        # give the stream node the same name).
        # One a killed ROS process left taken would hang init.
        release_left_locks(ports_of_domains([domain_id_from_environment()]))
        rclpy.init(args=["slicer-ros2-bridge"], context=self.context,
                   signal_handler_options=SignalHandlerOptions.NO)
        try:
            # Undeclared parameters are refused: clients declare them (parameter server).
            self.node = Node(options.node_name, namespace=options.namespace or None,
                             context=self.context,
                             cli_args=["--ros-args", *options.ros_args] if options.ros_args
                             else None)
            # Same namespace and topic remaps as `node`, so a client's remapped topic is
            # streamed from where `node` would publish or subscribe it.
            self.stream_node = Node(f"{self.node.get_name()}_streams",
                                    namespace=self.node.get_namespace(), context=self.context,
                                    start_parameter_services=False,
                                    cli_args=_topic_remaps(options.ros_args))
        except Exception as error:
            try_shutdown(context=self.context)
            if options.ros_args and type(error).__name__ in ("UnknownROSArgsError",
                                                             "RCLError", "InvalidHandle"):
                raise RosArgumentsError(f"--ros-args {' '.join(options.ros_args)}: "
                                        f"{error}") from None
            raise
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.stream_executor = EventsExecutor(context=self.context)
        self.stream_executor.add_node(self.stream_node)
        self._thread: Optional[threading.Thread] = None
        self._stream_thread: Optional[threading.Thread] = None
        self._stopping = threading.Event()
        self._raw_readers: list[RawReader] = []
        self._stream_reader: Optional[RawReader] = None  # made by the first `read_stream`
        self._stream_reader_lock = threading.Lock()

    @property
    def fully_qualified_name(self) -> str:
        return self.node.get_fully_qualified_name()

    def start(self) -> None:
        # `_spin` logs a failing callback and goes on; what escapes it runs it again.
        self._thread = start_thread("ros-executor", partial(self._spin, self.executor),
                                    OnFailure.RESTART)
        self._stream_thread = start_thread("ros-streams",
                                           partial(self._spin, self.stream_executor),
                                           OnFailure.RESTART)

    def _spin(self, executor: Executor) -> None:
        last_logged = -_ERROR_LOG_INTERVAL_S
        unlogged = 0
        while not self._stopping.is_set() and self.context.ok():
            try:
                self._spin_once(executor)
            except ExternalShutdownException:
                return
            except Exception:
                # One failing callback must not stop every bridge: log it and keep spinning.
                if self._stopping.is_set() or not self.context.ok():
                    return
                now = time.monotonic()
                if now - last_logged >= _ERROR_LOG_INTERVAL_S:
                    more = f" ({unlogged} more since the last report)" if unlogged else ""
                    log.exception("a ROS callback failed; the executor goes on%s", more)
                    last_logged, unlogged = now, 0
                else:
                    unlogged += 1
                time.sleep(_ERROR_PAUSE_S)

    def _spin_once(self, executor: Executor) -> None:
        """Run one ready callback, or return when `stop` wakes the executor. The Python
        executor waits with no timeout: one that looked at the stop flag ten times a second
        rebuilt its wait set in Python each time, about 0.4% of a core for an idle daemon.
        (Its `spin_until_future_complete` adds a callback to the future at every turn.)"""
        if not isinstance(executor, SingleThreadedExecutor):
            # The C++ EventsExecutor is woken by no condition or future (rclpy 7.1), and
            # its turn costs no Python wait set.
            executor.spin_once(timeout_sec=_SPIN_TIMEOUT_S)
            return
        try:
            handler, _, _ = executor.wait_for_ready_callbacks(None, None, self._stopping.is_set)
        except (ConditionReachedException, ShutdownException, TimeoutException):
            return
        handler()
        if handler.exception() is not None:
            raise handler.exception()

    def raw_reader(self, topics: Sequence[Union[RawTopic, BatchTopic]], name: str, *,
                   batches: bool = False) -> Optional[RawReader]:
        """`topics` subscribed raw on ``stream_node`` and read without the interpreter's
        lock in the thread ``name`` (bridge/ros/raw_reader.py); None where the compiled reader
        is not built (then subscribe through rclpy). Closed by `stop` at the latest."""
        if not (self.options.rcl_take and raw_reader_available()):
            return None
        try:
            reader = RawReader(self.stream_node, topics, name, batches=batches)
        except ReaderError as error:
            log.warning("%s taken through rclpy: %s", name, error)
            return None
        # Those closed by their owners meanwhile are forgotten: a bridge each, made and removed.
        self._raw_readers = [r for r in self._raw_readers if not r.closed]
        self._raw_readers.append(reader)
        return reader

    def read_stream(self, topic: BatchTopic) -> Optional[RawSubscription]:
        """`topic` subscribed raw on ``stream_node`` and taken by the daemon's one stream
        reader, a burst at a time, without the interpreter's lock (bridge/ros/raw_reader.py);
        None where the compiled reader is not built, or it takes `MAX_READ_STREAMS` topics
        already, or the middleware cannot tell it new messages (then subscribe through
        rclpy): one thread for all. `RawSubscription.close` ends it."""
        if not (self.options.rcl_take and raw_reader_available()) or self._stopping.is_set():
            return None
        with self._stream_reader_lock:
            reader = self._stream_reader
            if reader is None:
                reader = self._stream_reader = self.raw_reader([], name="ros-stream-reader",
                                                               batches=True)
                if reader is None:
                    return None
            if reader.count >= MAX_READ_STREAMS:
                return None
            try:
                return reader.add(topic)
            except ReaderError as error:
                log.warning("%s is taken through rclpy: %s", topic.topic, error)
                return None

    def destroy(self, entity: RosEntity) -> None:
        """Destroy a subscription, publisher, client or service of the node.

        Done in the executor thread, between two waits: destroyed from another thread while
        the executor builds its wait set, an entity's QoS event handlers raise InvalidHandle.
        """
        if self._stopping.is_set():
            return  # stop() destroys the node and everything on it
        streamed = isinstance(entity, Subscription) and entity in self.stream_node.subscriptions
        node, executor, thread = ((self.stream_node, self.stream_executor, self._stream_thread)
                                  if streamed else (self.node, self.executor, self._thread))
        if thread is None or not thread.is_alive() or threading.current_thread() is thread:
            self._destroy_now(node, entity)
        else:
            executor.create_task(self._destroy_now, node, entity)

    @staticmethod
    def _destroy_now(node: Node, entity: RosEntity) -> None:
        if isinstance(entity, Subscription):
            node.destroy_subscription(entity)
        elif isinstance(entity, Publisher):
            node.destroy_publisher(entity)
        elif isinstance(entity, Client):
            node.destroy_client(entity)
        else:
            node.destroy_service(entity)

    def stop(self) -> None:
        # The executor thread must be out of its callbacks before the executor's handles
        # are destroyed: shutting down under a running callback raises InvalidHandle.
        self._stopping.set()
        for reader in self._raw_readers:  # their subscriptions go before the node
            reader.close()
        self.executor.wake()
        self.stream_executor.wake()
        for thread in (self._thread, self._stream_thread):
            if thread is not None:
                thread.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=2.0)
        self.stream_executor.shutdown(timeout_sec=2.0)
        try:
            self.node.destroy_node()
            self.stream_node.destroy_node()
        finally:
            try_shutdown(context=self.context)

    def subscriber_count(self, topic: str) -> int:
        return self.node.count_subscribers(topic)

    def topic_types(self, topic: str) -> list[str]:
        """The types the ROS graph knows for `topic` (any node's publishers or subscribers)."""
        for name, types in self.node.get_topic_names_and_types():
            if name == topic:
                return list(types)
        return []

    def resolve_name(self, name: str, field: str) -> str:
        """A topic, service, action or node name -> fully qualified; relative names resolve
        under the daemon's namespace (``PSM1/x`` with namespace ``/lab`` -> ``/lab/PSM1/x``).
        The one place a client's name is resolved: an invalid one is refused naming `field`."""
        try:
            return self.resolve_topic(name)
        except Exception as error:  # rclpy raises several name-validation exceptions
            raise OutOfRangeError(field, "a valid ROS name", f"{name!r} ({error})") from None

    def resolve_topic(self, topic: str) -> str:
        """The fully qualified name of `topic` for this node (namespace, ~ expansion);
        raises `rclpy.exceptions.InvalidTopicNameException` for an invalid name."""
        from rclpy.expand_topic_name import expand_topic_name
        from rclpy.validate_full_topic_name import validate_full_topic_name

        full = expand_topic_name(topic, self.node.get_name(), self.node.get_namespace())
        validate_full_topic_name(full)
        return full
