"""A client that leaves, even abruptly in the middle of a stream, is one INFO line in the
daemon's log: no "socket.send() raised exception" from writes after it went."""

from __future__ import annotations

import socket
import struct

import pytest

from slicer_client.connection import Connection
from support import Processes, assert_clean_exit, start_daemon, wait_until

pytestmark = pytest.mark.ros


def test_a_client_reset_mid_stream_is_one_info_line(processes: Processes) -> None:
    daemon = start_daemon(processes)
    processes.python("pose", "pose_publisher.py", "/dl_pose", "1", "2", "3", "0", "0", "0", "1")
    client = Connection("127.0.0.1", daemon.port)
    device = client.command("create_subscriber", {"topic": "/dl_pose",
                                                  "type": "PoseStamped"})["device"]
    client.wait_for(device, timeout=30)  # the stream is flowing to it
    peer = client._sock.getsockname()
    # Leave abruptly: SO_LINGER 0 makes close() send a reset, as a killed Slicer would.
    client._sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    client._sock.close()
    gone = f"client {peer[0]}:{peer[1]} disconnected"
    wait_until(lambda: gone in daemon.child.output(), timeout=30, what="the disconnect line")
    # Let the stream run on past the client's end before judging the log.
    with Connection("127.0.0.1", daemon.port) as other:
        other.command("create_subscriber", {"topic": "/dl_pose", "type": "PoseStamped"})
        first = other.wait_for(device, timeout=30).timestamp
        other.wait_for(device, lambda m: m.timestamp != first, timeout=30)
    output = daemon.child.output()
    assert output.count(gone) == 1
    assert "socket.send() raised exception" not in output
    assert [line for line in output.splitlines() if f"{peer[0]}:{peer[1]}" in line
            and " WARNING " in line] == []
    assert_clean_exit(daemon)
