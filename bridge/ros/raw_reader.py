"""Raw subscriptions read without the interpreter's lock, in a thread of their own.

rclpy takes each raw message holding the lock: a peer's 10 MB TFMessage kept every other
thread of the daemon waiting about 20 ms (bench/attacks.py's tf_frames storm). A
`RawReader` waits for its subscriptions' messages (told by the middleware's on-new-message
callback) and takes them with rcl's take, the lock released (the compiled
`bridge.ros._rcl_reader`), and hands each to its topic's callback as a read-only view, valid
during the call (`RawTopic`), or, for a `BatchTopic`, every message of that topic waiting at
once, as one list: a burst costs one callback. A `BatchTopic`'s native lane is run in the
middleware's callback itself, on its thread, while the reader's thread waits (no thread
wake per message); what the lane leaves to Python comes to the reader's thread, in order.

The subscriptions are real ones on the given node (the ROS graph lists them), made outside
rclpy's `Node.create_subscription`, so no executor waits on them too. `available()` says
whether the compiled module was built here; without it (or with the daemon's `--ros-take rclpy`)
the caller subscribes through rclpy.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence, Union

from rclpy.node import Node
from rclpy.qos import QoSProfile

from bridge.core.threads import OnFailure, start_thread

log = logging.getLogger(__name__)

# The compiled module's interface this wrapper expects (`_rcl_reader.INTERFACE`).
READER_INTERFACE = 5
_WAIT_S = 0.1  # at most this long between waits: a wake-up rcl missed costs no more
_ERROR_LOG_INTERVAL_S = 5.0

try:  # imported after rclpy (above), which has loaded the rcl libraries it links to
    from bridge.ros import _rcl_reader
except ImportError:
    _rcl_reader = None  # type: ignore[assignment]


class ReaderStopped(RuntimeError):
    """The reader's ROS wait or take failed: its topics would go silent for good."""


class _NotBuilt(RuntimeError):
    """Stands for the compiled reader's error where it is not built (never raised)."""


# What a reader raises when rcl refuses it (a take, the middleware's callback).
ReaderError: type[RuntimeError] = (_rcl_reader.ReaderError if _rcl_reader is not None
                                   else _NotBuilt)


def available() -> bool:
    """Whether the compiled reader was built here, for this wrapper (`--ros-take rclpy`
    rules it out in `RosNode`)."""
    return (_rcl_reader is not None
            and getattr(_rcl_reader, "INTERFACE", None) == READER_INTERFACE)


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
    # A native lane (bridge/core/native_stream.py's `PoseLane`) that takes the messages it
    # can without the interpreter, in the middleware's callback or the reader's thread; the
    # callback gets the rest, and an empty list when the lane asks to settle.
    native: Any = None


Topic = Union[RawTopic, BatchTopic]


class RawSubscription:
    """One topic a reader takes (`RawReader.add`); `close` ends it."""

    def __init__(self, reader: RawReader, topic: Topic, handle: Any) -> None:
        self.reader = reader
        self.topic = topic
        self.handle = handle

    def close(self) -> None:
        self.reader.remove(self)


