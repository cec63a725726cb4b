"""The multi-client floor for streamed poses: the least a relay can do. bench_daemon.py
runs it, as its own process, where it measures the daemon with many clients.

usage: fanout_relay.py PORT TOPIC DEPTH

A bare subscriber (rclpy's EventsExecutor, as the daemon's other streams use, each
PoseStamped taken raw, spin_once in a loop), listens on 127.0.0.1:PORT for any number of
OpenIGTLink clients. For each message it writes to every client, one after another, a
TRANSFORM in header v2 encoded once at start (the bytes the daemon sends for the stream)
with only its timestamp set: the message's header.stamp, read from the CDR. No
conversion, no per-client state, no backlog, no coalescing; a client whose socket is full
blocks the others (a floor, not a relay to use). What clients send is read and dropped.

Beside the daemon's figure for the same clients, in the same run, it shows what any relay
written this way gets on this machine at this load: the ROS hop, a Python subscriber's
wake-up, and the readers' own scheduling, with nothing of the daemon's.
Prints READY once it listens.
"""

from __future__ import annotations

import selectors
import socket
import struct
import sys
import threading
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.executors import ExternalShutdownException  # noqa: E402
from rclpy.experimental import EventsExecutor  # noqa: E402

from protocol.conversions import ConversionError, igtl_timestamp_from_ros  # noqa: E402
from protocol.framing import encode  # noqa: E402
from protocol.messages import Message, Transform  # noqa: E402

# PoseStamped's CDR: a 4-byte encapsulation header, then header.stamp (int32 sec, uint32
# nanosec), little-endian as rmw_fastrtps writes it here.
_STAMP = struct.Struct("<iI")
_STAMP_AT = 4
# OpenIGTLink header: version, type, device name, then the timestamp (8 bytes, big-endian).
_TIMESTAMP = struct.Struct(">Q")
_TIMESTAMP_AT = 2 + 12 + 20


class Clients:
    """Connected sockets; what they send is read and dropped in a thread of its own."""

    def __init__(self, port: int) -> None:
        self.server = socket.create_server(("127.0.0.1", port))
        self.sockets: tuple[socket.socket, ...] = ()
        self._selector = selectors.DefaultSelector()
        self._selector.register(self.server, selectors.EVENT_READ)
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            for key, _ in self._selector.select():
                sock = key.fileobj
                if sock is self.server:
                    client, _ = self.server.accept()
                    client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    self._selector.register(client, selectors.EVENT_READ)
                    self.sockets = (*self.sockets, client)
                    continue
                try:
                    data = sock.recv(1 << 16)  # type: ignore[union-attr]
                except OSError:
                    data = b""
                if not data:
                    self._selector.unregister(sock)
                    self.sockets = tuple(s for s in self.sockets if s is not sock)
                    sock.close()  # type: ignore[union-attr]


def main() -> None:
    port, topic, depth = int(sys.argv[1]), sys.argv[2], int(sys.argv[3])
    frame = bytearray(encode(Message(device_name="bench_pose", body=Transform(
        matrix=np.eye(4)), metadata={"ros_topic": topic, "ros_type": "PoseStamped"}),
        header_version=2))
    clients = Clients(port)
    rclpy.init()
    node = rclpy.create_node("fanout_relay")

    def on_pose(data: bytes) -> None:
        try:
            sec, nanosec = _STAMP.unpack_from(data, _STAMP_AT)
            stamp = igtl_timestamp_from_ros(sec, nanosec)
        except (struct.error, ConversionError) as error:  # too short, or stamp out of range
            print(f"fanout_relay: a message it cannot stamp, dropped: {error}",
                  file=sys.stderr, flush=True)
            return
        _TIMESTAMP.pack_into(frame, _TIMESTAMP_AT, stamp)
        for client in clients.sockets:
            try:
                client.sendall(frame)
            except OSError:
                pass  # gone: its reader thread drops it

    node.create_subscription(PoseStamped, topic, on_pose, depth, raw=True)
    executor = EventsExecutor()
    executor.add_node(node)
    print("READY", flush=True)
    try:
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
