"""What a tf fan-out costs before any tf work: the floor under bench_daemon.py's tf figure.

Run: .venv/bin/python bench/bench_fanout_floor.py [--seconds 5] [--clients 0 1 8]

A bare subscriber, written as the daemon's streams thread is (rclpy's EventsExecutor, the
TFMessage taken raw, spin_once in a loop), receives bench/peers.py's /tf publisher (7
transforms at 1 kHz, its own process, sleeping between messages). Its callback does no tf
work at all: it only writes, per message, the bytes the daemon writes to each client for
one update of 7 streamed lookups (7 TRANSFORM messages, header v2 with their metadata,
encoded by the protocol package), to 0, 1 and 8 loopback TCP connections read by another
process. Printed per message: the spinning thread's CPU and the whole process's (Fast
DDS's receive threads included), in microseconds; at 1 kHz, 100 us is 10% of a core.

The daemon's own figure for the same load (bench_daemon.py, "tf of a 7-link robot ... -> 8
clients") minus this floor is what its tf work (parse, store, evaluate, encode) costs;
bench_daemon.py runs this floor for 8 clients right after that phase and prints it beside.
"""

from __future__ import annotations

import argparse
import os
import random
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from protocol.framing import encode  # noqa: E402
from protocol.messages import Message, Transform  # noqa: E402
from protocol.naming import NameKey, device_name_for, metadata_for  # noqa: E402

LINKS = 7
_READER = """
import selectors, socket, sys
socks = [socket.create_connection(("127.0.0.1", int(sys.argv[1]))) for _ in range(int(sys.argv[2]))]
sel = selectors.DefaultSelector()
for s in socks:
    sel.register(s, selectors.EVENT_READ)
print("READY", flush=True)
while True:
    for key, _ in sel.select():
        if not key.fileobj.recv(1 << 16):
            raise SystemExit
"""


def update_bytes() -> bytes:
    """One client's write for one /tf message: 7 lookups' TRANSFORMs, header v2."""
    out = []
    for i in range(1, LINKS + 1):
        key = NameKey.tf_lookup("base", f"link{i}")
        device = device_name_for(key)
        out.append(encode(Message(device_name=device, body=Transform(matrix=np.eye(4)),
                                  metadata=metadata_for(key, frame="base", units="mm")),
                          header_version=2))
    return b"".join(out)


def measure(clients: int, seconds: float, payload: bytes) -> tuple[int, float, float]:
    """(messages, thread us/msg, process us/msg) for one run with `clients` connections."""
    import rclpy
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from tf2_msgs.msg import TFMessage

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(64)
    reader = subprocess.Popen([sys.executable, "-c", _READER,
                               str(server.getsockname()[1]), str(clients)],
                              stdout=subprocess.PIPE, text=True)
    publisher = subprocess.Popen([sys.executable, str(REPO / "bench" / "peers.py"), "publish",
                                  "tf", "/tf"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                 text=True)
    context = Context()
    rclpy.init(context=context)
    try:
        connections = [server.accept()[0] for _ in range(clients)]
        for connection in connections:
            connection.setblocking(False)
            connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        assert reader.stdout is not None and reader.stdout.readline().strip() == "READY"
        assert publisher.stdout is not None and publisher.stdout.readline().strip() == "READY"
        node = rclpy.create_node("fanout_floor", context=context)
        count = [0]

        def on_tf(data: bytes) -> None:
            count[0] += 1
            for connection in connections:
                connection.send(payload)

        node.create_subscription(TFMessage, "/tf", on_tf, 5000, raw=True)
        executor = EventsExecutor(context=context)
        executor.add_node(node)
        stop = threading.Event()
        spent = [0.0]

        def spin() -> None:
            while not stop.is_set():
                executor.spin_once(timeout_sec=0.1)
            spent[0] = time.thread_time()

        assert publisher.stdin is not None
        publisher.stdin.write("WAIT 1\n")
        publisher.stdin.flush()
        publisher.stdout.readline()  # MATCHED n
        thread_start = [0.0]

        def spin_measured() -> None:
            thread_start[0] = time.thread_time()
            spin()

        thread = threading.Thread(target=spin_measured, daemon=True)
        thread.start()
        process_start = time.process_time()
        publisher.stdin.write(f"RUN 1000 {seconds}\n")
        publisher.stdin.flush()
        publisher.stdout.readline()  # DONE n
        time.sleep(0.2)
        stop.set()
        thread.join()
        process = time.process_time() - process_start
        n = max(count[0], 1)
        executor.shutdown()
        node.destroy_node()
        return count[0], (spent[0] - thread_start[0]) / n * 1e6, process / n * 1e6
    finally:
        rclpy.try_shutdown(context=context)
        if publisher.stdin is not None:
            try:
                publisher.stdin.write("QUIT\n")
                publisher.stdin.flush()
            except OSError:
                pass
        for child in (publisher, reader):
            try:
                child.wait(timeout=5)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
        server.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--clients", type=int, nargs="+", default=[0, 1, 8],
                        help="the client counts to measure, one run each (default 0 1 8)")
    args = parser.parse_args()
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(100, 200)))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    payload = update_bytes()
    print(f"/tf at 1 kHz, 7 transforms; per client per message {len(payload)} bytes "
          f"(7 TRANSFORMs, header v2); load {os.getloadavg()[0]:.2f}")
    for clients in args.clients:
        messages, thread_us, process_us = measure(clients, args.seconds, payload)
        print(f"  {clients} clients: {messages} messages; spinning thread {thread_us:6.1f} us"
              f"/msg, process {process_us:6.1f} us/msg ({process_us / 10:.1f}% of a core "
              f"at 1 kHz)", flush=True)


if __name__ == "__main__":
    main()