class RawReader:
    """Subscribes raw to `topics` on `node` and calls each one's callback, in the thread
    ``name``, with each message's bytes (a `BatchTopic`'s: with those waiting together).
    More topics come and go while it runs (`add`, `remove`). `close` stops the thread and
    destroys the subscriptions; it must run before the node is destroyed (RosNode.stop sees
    to it)."""

    def __init__(self, node: Node, topics: Sequence[Topic], name: str, *,
                 batches: bool = False) -> None:
        if not available():
            raise RuntimeError("the compiled rcl reader is not built here")
        self._batches = batches  # its topics are all BatchTopics, or all RawTopics
        for topic in topics:
            self._check_kind(topic)
        self._node = node
        self._taken: list[RawSubscription] = []  # in the compiled reader's order
        # Changes to what is taken, applied by the reader's thread between two takes.
        self._lock = threading.Lock()
        self._adding: list[RawSubscription] = []
        self._removing: dict[RawSubscription, threading.Event] = {}
        try:
            for topic in topics:
                self._taken.append(RawSubscription(self, topic, self._subscribe(topic)))
            self._reader = _rcl_reader.RawReader([s.handle for s in self._taken])
            self._reader.set_subscriptions([s.handle for s in self._taken],
                                           self._handlers(self._taken))
        except Exception:
            self._destroy_handles()
            raise
        self._stopping = threading.Event()
        # Its topics would go silent for good if the thread died: the daemon stops instead.
        self._thread: Optional[threading.Thread] = start_thread(name, self._run,
                                                                OnFailure.STOP)

    def _check_kind(self, topic: Topic) -> None:
        if isinstance(topic, BatchTopic) != self._batches:
            raise TypeError(f"topic: expected a {'BatchTopic' if self._batches else 'RawTopic'}"
                            f" (this reader's kind), got a {type(topic).__name__}")

    def _subscribe(self, topic: Topic) -> Any:
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
        from rclpy.type_support import check_is_valid_msg_type

        check_is_valid_msg_type(topic.msg_type)
        with self._node.handle:
            return _rclpy.Subscription(self._node.handle, topic.msg_type, topic.topic,
                                       topic.qos.get_c_qos_profile())

    @property
    def count(self) -> int:
        """Topics taken or about to be."""
        with self._lock:
            return len(self._taken) + len(self._adding) - len(self._removing)

    def add(self, topic: Topic) -> RawSubscription:
        """Take `topic` too (any thread): its messages are taken from the reader's next
        turn on; those that came meanwhile wait in the subscription. ReaderError if the
        middleware cannot tell its new messages (nothing is left subscribed then)."""
        self._check_kind(topic)
        subscription = RawSubscription(self, topic, self._subscribe(topic))
        try:
            _rcl_reader.check_tells_new_messages(subscription.handle)
        except _rcl_reader.ReaderError:
            subscription.handle.destroy_when_not_in_use()
            raise
        with self._lock:
            if self._thread is None:
                subscription.handle.destroy_when_not_in_use()
                raise RuntimeError("the raw reader is closed")
            self._adding.append(subscription)
        self._reader.wake()
        return subscription

    def remove(self, subscription: RawSubscription) -> None:
        """Stop taking a topic and destroy its subscription. From another thread, returns
        once the reader takes it no more; from the reader's own (a callback), at once, and
        nothing more is taken of it after that callback. Idempotent."""
        done = threading.Event()
        with self._lock:
            if subscription in self._adding:
                self._adding.remove(subscription)
                subscription.handle.destroy_when_not_in_use()
                return
            if subscription not in self._taken or subscription in self._removing:
                return
            self._removing[subscription] = done
            thread = self._thread
        self._reader.wake()
        if thread is not None and thread is not threading.current_thread():
            if not done.wait(5.0):
                log.error("the raw reader did not let go of %s within 5 s",
                          subscription.topic.topic)

    def _apply_changes(self) -> None:
        """Reader thread, between two takes: what `add` and `remove` asked for."""
        with self._lock:
            adding, self._adding = self._adding, []
            removing, self._removing = self._removing, {}
        taken = [s for s in self._taken if s not in removing] + adding
        self._reader.set_subscriptions([s.handle for s in taken], self._handlers(taken))
        self._taken = taken
        for subscription, done in removing.items():
            subscription.handle.destroy_when_not_in_use()
            done.set()

    def _run(self) -> None:
        last_logged = -_ERROR_LOG_INTERVAL_S
        unlogged = 0
        reader = self._reader
        while not self._stopping.is_set():
            try:
                if self._adding or self._removing:
                    self._apply_changes()
                taken: Optional[tuple[int, Any]] = (
                    reader.take_batch(_WAIT_S, BATCH_MAX_MESSAGES, BATCH_MAX_BYTES)
                    if self._batches else reader.take(_WAIT_S))
            except _rcl_reader.ReaderError as error:
                if not self._stopping.is_set():
                    raise ReaderStopped(f"the raw reader of {self._names()}: {error}") from None
                return
            if taken is None:
                continue
            index, data = taken  # a view (RawTopic) or a list of bytes (BatchTopic)
            topic = self._taken[index].topic
            try:
                topic.callback(data)
            except _rcl_reader.ReaderError as error:
                if not self._stopping.is_set():
                    raise ReaderStopped(f"the raw reader of {topic.topic}: {error}") from None
                return
            except Exception:
                # One failing message must not stop the topic: log it and go on.
                now = time.monotonic()
                if now - last_logged >= _ERROR_LOG_INTERVAL_S:
                    more = f" ({unlogged} more since the last report)" if unlogged else ""
                    log.exception("a callback of %s failed; the reader goes on%s",
                                  topic.topic, more)
                    last_logged, unlogged = now, 0
                else:
                    unlogged += 1
            finally:
                if not self._batches:
                    try:
                        data.release()
                    except BufferError:  # a callback kept a view: a bug, the buffer is reused
                        log.error("a callback of %s kept a view on the reader's buffer",
                                  topic.topic)

    @staticmethod
    def _handlers(taken: Sequence[RawSubscription]) -> Optional[list[Any]]:
        natives = [getattr(s.topic, "native", None) for s in taken]
        if not any(n is not None for n in natives):
            return None
        return [n.handler if n is not None else None for n in natives]

    def _names(self) -> str:
        return ", ".join(s.topic.topic for s in self._taken) or "no topic"

    @property
    def closed(self) -> bool:
        return self._thread is None

    def close(self) -> None:
        """Stop the thread (a wait in progress ends at once), then free the reader and
        destroy the subscriptions. Idempotent."""
        with self._lock:
            thread, self._thread = self._thread, None
        if thread is None:
            return
        self._stopping.set()
        self._reader.wake()
        thread.join(timeout=5.0)
        if thread.is_alive():  # a callback that does not return: leave the handles be
            log.error("the raw reader of %s did not stop within 5 s", self._names())
            return
        self._reader.close()
        self._destroy_handles()

    def _destroy_handles(self) -> None:
        with self._lock:
            removing = self._removing
            doomed = [*self._taken, *self._adding]
            self._taken, self._adding, self._removing = [], [], {}
        for subscription in doomed:
            subscription.handle.destroy_when_not_in_use()
        for done in removing.values():
            done.set()
