"""The hub's hand-off from other threads: order, bounds, and a removed device staying gone."""

from __future__ import annotations

import asyncio
import threading
from contextlib import contextmanager
from typing import Any, Iterator

import numpy as np

from bridge.core.hub import Hub, frame_for
from bridge.core.outbox import BulkFrame
from protocol.messages import Image, Message, String


def _text(device: str, text: str) -> Message:
    return Message(device_name=device, body=String(text))


def _run_posts(hub: Hub, messages: list[Message]) -> None:
    """Post from another thread, as the ROS executor does."""
    poster = threading.Thread(target=lambda: [hub.post(m) for m in messages])
    poster.start()
    poster.join()


def test_posts_from_another_thread_arrive_in_order_with_the_newest_kept() -> None:
    loop = asyncio.new_event_loop()
    try:
        hub = Hub(loop)
        _run_posts(hub, [_text("a", str(n)) for n in range(100)])
        loop.run_until_complete(asyncio.sleep(0.01))
        latest = hub.latest("a")
        assert latest is not None and latest.body.text == "99"
        assert hub.streamed == 100 and hub.dropped == 0
    finally:
        loop.close()


def test_a_device_forgotten_before_the_loop_drains_does_not_come_back() -> None:
    loop = asyncio.new_event_loop()
    try:
        hub = Hub(loop)
        big = "x" * 70_000  # a large message takes the per-device coalescing path
        _run_posts(hub, [_text("gone", "1"), _text("kept", "2"), _text("gone", big),
                               _text("gone", "3")])
        hub.forget("gone")  # the loop has not run yet: all of them are still queued
        loop.run_until_complete(asyncio.sleep(0.01))
        assert hub.devices() == ["kept"]
        assert hub.latest("gone") is None
        kept = hub.latest("kept")
        assert kept is not None and kept.body.text == "2"
    finally:
        loop.close()


class _Client:
    """What the hub needs of a session, recording what it is sent."""

    header_version = 2

    def __init__(self) -> None:
        self.got: list[tuple[str, str]] = []

    def send_stream(self, device: str, frame) -> None:  # noqa: ANN001
        self.got.append((device, frame.message.body.text))

    def send_once(self, frame) -> None:  # noqa: ANN001
        self.got.append((frame.message.device_name, frame.message.body.text))

    def write_direct(self, data: bytes) -> bool:
        return False  # always the loop's path, so send_stream records it

    def hand_over(self, device: str, frame) -> None:  # noqa: ANN001
        self.send_stream(device, frame)

    def forget_device(self, device: str) -> None:
        pass


def test_a_device_with_an_audience_reaches_only_the_clients_that_joined() -> None:
    loop = asyncio.new_event_loop()
    try:
        hub = Hub(loop)
        a, b, late = _Client(), _Client(), _Client()
        hub.attach(a)
        hub.attach(b)
        hub.limit_to_audience("msg:x")
        assert not hub.has_audience("msg:x") and hub.has_audience("x")
        hub.stream(_text("msg:x", "before anyone joined"))
        hub.stream(_text("x", "shared"))
        hub.join("msg:x", a)  # gets the newest value at once
        assert hub.has_audience("msg:x")
        hub.stream(_text("msg:x", "for a"))
        hub.attach(late)  # a client that connects later gets only the shared state
        assert a.got == [("x", "shared"), ("msg:x", "before anyone joined"), ("msg:x", "for a")]
        assert b.got == [("x", "shared")]
        assert late.got == [("x", "shared")]
        assert hub.latest("msg:x", b) is None and hub.latest("msg:x", a) is not None
        hub.detach(a)  # leaving drops it from every audience
        assert not hub.has_audience("msg:x")
        hub.join("msg:x", b)
        hub.leave("msg:x", b)
        hub.stream(_text("msg:x", "to nobody"))
        assert b.got == [("x", "shared"), ("msg:x", "for a")]
        hub.forget("msg:x")  # a removed bridge's device goes to everyone again if reused
        assert hub.has_audience("msg:x")
    finally:
        loop.close()


def test_a_volatile_device_keeps_its_small_values_for_later_clients_not_its_large_ones() -> None:
    loop = asyncio.new_event_loop()
    try:
        hub = Hub(loop)
        big = "x" * 70_000  # over LARGE_MESSAGE_BYTES: a BulkFrame
        assert isinstance(frame_for(_text("v", big)), BulkFrame)
        assert not isinstance(frame_for(_text("v", "small")), BulkFrame)
        hub.set_volatile("v", True)
        hub.stream(_text("v", "small"))
        kept = hub.latest("v")
        assert kept is not None and kept.body.text == "small"
        hub.stream(_text("v", big))  # sent, then not kept: nor is the older small one
        assert hub.latest("v") is None
        hub.stream(_text("durable", big))  # not volatile (transient local): kept
        durable = hub.latest("durable")
        assert durable is not None and durable.body.text == big
        hub.stream(_text("v", big))
        hub.set_volatile("v", False)
        hub.stream(_text("v", big))
        assert hub.latest("v") is not None
        hub.set_volatile("v", True)  # made volatile again: its large value goes at once
        assert hub.latest("v") is None
    finally:
        loop.close()


class _DirectClient(_Client):
    """A client that keeps up (every direct write taken) or not (`keeps_up`)."""

    def __init__(self, keeps_up: bool) -> None:
        super().__init__()
        self.keeps_up = keeps_up
        self.written: list[Any] = []
        self.handed: list[tuple[str, Any]] = []

    def write_direct(self, data: Any) -> bool:
        if self.keeps_up:
            self.written.append(data)
        return self.keeps_up

    def hand_over(self, device: str, frame) -> None:  # noqa: ANN001
        self.handed.append((device, frame))


