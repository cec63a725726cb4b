"""A client that leaves, even abruptly in the middle of a stream, is one INFO line in the
daemon's log: no "socket.send() raised exception" from writes after it went."""

from __future__ import annotations

import socket
import struct
from pathlib import Path

import pytest

from slicer_client.connection import Connection
from support import REPO, Processes, assert_clean_exit, scaled, start_daemon, wait_until

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


SCRIPT = """import sys
import slicer_client
ros = slicer_client.connect("127.0.0.1", int(sys.argv[1]))
ros.subscribe("/dl_script_pose", "PoseStamped").wait_for_message(timeout=60)
print("PEER %s:%d" % ros._transport._conn._sock.getsockname(), flush=True)
"""  # and ends without close(), as example scripts do


def test_a_script_that_ends_without_close_is_an_ordinary_disconnect(
        processes: Processes, tmp_path: Path) -> None:
    """Issue 43, item 12: each script's exit logged "Connection reset by peer": the kernel
    closed its socket with unread stream data in it. Connections left open are now closed
    at exit as close() does: the daemon logs a plain disconnect, the script no loss."""
    daemon = start_daemon(processes)
    processes.python("pose", "pose_publisher.py", "/dl_script_pose", "1", "2", "3", "0",
                     "0", "0", "1")
    script = tmp_path / "ends_without_close.py"
    script.write_text(SCRIPT)
    child = processes.python("script", str(script), str(daemon.port),
                             env={"PYTHONPATH": str(REPO)})
    peer = child.wait_for_output("PEER ", timeout=60).split("PEER ", 1)[1]
    assert child.popen.wait(scaled(30)) == 0, child.output()
    gone = f"client {peer} disconnected"
    wait_until(lambda: gone in daemon.child.output(), timeout=30, what="the disconnect line")
    assert [line.split(" INFO bridge.core.session: ", 1)[1] for line in
            daemon.child.output().splitlines() if f"client {peer} " in line] == \
        [f"client {peer} connected", gone]
    assert "lost the daemon" not in child.output()
    assert_clean_exit(daemon)
