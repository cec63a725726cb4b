"""Benchmark: a MarkerArray of 1000 markers from an rclpy publisher to a client's socket.

Run: .venv/bin/python bench/bench_markers.py [--markers 1000] [--rate 10] [--seconds 8]

Separate processes, as in real use: the daemon (`bridge.cli run`), an rclpy publisher
(this file, ``peer``; it sleeps between arrays), a raw OpenIGTLink reader (``reader``: it
parses only headers) and the baseline, a plain rclpy subscriber of the same MarkerArray
(``floor``), both measured in the same run on the same messages.

The publisher stamps every marker's header with the wall clock just before ``publish()``;
the daemon keeps that stamp as each model's OpenIGTLink time stamp. Latency of an array
= arrival of its LAST model at the reader (or of the array at the floor) - its stamp.
Same machine, same clock.

Two cases:
* ``all``: every marker moves by 1 um in each array, so the daemon re-meshes and re-sends
  all 1000 models (its worst case);
* ``one``: only marker 0 moves; the 999 others are re-sent unchanged, as RViz publishers
  re-publish whole arrays (the daemon's digest skips them: one model goes out).

The daemon's CPU per array is read from /proc (utime + stime) over the timed part.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import struct
import subprocess
import sys
import tempfile
import time
from typing import Any

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

NS = 1_000_000_000
TOPIC = "/bench_markers"
_HEADER = struct.Struct(">H12s20sQQQ")


def _stamp_ns(igtl: int) -> int:
    return (igtl >> 32) * NS + ((igtl & 0xFFFFFFFF) * NS >> 32)


# ---------------------------------------------------------------------------- children


def run_peer(markers: int, rate: float, seconds: float, mode: str) -> None:
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from visualization_msgs.msg import Marker, MarkerArray

    rclpy.init()
    node = rclpy.create_node("bench_marker_publisher")
    pub = node.create_publisher(MarkerArray, TOPIC, QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE))
    array = MarkerArray()
    for i in range(markers):
        m = Marker()
        m.header.frame_id = "base"
        m.ns, m.id, m.type = "bench", i, Marker.CUBE
        m.pose.position.x = (i % 10) * 0.1
        m.pose.position.y = (i // 10 % 10) * 0.1
        m.pose.position.z = (i // 100) * 0.1
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = m.scale.z = 0.05
        m.color.r, m.color.a = 1.0, 1.0
        array.markers.append(m)
    print("READY", flush=True)
    while pub.get_subscription_count() < 2:  # the daemon and the floor
        time.sleep(0.05)
    period = 1.0 / rate
    total = int(seconds * rate)
    warm = int(rate)  # one second not measured: discovery, first meshes
    due = time.monotonic()
    for n in range(warm + total):
        if n == warm:
            print(f"START {time.time_ns()}", flush=True)
        moved = array.markers if mode == "all" else array.markers[:1]
        for m in moved:
            m.pose.position.x += 1e-6
        now = time.time_ns()
        sec, nsec = divmod(now, NS)
        for m in array.markers:
            m.header.stamp.sec, m.header.stamp.nanosec = sec, nsec
        pub.publish(array)
        due += period
        delay = due - time.monotonic()
        if delay > 0:
            time.sleep(delay)  # sleep, never spin: the daemon needs the cores
        else:
            due = time.monotonic()
    print("DONE", flush=True)
    time.sleep(1.0)
    node.destroy_node()
    rclpy.shutdown()


def run_floor(seconds: float, out: str) -> None:
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from visualization_msgs.msg import MarkerArray

    rclpy.init()
    node = rclpy.create_node("bench_marker_floor")
    samples: list[tuple[int, int]] = []

    def on_message(msg: Any) -> None:
        arrival = time.time_ns()
        stamp = msg.markers[0].header.stamp
        samples.append((stamp.sec * NS + stamp.nanosec, arrival))

    node.create_subscription(MarkerArray, TOPIC, on_message, QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE))
    print("READY", flush=True)
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    with open(out, "w") as f:
        json.dump(samples, f)
    node.destroy_node()
    rclpy.shutdown()


def run_reader(port: int, seconds: float, out: str) -> None:
    """Headers only: per time stamp, the arrival of its last model (POLYDATA)."""
    sock = socket.create_connection(("127.0.0.1", port))
    sock.settimeout(0.2)
    print("READY", flush=True)
    last: dict[int, int] = {}
    counts: dict[int, int] = {}
    buf = bytearray()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            chunk = sock.recv(1 << 20)
        except socket.timeout:
            continue
        if not chunk:
            break
        arrival = time.time_ns()
        buf += chunk
        while len(buf) >= _HEADER.size:
            _, kind, _, stamp, size, _ = _HEADER.unpack_from(buf)
            if len(buf) < _HEADER.size + size:
                break
            if kind.rstrip(b"\0") == b"POLYDATA":
                key = _stamp_ns(stamp)
                last[key] = arrival
                counts[key] = counts.get(key, 0) + 1
            del buf[:_HEADER.size + size]
    with open(out, "w") as f:
        json.dump([(k, last[k], counts[k]) for k in sorted(last)], f)


# ---------------------------------------------------------------------------- the run


def _cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _percentiles(values: list[float]) -> dict[str, float]:
    if not values:
        return {"n": 0}
    ordered = sorted(values)

    def pick(q: float) -> float:
        return round(ordered[min(len(ordered) - 1, int(q * len(ordered)))], 2)
    return {"n": len(ordered), "p50": pick(0.5), "p99": pick(0.99), "max": pick(1.0)}


class _Child:
    def __init__(self, argv: list[str], log: str) -> None:
        self.log = log
        self.out = open(log, "w")
        self.popen = subprocess.Popen(argv, stdout=self.out, stderr=subprocess.STDOUT,
                                      stdin=subprocess.DEVNULL, cwd=REPO)

    def wait_for(self, needle: str, timeout: float = 60.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with open(self.log) as f:
                for line in f:
                    if needle in line:
                        return line.strip()
            if self.popen.poll() is not None:
                break
            time.sleep(0.05)
        with open(self.log) as f:
            raise RuntimeError(f"{self.popen.args[:4]}: no {needle!r}:\n{f.read()[-2000:]}")

    def stop(self) -> None:
        if self.popen.poll() is None:
            self.popen.send_signal(2)
            try:
                self.popen.wait(10)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        self.out.close()


def measure(args: argparse.Namespace, mode: str, tmp: str) -> dict[str, Any]:
    from slicer_client.connection import Connection

    me = [sys.executable, "-u", os.path.abspath(__file__)]
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()
    children: list[_Child] = []
    try:
        daemon = _Child([sys.executable, "-u", "-m", "bridge.cli", "run", "--port", str(port)],
                        f"{tmp}/daemon-{mode}.log")
        children.append(daemon)
        daemon.wait_for("listening on")
        client = Connection("127.0.0.1", port)
        client.command("create_marker_subscriber", {"topic": TOPIC, "type": "MarkerArray",
                                                    "fixed_frame": "world"})
        span = args.seconds + 12.0
        floor = _Child(me + ["floor", str(span), f"{tmp}/floor-{mode}.json"],
                       f"{tmp}/floor-{mode}.log")
        reader = _Child(me + ["reader", str(port), str(span), f"{tmp}/reader-{mode}.json"],
                        f"{tmp}/reader-{mode}.log")
        children += [floor, reader]
        floor.wait_for("READY")
        reader.wait_for("READY")
        peer = _Child(me + ["peer", str(args.markers), str(args.rate), str(args.seconds), mode],
                      f"{tmp}/peer-{mode}.log")
        children.append(peer)
        start_ns = int(peer.wait_for("START", timeout=60).split()[1])
        cpu0 = _cpu_s(daemon.popen.pid)
        peer.wait_for("DONE", timeout=args.seconds * 3 + 30)
        time.sleep(1.0)  # what is still in flight
        cpu1 = _cpu_s(daemon.popen.pid)
        listing = client.command("list_bridges")
        client.close()
        floor.popen.wait(span + 30)
        reader.popen.wait(span + 30)
        with open(f"{tmp}/floor-{mode}.json") as f:
            floor_samples = [(s, a) for s, a in json.load(f) if s >= start_ns]
        with open(f"{tmp}/reader-{mode}.json") as f:
            reader_samples = [(s, a, n) for s, a, n in json.load(f) if s >= start_ns]
        arrays = int(args.seconds * args.rate)
        bridge = [b for b in listing["bridges"] if b.get("kind") == "marker_subscriber"][0]
        return {
            "mode": mode, "markers": args.markers, "rate_hz": args.rate, "arrays": arrays,
            "daemon_ms": _percentiles([(a - s) / 1e6 for s, a, _ in reader_samples]),
            "models_per_array": round(sum(n for *_, n in reader_samples)
                                      / max(1, len(reader_samples)), 1),
            "floor_ms": _percentiles([(a - s) / 1e6 for s, a in floor_samples]),
            "daemon_cpu_ms_per_array": round((cpu1 - cpu0) * 1000.0 / max(1, arrays), 2),
            "daemon_dropped": bridge.get("dropped"),
            "load_average_1min": round(os.getloadavg()[0], 2),
        }
    finally:
        for child in reversed(children):
            child.stop()


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] in ("peer", "floor", "reader"):
        role, rest = sys.argv[1], sys.argv[2:]
        if role == "peer":
            run_peer(int(rest[0]), float(rest[1]), float(rest[2]), rest[3])
        elif role == "floor":
            run_floor(float(rest[0]), rest[1])
        else:
            run_reader(int(rest[0]), float(rest[1]), rest[2])
        return 0
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--markers", type=int, default=1000)
    parser.add_argument("--rate", type=float, default=10.0)
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--modes", default="all,one")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-markers-") as tmp:
        for mode in args.modes.split(","):
            result = measure(args, mode, tmp)
            print(json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