def test_a_large_value_from_another_thread_is_written_at_once_as_its_parts() -> None:
    loop = asyncio.new_event_loop()
    try:
        hub = Hub(loop)
        quick, behind = _DirectClient(True), _DirectClient(False)
        hub.attach(quick)
        hub.attach(behind)
        pixels = np.arange(120 * 200 * 3, dtype=np.uint32).astype(np.uint8).reshape(
            1, 120, 200, 3)
        frame = frame_for(Message(device_name="v", body=Image(pixels=pixels)))
        assert isinstance(frame, BulkFrame)
        hub.set_volatile("v", True)
        poster = threading.Thread(target=hub.post_frame, args=(hub.open_channel("v"), frame))
        poster.start()
        poster.join()
        # Its parts, not joined: the pixels are sent from where they lie.
        assert [type(data) for data in quick.written] == [tuple]
        header, content, metadata = quick.written[0]
        assert bytes(content)[-pixels.size:] == pixels.tobytes()
        assert b"".join(quick.written[0]) == frame.encoded(2)
        assert behind.handed == [("v", frame)]  # the loop's path, for a client behind
        assert hub.latest("v") is None  # volatile: not kept for later clients
        assert hub.direct == 1 and hub.dropped == 0
    finally:
        loop.close()


def test_a_bridges_devices_go_to_its_audience_and_a_client_added_catches_up() -> None:
    """What the dispatcher derives from ownership (docs/security.md, "Who owns a bridge"):
    a client's bridge to its holders, every client once kept; a device several bridges
    share to each of their audiences; a client added gets the current state at once, on
    the loop's path and the direct one."""
    loop = asyncio.new_event_loop()
    try:
        hub = Hub(loop)
        maker, joiner, plain = _DirectClient(True), _DirectClient(True), _DirectClient(True)
        for client in (maker, joiner, plain):
            hub.attach(client)
        mine, theirs = ("subscriber", ("/mine",)), ("subscriber", ("/theirs",))
        hub.set_bridge_audience(mine, (maker,))
        hub.bridge_device(mine, "mine")
        hub.bridge_device(mine, "frame")
        hub.bridge_device(theirs, "frame")  # shared: by both bridges' audiences
        hub.set_bridge_audience(theirs, (joiner,))
        hub.stream(_text("mine", "1"))
        hub.publish_persistent(_text("mesh", "everyone's"))  # no bridge named it: all
        assert hub.audience("mine") == (maker,) and set(hub.audience("frame")) == {
            maker, joiner}
        assert maker.got == [("mine", "1"), ("mesh", "everyone's")]
        assert joiner.got == plain.got == [("mesh", "everyone's")]
        # The direct path: each client in one write of what it gets.
        update = [("mine", frame_for(_text("mine", "2"))),
                  ("frame", frame_for(_text("frame", "f")))]
        hub.post_frames(update)
        assert [len(c.written) for c in (maker, joiner, plain)] == [1, 1, 0]
        assert maker.written[0] == update[0][1].encoded(2) + update[1][1].encoded(2)
        assert joiner.written[0] == update[1][1].encoded(2)
        hub.set_bridge_audience(mine, (maker, joiner))  # it asked for the bridge too
        assert joiner.got[-1] == ("mine", "2")
        hub.set_bridge_audience(mine, None)  # kept: everyone, the newest at once
        assert plain.got[1:] == [("mine", "2"), ("frame", "f")]
        hub.drop_bridge(mine)  # removed: the shared frame is the other bridge's again
        assert hub.audience("frame") == (joiner,)
        hub.detach(joiner)
        assert hub.audience("frame") == ()
    finally:
        loop.close()


@contextmanager
def _hub_of(*clients: _Client) -> Iterator[Hub]:
    """A hub on a loop of its own (closed after), `clients` attached."""
    loop = asyncio.new_event_loop()
    try:
        hub = Hub(loop)
        for client in clients:
            hub.attach(client)
        yield hub
    finally:
        loop.close()


def test_a_client_that_declines_a_devices_values_gets_its_condition_only() -> None:
    """`set_declined` (a client reading a subscriber's messages whole): none of the
    device's values reach it on any route (the loop's, the direct one, a later client's
    catch-up, `latest`), its condition still does, kept bridges included; taken back, it
    gets the newest at once."""
    reader, raw = _DirectClient(True), _DirectClient(True)
    with _hub_of(reader, raw) as hub:
        pose = ("subscriber", ("/pose",))
        hub.set_bridge_audience(pose, (reader, raw))
        hub.bridge_device(pose, "pose")
        hub.set_declined("pose", reader, True)
        hub.stream(_text("pose", "1"))
        hub.post_frames([("pose", frame_for(_text("pose", "2")))])
        assert reader.got == [] and reader.written == []
        assert raw.got == [("pose", "1")] and len(raw.written) == 1
        assert hub.latest("pose", reader) is None and hub.latest("pose", raw) is not None
        hub.set_condition("pose", frame_for(_text("pose", "stale")),
                          frame_for(_text("pose", "stale")))
        assert reader.got == [("pose", "stale")]  # its condition: not a value
        hub.set_bridge_audience(pose, None)  # kept: every client, still not the decliner
        later = _DirectClient(True)
        hub.attach(later)
        assert ("pose", "2") in later.got and ("pose", "2") not in reader.got
        hub.post_frames([("pose", frame_for(_text("pose", "3")))])
        assert reader.written == [] and len(later.written) == 1
        hub.set_declined("pose", reader, False)  # asked again for the values
        assert reader.got[-1] == ("pose", "3")
        hub.detach(reader)
        hub.set_declined("pose", later, True)
        hub.detach(later)  # its decline goes with it
        assert hub._declined == {}
