"""The daemon's node: its executor outlives a failing callback, and destroys entities in
its own thread."""

from __future__ import annotations

import logging
import threading
import time

import pytest
from std_msgs.msg import String

from bridge.ros.ros_node import RosNode, RosOptions
from support import scaled

pytestmark = pytest.mark.ros


def test_a_failing_callback_is_logged_and_the_executor_goes_on(
        caplog: pytest.LogCaptureFixture) -> None:
    ros = RosNode(RosOptions(node_name="ros_node_test_failing"))
    ticks: list[int] = []
    healthy = threading.Event()

    def failing() -> None:
        raise ValueError("a callback bug")

    def counting() -> None:
        ticks.append(1)
        if len(ticks) >= 5:
            healthy.set()

    ros.node.create_timer(0.01, failing)
    ros.node.create_timer(0.01, counting)
    with caplog.at_level(logging.ERROR, logger="bridge.ros.ros_node"):
        ros.start()
        try:
            assert healthy.wait(scaled(10)), f"the executor stopped after {len(ticks)} ticks"
        finally:
            ros.stop()
    failures = [r for r in caplog.records if "a ROS callback failed" in r.getMessage()]
    assert failures and failures[0].exc_info is not None
    assert failures[0].exc_info[0] is ValueError
    # It failed on each of the >= 5 ticks, but the log says so once (per 5 s), not each time.
    assert len(failures) == 1, [r.getMessage() for r in failures]


def test_destroy_from_another_thread_removes_the_entities() -> None:
    ros = RosNode(RosOptions(node_name="ros_node_test_destroy"))
    ros.start()
    try:
        subscription = ros.node.create_subscription(String, "/ros_node_test", lambda _: None, 10)
        publisher = ros.node.create_publisher(String, "/ros_node_test_out", 10)
        ros.destroy(subscription)
        ros.destroy(publisher)
        deadline = time.monotonic() + scaled(5)
        while ((subscription in ros.node.subscriptions or publisher in ros.node.publishers)
               and time.monotonic() < deadline):
            time.sleep(0.01)
        assert subscription not in ros.node.subscriptions
        assert publisher not in ros.node.publishers
        # The node's own /parameter_events publisher stays.
        assert [p.topic_name for p in ros.node.publishers] == ["/parameter_events"]
        assert ros.node.count_subscribers("/ros_node_test_out") == 0
    finally:
        ros.stop()


def test_streamed_subscriptions_have_their_own_executor_and_are_destroyed_there() -> None:
    """`stream_node` runs under the EventsExecutor: its callbacks run, a failing one does not
    stop it, and `destroy` from another thread removes its subscription."""
    ros = RosNode(RosOptions(node_name="ros_node_test_streams"))
    got: list[str] = []
    arrived = threading.Event()

    def on_message(msg: String) -> None:
        if msg.data == "fail":
            raise ValueError("a callback bug")
        got.append(msg.data)
        arrived.set()

    subscription = ros.stream_node.create_subscription(String, "/ros_node_test_streams",
                                                       on_message, 10)
    publisher = ros.node.create_publisher(String, "/ros_node_test_streams", 10)
    ros.start()
    try:
        deadline = time.monotonic() + 15
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        publisher.publish(String(data="fail"))
        while not arrived.is_set() and time.monotonic() < deadline:
            publisher.publish(String(data="ok"))
            arrived.wait(0.1)
        assert got and got[0] == "ok"
        ros.destroy(subscription)
        while subscription in ros.stream_node.subscriptions and time.monotonic() < deadline:
            time.sleep(0.01)
        assert subscription not in ros.stream_node.subscriptions
    finally:
        ros.stop()
