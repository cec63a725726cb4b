"""The raw reader (bridge/ros/raw_reader.py): subscriptions taken without the interpreter's lock,
fed by real publishers in other processes. What it saves (the lock rclpy held about 20 ms for
each 10 MB message) is measured by bench/attacks.py's tf_frames storm, not here."""

from __future__ import annotations

import logging
import select
import socket
import threading
from typing import Any, Callable, Iterator

import pytest
from geometry_msgs.msg import PoseStamped
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from tf2_msgs.msg import TFMessage

from bridge.core import native_stream
from bridge.ros import raw_reader
from bridge.ros.qos import TF_QOS
from bridge.ros.raw_reader import BatchTopic, RawReader, RawSubscription, RawTopic
from bridge.ros.ros_node import RosNode, RosOptions
from protocol.framing import Decoder
from support import Processes, scaled, wait_until

pytestmark = [pytest.mark.ros, pytest.mark.skipif(
    raw_reader._rcl_reader is None,
    reason="the rcl reader was not built (no rcl headers, C compiler or Cython at install)")]


@pytest.fixture
def ros() -> Iterator[RosNode]:
    node = RosNode(RosOptions(node_name="raw_reader_test"))
    node.start()
    try:
        yield node
    finally:
        node.stop()


def test_two_topics_are_read_in_turn_and_close_removes_them(ros: RosNode,
                                                            processes: Processes) -> None:
    poses: list[float] = []
    chains: list[list[str]] = []
    threads: set[str] = set()
    got_both = threading.Event()

    def on_pose(view: memoryview) -> None:
        threads.add(threading.current_thread().name)
        poses.append(deserialize_message(bytes(view), PoseStamped).pose.position.x)
        if chains:
            got_both.set()

    def on_tf(view: memoryview) -> None:
        threads.add(threading.current_thread().name)
        chains.append([t.child_frame_id for t in deserialize_message(bytes(view),
                                                                     TFMessage).transforms])
        if poses:
            got_both.set()

    reader = ros.raw_reader([RawTopic("/rr_pose", PoseStamped, TF_QOS, on_pose),
                             RawTopic("/tf", TFMessage, TF_QOS, on_tf)], name="rr-test")
    assert reader is not None
    # The subscriptions are real ones of the daemon's stream node: the graph lists them.
    assert ros.stream_node.count_subscribers("/rr_pose") == 1
    processes.python("poses", "stream_publisher.py", "/rr_pose", "100", "--count", "100000")
    processes.python("chain", "tf_chain_publisher.py", "rr_", "--rate", "100", "--no-static")
    assert got_both.wait(scaled(30)), f"poses {len(poses)}, tf messages {len(chains)}"
    wait_until(lambda: len(poses) >= 20 and len(chains) >= 20, timeout=30,
               what="20 messages of each topic")
    assert threads == {"rr-test"}
    assert all(chain == ["rr_link1", "rr_tool"] for chain in chains), chains[:3]
    # stream_publisher.py: the n-th pose has x = n * 1e-6 m, in the order sent.
    assert poses == sorted(poses) and len(set(poses)) == len(poses), poses[:10]

    reader.close()
    seen = len(poses)
    wait_until(lambda: ros.stream_node.count_subscribers("/rr_pose") == 0, timeout=10,
               what="the reader's subscription gone from the graph")
    assert len(poses) == seen  # nothing is handed on after close
    reader.close()  # idempotent


