"""Benchmark: tf latency from an rclpy /tf publish to the TRANSFORM at a client's socket.

Run: .venv/bin/python bench/bench_tf_latency.py [--quick]

Everything runs as separate processes, as in real use: the daemon (`bridge.cli run`), an
rclpy peer publishing /tf (this file with --peer), and a TCP client (slicer_client) here.
The peer stamps each transform with the wall clock at send time; the daemon keeps that
stamp as the TRANSFORM's IGTL time stamp; the client subtracts it from the wall clock when
the message is decoded. Same machine, same clock, so the difference is the whole path:
DDS, the daemon's buffer and lookup, the loop hand-off, TCP, decoding.

Measured in the same run:
1. streamed lookup (this daemon): create_tf_lookup world->tool, the peer publishes
   world->base (static) and base->tool at 200 Hz, every sample a new value;
2. baseline, the reference's scheme: the client polls the same lookup at 50 Hz
   (lookup_transform every 20 ms, what SlicerROS2's timer does in-process) while the same
   stream runs; its latency is the age of the value each poll first sees. The poll's own
   round trip (~0.3 ms here) is included: small next to the 20 ms period;
3. throughput: 100 lookups that all depend on one dynamic frame updated at 500 Hz, i.e.
   up to 50,000 lookup results a second asked of the daemon; reported: lookups evaluated
   and delivered per second at the client;
4. one-shot lookup_transform round trips per second (sequential, one client).
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from typing import Optional

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

NS = 1_000_000_000
# Each update moves the frame by 10 um: well above the lookup registry's change tolerance
# (1 um), so every update is a change to deliver.
STEP_M = 1e-5
STEP_MM = STEP_M * 1000.0


# ---------------------------------------------------------------------------- the peer


def run_peer(mode: str, prefix: str, rate: float, count: int, fan: int,
             stamps_out: str) -> None:
    """chain: world->base static x = 0.1 m, base->tool dynamic x = n * STEP_M.
    star: base->tool_i static x = 0.01 i m (i < fan), world->base dynamic x = n * STEP_M."""
    import rclpy
    from geometry_msgs.msg import TransformStamped
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from tf2_msgs.msg import TFMessage

    def tf(parent: str, child: str, x: float, stamp_ns: int) -> TransformStamped:
        t = TransformStamped()
        t.header.stamp.sec, t.header.stamp.nanosec = divmod(stamp_ns, NS)
        t.header.frame_id, t.child_frame_id = prefix + parent, prefix + child
        t.transform.translation.x = x
        t.transform.rotation.w = 1.0
        return t

    rclpy.init()
    node = rclpy.create_node("bench_tf_peer")
    static_pub = node.create_publisher(TFMessage, "/tf_static", QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    pub = node.create_publisher(TFMessage, "/tf", 100)
    now = time.time_ns()
    if mode == "chain":
        static_pub.publish(TFMessage(transforms=[tf("world", "base", 0.1, now)]))
        parent, child = "base", "tool"
    else:
        static_pub.publish(TFMessage(transforms=[tf("base", f"tool{i}", 0.01 * i, now)
                                                 for i in range(fan)]))
        parent, child = "world", "base"
    deadline = time.monotonic() + 20
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.5)  # let the latched static data land before the clock starts
    print("READY", flush=True)
    period = 1.0 / rate
    next_time = time.monotonic()
    stamps = []
    for n in range(1, count + 1):
        stamp = time.time_ns()
        pub.publish(TFMessage(transforms=[tf(parent, child, n * STEP_M, stamp)]))
        stamps.append(stamp)
        next_time += period
        delay = next_time - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    if stamps_out:
        with open(stamps_out, "w") as out:
            out.write("\n".join(map(str, stamps)))
    print(f"DONE {count}", flush=True)
    time.sleep(0.5)
    node.destroy_node()
    rclpy.try_shutdown()


# ---------------------------------------------------------------------------- the bench


class Recorder:
    """(receive wall-clock ns, IGTL stamp ns, x mm) per TRANSFORM, per device."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.rows: dict[str, list[tuple[int, int, float]]] = {}

    def __call__(self, message) -> None:  # receive thread
        received = time.time_ns()
        from protocol.conversions import ros_time_from_igtl
        from protocol.messages import Transform

        if not isinstance(message.body, Transform):
            return
        sec, nanosec = ros_time_from_igtl(message.timestamp)
        with self.lock:
            self.rows.setdefault(message.device_name, []).append(
                (received, sec * NS + nanosec, float(message.body.matrix[0, 3])))

    def of(self, device: str) -> list[tuple[int, int, float]]:
        with self.lock:
            return list(self.rows.get(device, []))


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    k = min(len(ordered) - 1, max(0, int(round(q / 100 * (len(ordered) - 1)))))
    return ordered[k]


