"""An rclpy echo peer (tests/peers/echo_subscriber.py) in its own process, and sending to it
until it hears: what tests of ROS-bound data share."""

from __future__ import annotations

import json
import time
from typing import Any, Callable

from support import Child, Processes, scaled, wait_until


def echo(processes: Processes, topic: str, msg_type: str, *flags: str) -> Child:
    """An echo subscriber of `topic`, started and ready (it prints each message as
    ``MSG <json>``)."""
    child = processes.python(f"echo{topic.replace('/', '_')}", "echo_subscriber.py", topic,
                             msg_type, *flags)
    child.wait_for_output("READY", timeout=30)
    return child


def until_received(send: Callable[[], Any], child: Child, timeout: float = 20.0
                   ) -> dict[str, Any]:
    """Call `send` until the echo prints a message (discovery races); that message."""
    deadline = time.monotonic() + scaled(timeout)
    while True:
        send()
        try:
            line = child.wait_for_output("MSG ", timeout=0.2)
            return json.loads(line.split("MSG ", 1)[1])  # type: ignore[no-any-return]
        except AssertionError:
            if time.monotonic() > deadline:
                raise


def until_got(pub: Any, value: Any, sub: Any, what: str) -> Any:
    """Publish `value` with the facade publisher `pub` until the facade subscriber `sub`
    has a message; that message."""
    wait_until(lambda: pub.Publish(value) >= 1 and sub.GetLastMessage() is not None,
               timeout=20, what=what)
    return sub.GetLastMessage()