def test_a_failing_callback_is_logged_and_the_reader_goes_on(
        ros: RosNode, processes: Processes, caplog: pytest.LogCaptureFixture) -> None:
    taken: list[int] = []
    healthy = threading.Event()

    def failing(view: memoryview) -> None:
        taken.append(len(view))
        if len(taken) >= 5:
            healthy.set()
        raise ValueError("a callback bug")

    with caplog.at_level(logging.ERROR, logger="bridge.ros.raw_reader"):
        reader = ros.raw_reader([RawTopic("/rr_failing", PoseStamped, TF_QOS, failing)],
                                name="rr-failing")
        assert reader is not None
        processes.python("poses", "stream_publisher.py", "/rr_failing", "100", "--count",
                         "100000")
        assert healthy.wait(scaled(30)), f"the reader stopped after {len(taken)} messages"
    failures = [r for r in caplog.records if "a callback of /rr_failing failed" in r.getMessage()]
    assert failures and failures[0].exc_info is not None
    assert failures[0].exc_info[0] is ValueError
    assert len(failures) == 1, [r.getMessage() for r in failures]  # once per 5 s


def test_stop_closes_a_reader_that_waits(ros: RosNode) -> None:
    """RosNode.stop closes its readers before the node goes (a wait in progress ends at
    once): no message ever came here."""
    reader = ros.raw_reader([RawTopic("/rr_silent", PoseStamped, TF_QOS, lambda view: None)],
                            name="rr-silent")
    assert reader is not None
    thread = reader._thread
    assert thread is not None and thread.is_alive()
    ros.stop()
    assert not thread.is_alive()


def _deep_reliable() -> QoSProfile:
    return QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                      history=HistoryPolicy.KEEP_LAST)


def _batched(ros: RosNode, processes: Processes, topic: str,
             count: int) -> list[list[float]]:
    """The batches a `BatchTopic` reader hands on while `count` poses are published back to
    back; the first callback holds until all of them were published, so that the rest wait
    in the subscription together."""
    batches: list[list[float]] = []
    published = threading.Event()
    threads: set[str] = set()

    def on_batch(messages: list[bytes]) -> None:
        threads.add(threading.current_thread().name)
        assert all(isinstance(m, bytes) for m in messages)
        batches.append([deserialize_message(m, PoseStamped).pose.position.x
                        for m in messages])
        if len(batches) == 1:
            published.wait(scaled(30))

    reader = ros.raw_reader([BatchTopic(topic, PoseStamped, _deep_reliable(), on_batch)],
                            name="rr-batch", batches=True)
    assert reader is not None
    publisher = processes.python("poses", "stream_publisher.py", topic, "100000",
                                 "--count", str(count))
    publisher.wait_for_output(f"SENT {count} DONE", timeout=30)
    published.set()
    wait_until(lambda: sum(len(b) for b in batches) >= count, timeout=30,
               what=f"{count} poses")
    assert threads == {"rr-batch"}
    reader.close()
    return batches


def test_a_batch_topic_gets_the_waiting_messages_together_in_order(
        ros: RosNode, processes: Processes) -> None:
    batches = _batched(ros, processes, "/rr_batch", 200)
    poses = [x for batch in batches for x in batch]
    # stream_publisher.py: the n-th pose has x = n * 1e-6 m; none lost, none repeated.
    assert [round(x * 1e6) for x in poses] == list(range(1, 201))
    assert all(batches)
    assert len(batches) < 200 and max(len(b) for b in batches) > 1, [len(b) for b in batches]


