"""The daemon's work per streamed pose, in its own thread: serialized PoseStamped in, the
TRANSFORM written to one client's socket (`SubscriberBridge._on_batch`, the stream reader's
callback: conversion, the hub, the client's direct write, `send()` included).

Run: .venv/bin/python bench/bench_pose_path.py [--messages N]

Measured in the same run, each the thread's CPU time per message (`time.thread_time`), for
the Python path and, where it is built, the native lane (`PoseLane.handle`: the same work
in C, which the stream reader's thread does without the interpreter):
- back to back: the messages one after another, the caches warm;
- paced at 1 kHz: a 1 ms sleep between messages, as a 1 kHz stream comes. The same code
  then costs several times more per message: after each sleep it runs with cold caches;
- the sleep alone, paced the same way (what the paced figure holds that is not the path).
The client is a real TCP connection, drained by another thread; no ROS traffic (the
subscription exists, nothing is published on it).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import socket
import sys
import threading
import time
from typing import Callable, Optional

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402

from bridge.codecs import codec_for  # noqa: E402
from bridge.core.hub import Hub  # noqa: E402
from bridge.core.session import ClientSession, SessionLimits  # noqa: E402
from bridge.ros.ros_node import RosNode, RosOptions  # noqa: E402
from bridge.topics.capability import SubscriberBridge  # noqa: E402
from protocol.commands import QoS  # noqa: E402


def pose_bytes(n: int) -> bytes:
    msg = PoseStamped()
    msg.header.frame_id = "world"
    msg.header.stamp.sec = 1_700_000_000 + n
    msg.pose.position.x = n * 1e-3
    msg.pose.orientation.w = 1.0
    return bytes(serialize_message(msg))


def per_message_us(take: Optional[Callable[[bytes], object]], messages: list[bytes],
                   pause_s: float) -> float:
    """The calling thread's CPU time per message, in a thread of its own."""
    result: list[float] = []

    def run() -> None:
        start = time.thread_time()
        for data in messages:
            if take is not None:
                take(data)
            if pause_s:
                time.sleep(pause_s)
        result.append((time.thread_time() - start) / len(messages) * 1e6)

    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    return result[0]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--messages", type=int, default=5000)
    args = parser.parse_args()

    loop = asyncio.new_event_loop()
    hub = Hub(loop)
    threading.Thread(target=loop.run_forever, daemon=True).start()
    limits = SessionLimits(negotiation_grace_s=0.0)

    async def serve() -> asyncio.AbstractServer:
        return await loop.create_server(
            lambda: ClientSession(hub, lambda m, c: None, limits, lambda c: None),
            "127.0.0.1", 0)

    server = asyncio.run_coroutine_threadsafe(serve(), loop).result(10)
    peer = socket.create_connection(server.sockets[0].getsockname())
    deadline = time.monotonic() + 10
    while not hub.clients and time.monotonic() < deadline:
        time.sleep(0.01)
    stop = threading.Event()

    def drain() -> None:
        peer.settimeout(0.5)
        while not stop.is_set():
            try:
                if not peer.recv(1 << 16):
                    return
            except socket.timeout:
                pass

    threading.Thread(target=drain, daemon=True).start()
    ros = RosNode(RosOptions(node_name="bench_pose_path"))
    bridge = SubscriberBridge(ros, hub, topic="/bench_pose_path",
                              codec=codec_for("geometry_msgs/msg/PoseStamped"), qos=QoS(),
                              device="pose", metadata={})
    messages = [pose_bytes(n) for n in range(args.messages)]

    def python_path(data: bytes) -> None:
        bridge._on_batch([data])

    lane = bridge._lane
    try:
        per_message_us(python_path, messages[:500], 0.0)  # first allocations, templates
        warm = per_message_us(python_path, messages, 0.0)
        paced = per_message_us(python_path, messages, 0.001)
        sleep = per_message_us(None, messages, 0.001)
        native: Optional[tuple[float, float, int]] = None
        if lane is not None:
            handled = [0]

            def native_lane(data: bytes) -> None:
                if lane.handle(data) == 0:  # HANDLED: written to the client
                    handled[0] += 1
                else:
                    bridge._on_batch([data])  # as the reader does with what it leaves

            native = (per_message_us(native_lane, messages, 0.0),
                      per_message_us(native_lane, messages, 0.001), handled[0])
    finally:
        stop.set()
        bridge.close()
        ros.stop()
        loop.call_soon_threadsafe(server.close)
        loop.call_soon_threadsafe(loop.stop)
    print(f"{len(messages)} PoseStamped, the daemon's path per message (thread CPU, us):")
    print(f"  back to back (warm caches)       {warm:7.1f}")
    print(f"  paced at 1 kHz, the sleep taken  {paced - sleep:7.1f}   (measured "
          f"{paced:.1f}, the 1 ms sleep alone {sleep:.1f})")
    if native is None:
        print("the native lane: not built here")
    else:
        print(f"the native lane (PoseLane.handle; {native[2]:,} of {2 * len(messages):,} "
              f"written by it):")
        print(f"  back to back (warm caches)       {native[0]:7.1f}")
        print(f"  paced at 1 kHz, the sleep taken  {native[1] - sleep:7.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
