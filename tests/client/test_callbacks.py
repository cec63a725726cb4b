"""Where callbacks run, against a real daemon: never on the receive thread, so an observer
may call anything, blocking commands included; in Spin() on the spinning thread; on the
dispatcher thread when nobody spins."""

from __future__ import annotations

import threading
import time

import pytest

import slicer_client
from slicer_client.events import EventDispatcher
from support import RunningDaemon, scaled, wait_until

pytestmark = pytest.mark.ros


def test_an_observer_calls_blocking_commands_a_thousand_times_without_a_stall(
        daemon: RunningDaemon) -> None:
    """The reference's observer reads the message (``GetLastMessageYAML``) in its callback;
    this one also sends a blocking command (``Publish``) on each of 1,000 messages."""
    with slicer_client.connect("127.0.0.1", daemon.port) as ros:
        node = ros.GetDefaultROS2Node()
        sub = node.CreateAndAddSubscriberNode("Int", "/cb_blocking")
        pub = node.CreateAndAddPublisherNode("Int", "/cb_blocking")
        echo = node.CreateAndAddPublisherNode("String", "/cb_blocking_echo")
        seen: list[int] = []
        threads: set[str] = set()
        done = threading.Event()

        def observer(caller, event) -> None:  # noqa: ANN001
            threads.add(threading.current_thread().name)
            value = caller.GetLastMessage()
            caller.GetLastMessageYAML()
            echo.Publish(f"saw {value}")  # a command: its reply comes on the receive thread
            seen.append(value)
            if len(seen) >= 1000:
                done.set()

        sub.AddObserver("ModifiedEvent", observer)
        wait_until(lambda: pub.Publish(-1) >= 1 and bool(seen), timeout=20,
                   what="the subscriber to hear the publisher")
        started = time.monotonic()
        deadline = started + scaled(120)
        n = 0
        while not done.is_set() and time.monotonic() < deadline:
            pub.Publish(n)  # a burst may reach the client coalesced: publish until seen
            n += 1
        assert done.wait(scaled(10)), f"only {len(seen)} observer calls in {n} publishes"
        assert threads == {"slicer-client-callbacks"}
        assert seen == sorted(seen)  # in order, each message once
        # No call waited out a command's 10 s timeout: the whole run took far less.
        assert time.monotonic() - started < scaled(60)
        assert ros.events.dropped == 0


def test_spin_runs_what_arrived_on_the_spinning_thread(daemon: RunningDaemon) -> None:
    # "spin": only a spin runs callbacks (in "auto" the dispatcher takes over after a
    # grace, which a busy machine's pause between two spins can exceed: tested below).
    with slicer_client.connect("127.0.0.1", daemon.port, callbacks="spin") as ros:
        logic = ros.logic
        node = logic.GetDefaultROS2Node()
        sub = node.CreateAndAddSubscriberNode("String", "/cb_spin")
        pub = node.CreateAndAddPublisherNode("String", "/cb_spin")
        calls: list[str] = []
        sub.AddObserver("ModifiedEvent", lambda caller, event: calls.append(
            threading.current_thread().name))
        wait_until(lambda: pub.Publish("first") >= 1 and sub.GetNumberOfMessages() > 0,
                   timeout=20, what="the first message")
        # While a script spins, callbacks wait for its spin rather than the dispatcher.
        # (Waited for by its value: a "first" still on its way would change the count.)
        deadline = time.monotonic() + scaled(20)
        pub.Publish("second")
        while sub.GetLastMessage() != "second" and time.monotonic() < deadline:
            logic.Spin()
            time.sleep(0.005)
        logic.Spin()
        assert sub.GetLastMessage() == "second"
        assert calls[-1] == threading.current_thread().name


def test_a_callback_never_runs_inside_another_and_spin_inside_one_returns() -> None:
    events = EventDispatcher("spin")
    order: list[str] = []

    def outer() -> None:
        order.append("outer")
        assert events.spin() == 0  # the inner event waits for the next spin
        order.append("outer done")

    events.post(outer)
    events.post(order.append, "inner")
    assert events.spin() == 2
    assert order == ["outer", "outer done", "inner"]
    events.close()


def test_the_dispatcher_thread_waits_for_a_spinner_then_takes_over() -> None:
    events = EventDispatcher("auto", spin_grace=0.2)
    ran: list[str] = []
    try:
        events.spin()  # somebody spins: a callback waits up to the grace for the next spin
        events.post(lambda: ran.append(threading.current_thread().name))
        events.spin()
        assert ran == [threading.current_thread().name]
        # Nobody spins any more: the dispatcher runs the next one after the grace.
        events.post(lambda: ran.append(threading.current_thread().name))
        wait_until(lambda: len(ran) == 2, timeout=10, what="the dispatcher")
        assert ran[1] == "slicer-client-callbacks"
    finally:
        events.close()


def test_a_callback_that_never_returns_costs_bounded_memory() -> None:
    events = EventDispatcher("spin", max_queued=100)
    for n in range(250):
        events.post(print, n)
    assert events.pending == 100 and events.dropped == 150
    events.close()


def test_a_callback_that_falls_behind_runs_once_with_the_newest_value(
        daemon: RunningDaemon) -> None:
    """A GUI spins every 20 ms; a 1 kHz topic brings 20 values meanwhile. Its callback
    runs once, with the newest, not 20 times with values already old; the count is exact."""
    with slicer_client.connect("127.0.0.1", daemon.port, callbacks="spin") as ros:
        sub = ros.subscribe("/cb_newest", "Int64")
        values: list[int] = []
        sub.add_callback(values.append)
        pub = ros.publisher("/cb_newest", "Int64")
        wait_until(lambda: pub.publish(-1) >= 1 and sub.count > 0, timeout=20,
                   what="the first message")
        ros.process_events()
        values.clear()
        start = sub.count
        for n in range(50):
            pub.publish(n)
        sub.wait_for_message(timeout=20, predicate=lambda value: value == 49)
        assert sub.count - start == 50  # every message came (the daemon's reliable stream)
        assert ros.process_events() == 1
        assert values == [49]
        assert ros.events.replaced >= 49


def test_post_newest_replaces_what_waits_and_keeps_its_place() -> None:
    events = EventDispatcher("spin")
    ran: list[tuple[str, int]] = []
    events.post_newest("a", lambda v: ran.append(("a", v)), 1)
    events.post(lambda: ran.append(("plain", 0)))
    events.post_newest("a", lambda v: ran.append(("a", v)), 2)
    events.post_newest("b", lambda v: ran.append(("b", v)), 3)
    assert events.spin() == 3
    assert ran == [("a", 2), ("plain", 0), ("b", 3)]  # "a" in its first place, newest value
    events.post_newest("a", lambda v: ran.append(("a", v)), 4)  # ran: queued anew
    assert events.spin() == 1 and ran[-1] == ("a", 4)
    events.close()