def start_peer(mode: str, prefix: str, rate: float, count: int, fan: int = 0,
               stamps_out: str = "") -> subprocess.Popen[str]:
    proc = subprocess.Popen([sys.executable, "-u", os.path.abspath(__file__), "--peer", mode,
                             "--prefix", prefix, "--rate", str(rate), "--count", str(count),
                             "--fan", str(fan), "--stamps-out", stamps_out],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if "READY" not in line:
        raise RuntimeError(f"the peer did not start: {line!r}")
    return proc


def visibility_ms(stamps: list[int], seen: list[tuple[int, int]]) -> list[float]:
    """Per published update n (stamp stamps[n-1]): the time until the client's view first
    holds update n or a newer one. ``seen`` is (wall-clock ns, update number) in arrival
    order. An update merged away by coalescing (or never polled) counts as visible when a
    newer one arrives: what a viewer would experience."""
    out = []
    k = 0
    best = 0  # the newest update the client has seen up to seen[k - 1]
    for n, stamp in enumerate(stamps, start=1):
        while best < n and k < len(seen):
            best = max(best, seen[k][1])
            k += 1
        if best < n:
            break  # never seen (the run ended first)
        out.append((seen[k - 1][0] - stamp) / 1e6)
    return out


def read_stamps(path: str) -> list[int]:
    with open(path) as f:
        return [int(line) for line in f if line.strip()]


def wait_done(proc: subprocess.Popen[str]) -> None:
    assert proc.stdout is not None
    for line in proc.stdout:
        if line.startswith("DONE"):
            break
    proc.wait(timeout=10)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer samples (a smoke run)")
    parser.add_argument("--peer", choices=("chain", "star"))
    parser.add_argument("--prefix", default="")
    parser.add_argument("--rate", type=float, default=200.0)
    parser.add_argument("--count", type=int, default=1200)
    parser.add_argument("--fan", type=int, default=100)
    parser.add_argument("--stamps-out", default="")
    args = parser.parse_args()
    if args.peer:
        run_peer(args.peer, args.prefix, args.rate, args.count, args.fan, args.stamps_out)
        return 0

    # An isolated ROS graph for this run (this host is shared).
    os.environ["ROS_DOMAIN_ID"] = str(random.randint(1, 100))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ["ROS_LOG_DIR"] = tempfile.mkdtemp(prefix="bench-tf-roslog-")
    from slicer_client.connection import CommandRefusedError, Connection

    count = 300 if args.quick else 1200
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    daemon = subprocess.Popen([sys.executable, "-m", "bridge.cli", "run", "--port", str(port),
                               "--log-level", "WARNING"], cwd=REPO)
    recorder = Recorder()
    client: Optional[Connection] = None
    tmp = tempfile.mkdtemp(prefix="bench-tf-")
    try:
        deadline = time.monotonic() + 30
        while client is None:
            try:
                client = Connection("127.0.0.1", port, on_message=recorder)
            except ConnectionError:
                if time.monotonic() > deadline or daemon.poll() is not None:
                    raise
                time.sleep(0.1)

        # 1. streamed lookup
        device = client.command("create_tf_lookup",
                                {"parent": "a_world", "child": "a_tool"})["device"]
        stamps_a = os.path.join(tmp, "a.stamps")
        peer = start_peer("chain", "a_", 200.0, count, stamps_out=stamps_a)
        wait_done(peer)
        client.wait_for(device, lambda m: hasattr(m.body, "matrix")
                        and abs(m.body.matrix[0, 3] - (100.0 + count * STEP_MM)) < 1e-4,
                        timeout=10)
        rows = recorder.of(device)  # x mm = 100 + n * STEP_MM
        streamed = visibility_ms(read_stamps(stamps_a),
                                 [(r, round((x - 100.0) / STEP_MM)) for r, _, x in rows])
        streamed_own = [(r - s) / 1e6 for r, s, _ in rows]  # each message's own age
        streamed_seen = len({round((x - 100.0) / STEP_MM) for _, _, x in rows})

        # 2. the reference's scheme: poll at 50 Hz while the same stream runs
        stamps_b = os.path.join(tmp, "b.stamps")
        peer = start_peer("chain", "b_", 200.0, count, stamps_out=stamps_b)
        polls: list[tuple[int, int]] = []  # (wall-clock ns at the reply, update number)
        next_poll = time.monotonic()
        while peer.poll() is None:
            try:
                reply = client.command("lookup_transform", {"parent": "b_world",
                                                            "child": "b_tool"})
                polls.append((time.time_ns(), round((reply["translation"][0] - 0.1) / STEP_M)))
            except CommandRefusedError:
                pass  # before the first sample
            next_poll += 0.020
            delay = next_poll - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        wait_done(peer)
        polled = visibility_ms(read_stamps(stamps_b), polls)
        polled_seen = len({n for _, n in polls if n > 0})

        # 3. throughput: 100 lookups on one moving frame, 500 Hz
        fan = 20 if args.quick else 100
        devices = [client.command("create_tf_lookup", {"parent": "c_world",
                                                       "child": f"c_tool{i}"})["device"]
                   for i in range(fan)]
        seconds = 1.0 if args.quick else 3.0
        rate = 500.0
        peer = start_peer("star", "c_", rate, int(rate * seconds), fan)
        t0 = time.time_ns()
        wait_done(peer)
        final = int(rate * seconds) * STEP_MM
        for i, d in enumerate(devices):  # base->tool_i adds 10 i mm
            client.wait_for(d, lambda m, i=i: hasattr(m.body, "matrix")
                            and abs(m.body.matrix[0, 3] - (final + 10.0 * i)) < 1e-3,
                            timeout=20)
        star_rows = [row for d in devices for row in recorder.of(d) if row[0] >= t0]
        span = (max(r for r, _, _ in star_rows) - min(r for r, _, _ in star_rows)) / NS
        lookups_per_s = len(star_rows) / span
        star_latency = [(r - s) / 1e6 for r, s, _ in star_rows]

        # 4. one-shot lookups
        n_oneshot = 500 if args.quick else 2000
        rtts = []
        start = time.perf_counter()
        for _ in range(n_oneshot):
            t = time.perf_counter()
            client.command("lookup_transform", {"parent": "c_world", "child": "c_tool7"})
            rtts.append((time.perf_counter() - t) * 1e3)
        oneshot_per_s = n_oneshot / (time.perf_counter() - start)
    finally:
        if client is not None:
            client.close()
        daemon.send_signal(signal.SIGINT)
        try:
            daemon.wait(timeout=10)
        except subprocess.TimeoutExpired:
            daemon.kill()

    def row(name: str, values: list[float], extra: str) -> str:
        return (f"| {name:<40} | {len(values):>6} | {percentile(values, 50):>7.2f} | "
                f"{percentile(values, 99):>7.2f} | {max(values):>7.2f} | {extra:<30} |")

    print(f"\ntf latency: /tf publish (rclpy peer) -> TRANSFORM decoded at a client socket;"
          f" {count} updates at 200 Hz.\nPer update: time until the client's view holds it"
          f" (or a newer one); ms.\n")
    print(f"| {'path':<40} | {'n':>6} | {'p50':>7} | {'p99':>7} | {'max':>7} | "
          f"{'updates delivered individually':<30} |")
    print(f"|{'-' * 42}|{'-' * 8}|{'-' * 9}|{'-' * 9}|{'-' * 9}|{'-' * 32}|")
    print(row("streamed lookup (this daemon)", streamed,
              f"{streamed_seen}/{count} ({100 * streamed_seen / count:.0f}%)"))
    print(row("  same, each message's own age", streamed_own, "(message stamp -> arrival)"))
    print(row("baseline: 50 Hz poll (reference scheme)", polled,
              f"{polled_seen}/{count} ({100 * polled_seen / count:.0f}%), {len(polls)} polls"))
    print(row(f"{fan} lookups on one frame at 500 Hz", star_latency,
              f"{len(star_rows)}/{fan * int(rate * seconds)} results"))
    p50_ratio = percentile(polled, 50) / percentile(streamed, 50)
    p99_ratio = percentile(polled, 99) / percentile(streamed, 99)
    print(f"\nbaseline / streamed: p50 {p50_ratio:.1f}x, p99 {p99_ratio:.1f}x")
    print(f"lookups evaluated and delivered: {lookups_per_s:,.0f} /s "
          f"({fan} lookups x 500 Hz asked = {fan * rate:,.0f} /s)")
    print(f"one-shot lookup_transform: {oneshot_per_s:,.0f} /s sequential, round trip p50 "
          f"{percentile(rtts, 50):.2f} ms, p99 {percentile(rtts, 99):.2f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