def test_a_batch_is_bounded(ros: RosNode, processes: Processes,
                            monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(raw_reader, "BATCH_MAX_MESSAGES", 4)
    batches = _batched(ros, processes, "/rr_batch_bounded", 60)
    assert [round(x * 1e6) for b in batches for x in b] == list(range(1, 61))
    assert max(len(b) for b in batches) == 4, [len(b) for b in batches]


def test_take_more_refuses_an_index_it_does_not_have(ros: RosNode) -> None:
    reader = ros.raw_reader([RawTopic("/rr_index", PoseStamped, TF_QOS, lambda view: None)],
                            name="rr-index")
    assert reader is not None
    with pytest.raises(IndexError, match="index: expected below 1, got 3"):
        reader._reader.take_more(3, 10, 1000)
    assert reader._reader.take_more(0, 10, 1000) == []  # nothing waits: none, at once
    reader.close()
    assert reader.closed
    with pytest.raises(raw_reader._rcl_reader.ReaderError, match="closed"):
        reader._reader.take_more(0, 10, 1000)


# ------------------------------------------------------------ topics added and removed


def test_topics_added_to_a_running_reader_are_taken_and_removed_ones_are_not(
        ros: RosNode, processes: Processes) -> None:
    received: dict[str, list[float]] = {"/rr_add_a": [], "/rr_add_b": []}
    threads: set[str] = set()

    def on(topic: str) -> Callable[[list[bytes]], None]:
        def callback(messages: list[bytes]) -> None:
            threads.add(threading.current_thread().name)
            received[topic] += [deserialize_message(m, PoseStamped).pose.position.x
                                for m in messages]
        return callback

    reader = ros.raw_reader([], name="rr-dynamic", batches=True)  # none to begin with
    assert reader is not None and reader.count == 0
    a = reader.add(BatchTopic("/rr_add_a", PoseStamped, TF_QOS, on("/rr_add_a")))
    b = reader.add(BatchTopic("/rr_add_b", PoseStamped, TF_QOS, on("/rr_add_b")))
    assert reader.count == 2
    processes.python("a", "stream_publisher.py", "/rr_add_a", "200", "--count", "100000")
    processes.python("b", "stream_publisher.py", "/rr_add_b", "200", "--count", "100000")
    wait_until(lambda: all(len(v) >= 20 for v in received.values()), timeout=30,
               what="20 poses of each topic")
    assert threads == {"rr-dynamic"}
    assert ros.stream_node.count_subscribers("/rr_add_a") == 1

    a.close()  # returns once the reader takes it no more
    after = len(received["/rr_add_a"])
    assert reader.count == 1
    wait_until(lambda: ros.stream_node.count_subscribers("/rr_add_a") == 0, timeout=10,
               what="the removed subscription gone from the graph")
    seen_b = len(received["/rr_add_b"])
    wait_until(lambda: len(received["/rr_add_b"]) >= seen_b + 20, timeout=30,
               what="the other topic still taken")
    assert len(received["/rr_add_a"]) == after
    a.close()  # idempotent
    b.close()
    reader.close()
    with pytest.raises(RuntimeError, match="closed"):
        reader.add(BatchTopic("/rr_add_late", PoseStamped, TF_QOS, on("/rr_add_a")))
    wait_until(lambda: ros.stream_node.count_subscribers("/rr_add_late") == 0, timeout=10,
               what="no subscription left by a refused add")


def test_a_callback_may_remove_its_own_topic(ros: RosNode, processes: Processes) -> None:
    batches: list[int] = []
    holder: list[RawSubscription] = []

    def once(messages: list[bytes]) -> None:
        batches.append(len(messages))
        holder[0].close()  # from the reader's own thread: at once, no deadlock

    reader = ros.raw_reader([], name="rr-self-remove", batches=True)
    assert reader is not None
    holder.append(reader.add(BatchTopic("/rr_self_remove", PoseStamped, TF_QOS, once)))
    processes.python("poses", "stream_publisher.py", "/rr_self_remove", "200", "--count",
                     "100000")
    wait_until(lambda: ros.stream_node.count_subscribers("/rr_self_remove") == 0,
               timeout=30, what="the topic removed by its own callback")
    assert len(batches) == 1
    reader.close()


def test_the_stream_reader_takes_up_to_its_bound_then_the_caller_uses_rclpy(
        ros: RosNode, monkeypatch: pytest.MonkeyPatch) -> None:
    from bridge.ros import ros_node

    monkeypatch.setattr(ros_node, "MAX_READ_STREAMS", 2)
    topics = [BatchTopic(f"/rr_bound_{i}", PoseStamped, TF_QOS, lambda m: None)
              for i in range(3)]
    first, second = ros.read_stream(topics[0]), ros.read_stream(topics[1])
    assert first is not None and second is not None
    assert first.reader is second.reader  # one thread for all
    assert ros.read_stream(topics[2]) is None
    first.close()
    third = ros.read_stream(topics[2])
    assert third is not None and third.reader is second.reader


def test_a_topic_the_middleware_cannot_tell_goes_through_rclpy(
        ros: RosNode, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """An rmw without rcl's on-new-message callback: the stream reader refuses the topic,
    leaves no subscription, and the caller subscribes through rclpy."""
    subscription = ros.read_stream(BatchTopic("/rr_told", PoseStamped, TF_QOS,
                                              lambda m: None))
    assert subscription is not None  # Fast DDS tells them
    subscription.close()

    def refuse(handle: object) -> None:
        raise raw_reader.ReaderError("the middleware does not tell new messages")

    monkeypatch.setattr(raw_reader._rcl_reader, "check_tells_new_messages", refuse)
    with caplog.at_level(logging.WARNING, logger="bridge.ros.ros_node"):
        assert ros.read_stream(BatchTopic("/rr_untold", PoseStamped, TF_QOS,
                                          lambda m: None)) is None
    assert any("/rr_untold is taken through rclpy: the middleware does not tell" in
               r.getMessage() for r in caplog.records)
    wait_until(lambda: ros.stream_node.count_subscribers("/rr_untold") == 0, timeout=10,
               what="no subscription left by the refused topic")


def test_a_reader_takes_one_kind_of_topic(ros: RosNode) -> None:
    views = ros.raw_reader([], name="rr-views")
    assert views is not None
    with pytest.raises(TypeError, match="topic: expected a RawTopic .* got a BatchTopic"):
        views.add(BatchTopic("/rr_kind", PoseStamped, TF_QOS, lambda m: None))
    with pytest.raises(TypeError, match="expected a BatchTopic .* got a RawTopic"):
        RawReader(ros.stream_node, [RawTopic("/rr_kind", PoseStamped, TF_QOS,
                                             lambda v: None)], "rr-kind", batches=True)
    assert ros.stream_node.count_subscribers("/rr_kind") == 0
    views.close()


# ------------------------------------------- native lanes, taken in the middleware's thread

RELIABLE_1000 = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST,
                           reliability=ReliabilityPolicy.RELIABLE)


class _LaneReader:
    """The compiled reader on one real subscription of the daemon's stream node, whose
    native lane writes to one client socket; no thread takes unless the test does."""

    def __init__(self, ros: RosNode, topic: str) -> None:
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

        from bridge.codecs import codec_for
        from bridge.codecs.fast import RawPoseStream

        ros_type = "geometry_msgs/msg/PoseStamped"
        self.fanout = native_stream.new_fanout()
        self.lane = native_stream.new_lane(self.fanout, ros_type, 1 << 16, 0.1)
        stream = RawPoseStream(codec_for(ros_type), "dev", {})
        sample = PoseStamped()
        sample.header.frame_id = "world"  # stream_publisher.py's
        sample.pose.orientation.w = 1.0
        template = stream.convert(bytes(serialize_message(sample)))[0]
        self.lane.set_template(b"world", b"", *template.wire_parts())
        self.ours, self.theirs = socket.socketpair()
        self.ours.setblocking(False)
        self.slot = native_stream.new_slot(None)
        with self.slot:
            self.slot.connect(self.ours)
            self.slot.header_version = 2
            self.slot.open = True
        with self.fanout:
            self.fanout.set_slots([self.slot])
        node = ros.stream_node
        with node.handle:
            self.handle = _rclpy.Subscription(node.handle, PoseStamped, topic,
                                              RELIABLE_1000.get_c_qos_profile())
        self.reader = raw_reader._rcl_reader.RawReader([self.handle])
        self.reader.set_subscriptions([self.handle], [self.lane.handler])
        self.decoder = Decoder()

    def written(self, count: int) -> list[int]:
        """The next ``count`` poses the client got, as stream_publisher.py's numbers."""
        numbers: list[int] = []
        self.theirs.settimeout(scaled(20))
        while len(numbers) < count:
            message = self.decoder.next_message()
            if message is None:
                self.decoder.feed(self.theirs.recv(1 << 16))
                continue
            numbers.append(round(float(message.body.matrix[0, 3]) * 1000))  # n / 1000 mm
        return numbers

    def close(self) -> None:
        self.reader.close()
        self.handle.destroy_when_not_in_use()
        self.ours.close()
        self.theirs.close()


needs_lanes = pytest.mark.skipif(not native_stream.available(),
                                 reason="the native lane is not built here")


@pytest.fixture
def lane_reader(ros: RosNode) -> Iterator[Callable[[str, bool], _LaneReader]]:
    made: list[_LaneReader] = []

    def make(topic: str, enabled: bool) -> _LaneReader:
        made.append(_LaneReader(ros, topic))
        with made[-1].fanout:
            made[-1].lane.enabled = enabled
        return made[-1]

    yield make
    for lanes in made:
        lanes.close()


def _publish(processes: Processes, topic: str) -> Any:
    return processes.python("poses", "stream_publisher.py", topic, "500", "--count", "100")


@needs_lanes
def test_a_native_lane_is_written_by_the_middlewares_thread_while_no_thread_takes(
        lane_reader: Callable[[str, bool], _LaneReader], processes: Processes) -> None:
    # No thread calls take: what the client gets, the middleware's own thread wrote, in
    # the callback that told the messages (a thread wake per message saved).
    lanes = lane_reader("/rr_inline", True)
    _publish(processes, "/rr_inline")
    assert lanes.written(100) == list(range(1, 101))
    with lanes.fanout:
        assert lanes.lane.count == 100


@needs_lanes
def test_what_the_lane_leaves_to_python_comes_first_and_in_order(
        lane_reader: Callable[[str, bool], _LaneReader], processes: Processes) -> None:
    # A disabled lane leaves each message to Python: the callback hands the first over,
    # and takes no more until Python is done. Enabled, the lane writes the rest.
    lanes = lane_reader("/rr_handover", False)
    publisher = _publish(processes, "/rr_handover")
    to_python: list[int] = []
    while len(to_python) < 30:
        taken = lanes.reader.take_batch(scaled(20), 7, 1 << 20)
        assert taken is not None, f"Python got {to_python}"
        index, batch = taken
        assert index == 0 and 1 <= len(batch) <= 7
        to_python += [round(deserialize_message(data, PoseStamped).pose.position.x * 1e6)
                      for data in batch]
    with lanes.fanout:
        lanes.lane.enabled = True
    publisher.wait_for_output("SENT 100 DONE")
    # Python asks for more: the lane writes what waits, here or in the callback.
    while lanes.reader.take_batch(0.05, 7, 1 << 20) is not None:
        pass
    got = len(to_python)
    assert to_python == list(range(1, got + 1))
    assert lanes.written(100 - got) == list(range(got + 1, 101))


@needs_lanes
def test_a_lane_whose_lock_is_held_is_written_later_by_the_readers_thread_in_order(
        lane_reader: Callable[[str, bool], _LaneReader], processes: Processes) -> None:
    # The middleware's thread never waits for the fanout: it hands the message it took
    # over, and the reader's thread writes it, then the rest, in order.
    lanes = lane_reader("/rr_busy", True)
    with lanes.fanout:
        publisher = _publish(processes, "/rr_busy")
        wait_until(lambda: lanes.reader.handed_over, timeout=20,
                   what="the callback's message handed over")
        publisher.wait_for_output("SENT 100 DONE")
        assert not select.select([lanes.theirs], [], [], 0)[0]  # nothing written meanwhile
    assert lanes.reader.take_batch(0.2, 7, 1 << 20) is None  # all written, none to Python
    assert lanes.written(100) == list(range(1, 101))
