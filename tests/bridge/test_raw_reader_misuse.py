"""The raw reader (bridge/ros/raw_reader.py) used wrongly or unlucky: ruled out but built
anyway, a topic rclpy refuses, a callback that keeps a view on the reader's buffer, a
callback that does not return when the reader closes. Real publishers in other processes."""

from __future__ import annotations

import logging
import pickle
import threading
from typing import Iterator

import pytest
from geometry_msgs.msg import PoseStamped

from bridge.ros import raw_reader
from bridge.ros.qos import TF_QOS
from bridge.ros.raw_reader import RawReader, RawTopic
from bridge.ros.ros_node import RosNode, RosOptions
from support import Processes, scaled, wait_until

pytestmark = [pytest.mark.ros, pytest.mark.skipif(
    raw_reader._rcl_reader is None,
    reason="the rcl reader was not built (no rcl headers, C compiler or Cython at install)")]


@pytest.fixture
def ros() -> Iterator[RosNode]:
    node = RosNode(RosOptions(node_name="raw_reader_misuse_test"))
    node.start()
    try:
        yield node
    finally:
        node.stop()


def test_a_reader_ruled_out_gives_none_and_the_caller_takes_rclpy() -> None:
    """`--ros-take rclpy`: the node gives no reader and no read stream, where it would."""
    topics = [RawTopic("/rr_out", PoseStamped, TF_QOS, lambda view: None)]
    for rcl_take in (True, False):
        node = RosNode(RosOptions(node_name="raw_reader_ruled_out", rcl_take=rcl_take))
        node.start()
        try:
            reader = node.raw_reader(topics, name="rr-out")
            assert (reader is not None) is rcl_take
        finally:
            node.stop()


def test_a_topic_rclpy_refuses_leaves_no_subscription(ros: RosNode) -> None:
    good = RawTopic("/rr_good", PoseStamped, TF_QOS, lambda view: None)
    bad = RawTopic("/rr bad name!", PoseStamped, TF_QOS, lambda view: None)
    with pytest.raises(Exception) as raised:
        RawReader(ros.stream_node, [good, bad], "rr-bad")
    assert "topic" in str(raised.value).lower()
    # The first topic's subscription, made before the refusal, is destroyed again.
    wait_until(lambda: ros.stream_node.count_subscribers("/rr_good") == 0, timeout=10,
               what="no subscription left on /rr_good")


def test_a_callback_that_keeps_a_view_is_reported(
        ros: RosNode, processes: Processes, caplog: pytest.LogCaptureFixture) -> None:
    kept: list[pickle.PickleBuffer] = []
    got = threading.Event()

    def keeps(view: memoryview) -> None:
        kept.append(pickle.PickleBuffer(view))  # a bug: holds the buffer, which is reused
        got.set()

    with caplog.at_level(logging.ERROR, logger="bridge.ros.raw_reader"):
        reader = ros.raw_reader([RawTopic("/rr_keeps", PoseStamped, TF_QOS, keeps)],
                                name="rr-keeps")
        assert reader is not None
        processes.python("poses", "stream_publisher.py", "/rr_keeps", "50", "--count", "20")
        assert got.wait(scaled(30)), "no message reached the callback"
        wait_until(lambda: any("kept a view on the reader's buffer" in r.getMessage()
                               for r in caplog.records), timeout=10, what="the report")
    kept.clear()
    messages = [r.getMessage() for r in caplog.records]
    assert "a callback of /rr_keeps kept a view on the reader's buffer" in messages


def test_a_callback_that_does_not_return_leaves_the_reader_open(
        ros: RosNode, processes: Processes, caplog: pytest.LogCaptureFixture) -> None:
    entered, release = threading.Event(), threading.Event()

    def hangs(view: memoryview) -> None:
        entered.set()
        release.wait(scaled(60))

    reader = ros.raw_reader([RawTopic("/rr_hangs", PoseStamped, TF_QOS, hangs)],
                            name="rr-hangs")
    assert reader is not None
    processes.python("poses", "stream_publisher.py", "/rr_hangs", "50", "--count", "20")
    assert entered.wait(scaled(30)), "no message reached the callback"
    thread = reader._thread
    assert thread is not None
    with caplog.at_level(logging.ERROR, logger="bridge.ros.raw_reader"):
        reader.close()  # waits 5 s for the thread, then leaves its handles be
    assert "the raw reader of /rr_hangs did not stop within 5 s" in [
        r.getMessage() for r in caplog.records]
    assert thread.is_alive()
    # Once the callback returns, the thread sees it was stopped and ends.
    release.set()
    thread.join(scaled(10))
    assert not thread.is_alive()
    reader._reader.close()  # what close would have done, for the node's clean stop
    reader._destroy_handles()
