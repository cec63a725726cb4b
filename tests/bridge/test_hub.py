"""The hub's hand-off from other threads: order, bounds, and a removed device staying gone."""

from __future__ import annotations

import asyncio
import threading

from bridge.hub import Hub
from protocol.messages import Message, String


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
