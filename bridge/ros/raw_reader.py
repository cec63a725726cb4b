"""Raw subscriptions read without the interpreter's lock, in a thread of their own.

rclpy takes each raw message holding the lock: a peer's 10 MB TFMessage kept every other
thread of the daemon waiting about 20 ms (bench/attacks.py's tf_frames storm). A
`RawReader` waits for and takes its subscriptions' messages with rcl's own wait set and take,
the lock released (the compiled `bridge.ros._rcl_reader`), and hands each to its topic's callback
as a read-only view, valid during the call (`RawTopic`), or, for a `BatchTopic`, every message
of that topic waiting at once, as one list: a burst costs one callback.

The subscriptions are real ones on the given node (the ROS graph lists them), made outside
rclpy's `Node.create_subscription`, so no executor waits on them too. `available()` says
whether the compiled module was built here; without it (or with ``SLICER_BRIDGE_RCLPY_TAKE=1``)
the caller subscribes through rclpy.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence, Union

from rclpy.node import Node
from rclpy.qos import QoSProfile

log = logging.getLogger(__name__)

# The compiled module's interface this wrapper expects (`_rcl_reader.INTERFACE`).
READER_INTERFACE = 2
_WAIT_S = 0.1  # at most this long between waits: a wake-up rcl missed costs no more
_ERROR_LOG_INTERVAL_S = 5.0

try:  # imported after rclpy (above), which has loaded the rcl libraries it links to
    from bridge.ros import _rcl_reader
except ImportError:
    _rcl_reader = None  # type: ignore[assignment]


# Set to 1 to take every raw subscription through rclpy (to compare, or to rule it out).
RCLPY_TAKE_ENV = "SLICER_BRIDGE_RCLPY_TAKE"


def available() -> bool:
    """Whether the compiled reader was built here, for this wrapper (and not ruled out)."""
    return (_rcl_reader is not None
            and getattr(_rcl_reader, "INTERFACE", None) == READER_INTERFACE
            and os.environ.get(RCLPY_TAKE_ENV, "") != "1")


@dataclass(frozen=True)
class RawTopic:
    topic: str
    msg_type: Any  # the message class
    qos: QoSProfile
    callback: Callable[[memoryview], None]  # runs in the reader's thread


# A batch: at most this many messages, and none after the one that passes the byte bound.
BATCH_MAX_MESSAGES = 256
BATCH_MAX_BYTES = 1024 * 1024


@dataclass(frozen=True)
class BatchTopic:
    """A topic whose callback gets every message waiting, copied, in order (a list of at
    least one; see `BATCH_MAX_MESSAGES`), in the reader's thread."""

    topic: str
    msg_type: Any
    qos: QoSProfile
    callback: Callable[[list[bytes]], None]


class RawReader:
    """Subscribes raw to `topics` on `node` and calls each one's callback, in the thread
    ``name``, with each message's bytes (a `BatchTopic`'s: with those waiting together).
    `close` stops the thread and destroys the subscriptions; it must run before the node is
    destroyed (RosNode.stop sees to it)."""

    def __init__(self, node: Node, topics: Sequence[Union[RawTopic, BatchTopic]],
                 name: str) -> None:
        if not available():
            raise RuntimeError("the compiled rcl reader is not built here")
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
        from rclpy.type_support import check_is_valid_msg_type

        self._topics = list(topics)
        self._subscriptions: list[Any] = []
        context = node.context.handle
        assert context is not None
        self._wake = _rclpy.GuardCondition(context)
        try:
            with node.handle:
                for topic in self._topics:
                    check_is_valid_msg_type(topic.msg_type)
                    self._subscriptions.append(_rclpy.Subscription(
                        node.handle, topic.msg_type, topic.topic,
                        topic.qos.get_c_qos_profile()))
            self._reader = _rcl_reader.RawReader(context, self._subscriptions, self._wake)
        except Exception:
            self._destroy_handles()
            raise
        self._stopping = threading.Event()
        self._thread: Optional[threading.Thread] = threading.Thread(
            target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        last_logged = -_ERROR_LOG_INTERVAL_S
        unlogged = 0
        while not self._stopping.is_set():
            try:
                taken = self._reader.take(_WAIT_S)
            except _rcl_reader.ReaderError:
                if not self._stopping.is_set():
                    log.exception("the raw reader of %s stopped",
                                  ", ".join(t.topic for t in self._topics))
                return
            if taken is None:
                continue
            index, view = taken
            topic = self._topics[index]
            try:
                if isinstance(topic, BatchTopic):
                    first = view.tobytes()
                    view.release()
                    topic.callback([first, *self._reader.take_more(
                        index, BATCH_MAX_MESSAGES - 1, max(0, BATCH_MAX_BYTES - len(first)))])
                else:
                    topic.callback(view)
            except _rcl_reader.ReaderError:
                if not self._stopping.is_set():
                    log.exception("the raw reader of %s stopped", topic.topic)
                return
            except Exception:
                # One failing message must not stop the topic: log it and go on.
                now = time.monotonic()
                if now - last_logged >= _ERROR_LOG_INTERVAL_S:
                    more = f" ({unlogged} more since the last report)" if unlogged else ""
                    log.exception("a callback of %s failed; the reader goes on%s",
                                  self._topics[index].topic, more)
                    last_logged, unlogged = now, 0
                else:
                    unlogged += 1
            finally:
                try:
                    view.release()
                except BufferError:  # a callback kept a view: a bug, the buffer is reused
                    log.error("a callback of %s kept a view on the reader's buffer",
                              self._topics[index].topic)

    @property
    def closed(self) -> bool:
        return self._thread is None

    def close(self) -> None:
        """Stop the thread (a wait in progress ends at once), then free the reader and
        destroy the subscriptions. Idempotent."""
        thread, self._thread = self._thread, None
        if thread is None:
            return
        self._stopping.set()
        self._wake.trigger_guard_condition()
        thread.join(timeout=5.0)
        if thread.is_alive():  # a callback that does not return: leave the handles be
            log.error("the raw reader of %s did not stop within 5 s",
                      ", ".join(t.topic for t in self._topics))
            return
        self._reader.close()
        self._destroy_handles()

    def _destroy_handles(self) -> None:
        for subscription in self._subscriptions:
            subscription.destroy_when_not_in_use()
        self._subscriptions = []
        self._wake.destroy_when_not_in_use()
