"""Daemon benchmark: ROS -> OpenIGTLink latency, throughput, image latency and memory,
against the naive relay a Python user would write (pyigtl's server + rclpy), measured in
the same run on the same machine.

    .venv/bin/python bench/bench_daemon.py            # ~1 minute
    .venv/bin/python bench/bench_daemon.py --quick    # ~20 s

Latency is from the rclpy `publish()` call (its time goes in header.stamp) to the decoded
message at a client socket in this process; both relays carry the stamp into the
OpenIGTLink timestamp. Each relay runs alone while it is measured.
"""

from __future__ import annotations

import argparse
import os
import random
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

# Isolate from other ROS users of this host before rclpy is imported.
os.environ["ROS_DOMAIN_ID"] = str(random.randint(1, 100))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="bench-roslog-"))

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402

from protocol.conversions import ros_time_from_igtl  # noqa: E402
from protocol.framing import Decoder  # noqa: E402
from slicer_client.connection import Connection  # noqa: E402

POSE_TOPIC = "/bench_pose"
IMAGE_TOPIC = "/bench_image"


@dataclass
class Receiver:
    """A plain TCP client: decodes everything, records latency per device."""

    port: int
    latencies: dict[str, list[int]] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._sock = socket.create_connection(("127.0.0.1", self.port), timeout=10)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock.settimeout(None)
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        decoder = Decoder(max_body_size=1 << 26)
        while True:
            try:
                data = self._sock.recv(1 << 20)
            except OSError:
                return
            if not data:
                return
            arrived = time.time_ns()
            decoder.feed(data)
            for message in decoder.messages():
                if message.type_name not in ("TRANSFORM", "IMAGE") or not message.timestamp:
                    continue
                sec, nanosec = ros_time_from_igtl(message.timestamp)
                with self._lock:
                    self.latencies.setdefault(message.device_name, []).append(
                        arrived - (sec * 1_000_000_000 + nanosec))
                    self.counts[message.device_name] = self.counts.get(
                        message.device_name, 0) + 1

    def reset(self) -> None:
        with self._lock:
            self.latencies.clear()
            self.counts.clear()

    def take(self, device: str) -> list[int]:
        with self._lock:
            return list(self.latencies.get(device, []))

    def close(self) -> None:
        self._sock.close()
        self._thread.join(2)


class Publisher:
    """rclpy publishers in this process, paced in a loop (timers cannot do kHz)."""

    def __init__(self) -> None:
        rclpy.init()
        self.node = rclpy.create_node("bench_publisher")
        self.poses = self.node.create_publisher(PoseStamped, POSE_TOPIC, 1000)
        self.images = self.node.create_publisher(Image, IMAGE_TOPIC, 10)
        self.pose = PoseStamped()
        self.pose.header.frame_id = "world"
        self.pose.pose.position.x = 0.0031415
        self.pose.pose.orientation.w = 1.0
        self.image = Image(height=480, width=640, encoding="rgb8", step=640 * 3)
        self.image.data = np.random.default_rng(0).integers(
            0, 255, 640 * 480 * 3, dtype=np.uint8).tobytes()

    def wait_for_subscriber(self, publisher: object, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while publisher.get_subscription_count() == 0:  # type: ignore[attr-defined]
            if time.monotonic() > deadline:
                raise SystemExit("no relay subscribed to the benchmark topic")
            time.sleep(0.01)

    @staticmethod
    def _stamp(header: object) -> None:
        now = time.time_ns()
        header.stamp = Time(sec=now // 1_000_000_000,  # type: ignore[attr-defined]
                            nanosec=now % 1_000_000_000)

    def run(self, publisher: object, message: object, rate_hz: float, seconds: float) -> int:
        period = 1.0 / rate_hz
        count = int(rate_hz * seconds)
        start = time.perf_counter()
        for n in range(count):
            target = start + n * period
            while (delay := target - time.perf_counter()) > 0:
                # sleep(0) releases the GIL: the receiver thread must not starve.
                time.sleep(delay - 0.0003 if delay > 0.0005 else 0)
            self._stamp(message.header)  # type: ignore[attr-defined]
            publisher.publish(message)  # type: ignore[attr-defined]
        return count

    def close(self) -> None:
        self.node.destroy_node()
        rclpy.try_shutdown()


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def start(argv: list[str], ready: str) -> subprocess.Popen[str]:
    env = dict(os.environ)
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env, cwd=REPO, start_new_session=True)
    assert proc.stdout is not None
    for line in proc.stdout:
        if ready in line:
            threading.Thread(target=proc.stdout.read, daemon=True).start()  # drain
            return proc
    raise SystemExit(f"{argv} exited before '{ready}'")


def stop(proc: subprocess.Popen[str]) -> None:
    proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def memory_kib(pid: int) -> tuple[int, int]:
    """(VmRSS, VmHWM) in KiB."""
    fields = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text()
                  .splitlines() if ":" in line)
    return int(fields["VmRSS"].split()[0]), int(fields["VmHWM"].split()[0])


def stats_ms(latencies_ns: list[int]) -> dict[str, float]:
    if not latencies_ns:
        return {"n": 0, "p50": float("nan"), "p99": float("nan"), "max": float("nan")}
    values = np.asarray(latencies_ns, dtype=np.float64) / 1e6
    return {"n": len(values), "p50": float(np.percentile(values, 50)),
            "p99": float(np.percentile(values, 99)), "max": float(values.max())}


@dataclass
class RelayResult:
    name: str
    latency: dict[str, float]
    throughput: list[tuple[int, int, float, float]]  # rate, received/s, lag first, lag last
    image: dict[str, float]
    memory_kib: tuple[int, int] = (0, 0)


def measure(name: str, publisher: Publisher, receiver: Receiver, pose_device: str,
            image_device: str, args: argparse.Namespace, pid: int) -> RelayResult:
    publisher.wait_for_subscriber(publisher.poses)
    publisher.wait_for_subscriber(publisher.images)
    # Warm-up: discovery, first allocations.
    publisher.run(publisher.poses, publisher.pose, 200, 0.5)
    time.sleep(0.5)
    receiver.reset()
    publisher.run(publisher.poses, publisher.pose, args.rate, args.seconds)
    time.sleep(0.5)
    latency = stats_ms(receiver.take(pose_device))
    latency["sent"] = int(args.rate * args.seconds)

    throughput = []
    for rate in args.throughput_rates:
        receiver.reset()
        started = time.perf_counter()
        sent = publisher.run(publisher.poses, publisher.pose, rate, args.burst_seconds)
        elapsed = time.perf_counter() - started
        time.sleep(0.5)
        lat = receiver.take(pose_device)
        quarter = max(1, len(lat) // 4)
        throughput.append((rate, int(len(lat) / elapsed), stats_ms(lat[:quarter])["p50"],
                           stats_ms(lat[-quarter:])["p50"]))
        del sent

    receiver.reset()
    publisher.run(publisher.images, publisher.image, 30, args.seconds)
    time.sleep(0.5)
    image = stats_ms(receiver.take(image_device))
    image["sent"] = int(30 * args.seconds)
    return RelayResult(name, latency, throughput, image, memory_kib(pid))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="shorter phases")
    parser.add_argument("--rate", type=float, default=1000.0, help="latency phase rate (Hz)")
    args = parser.parse_args()
    args.seconds = 2.0 if args.quick else 5.0
    args.burst_seconds = 1.0 if args.quick else 2.0
    args.throughput_rates = [1000, 3000, 5000] if args.quick else [1000, 2000, 3000, 4000, 6000]

    # The publisher loop and the receiver thread share this process's GIL.
    sys.setswitchinterval(0.0002)
    publisher = Publisher()
    results = []
    try:
        # Ours.
        port = free_port()
        daemon = start([sys.executable, "-m", "bridge.cli", "run", "--port", str(port),
                        "--log-level", "INFO"], "listening on")
        try:
            with Connection("127.0.0.1", port) as setup:
                pose_device = setup.command("create_subscriber", {
                    "topic": POSE_TOPIC, "type": "PoseStamped", "qos": {"depth": 1000}})["device"]
                image_device = setup.command("create_subscriber", {
                    "topic": IMAGE_TOPIC, "type": "Image"})["device"]
            receiver = Receiver(port)
            results.append(measure("slicer-ros2-bridge", publisher, receiver, pose_device,
                                   image_device, args, daemon.pid))
            receiver.close()
        finally:
            stop(daemon)
        # The naive relay.
        port = free_port()
        relay = start([sys.executable, str(REPO / "bench" / "naive_relay.py"), str(port),
                       POSE_TOPIC, IMAGE_TOPIC], "READY")
        try:
            receiver = Receiver(port)
            results.append(measure("naive pyigtl relay", publisher, receiver, "pose",
                                   "camera", args, relay.pid))
            receiver.close()
        finally:
            stop(relay)
    finally:
        publisher.close()
    report(results, args)
    return 0


def report(results: list[RelayResult], args: argparse.Namespace) -> None:
    ours, naive = results
    print(f"\nPoseStamped -> TRANSFORM at {args.rate:.0f} Hz for {args.seconds:.0f} s "
          f"(latency in ms, publish() -> decoded at the client)")
    print(f"{'relay':<22}{'received':>10}{'p50':>9}{'p99':>9}{'max':>9}")
    for r in results:
        print(f"{r.name:<22}{r.latency['n']:>6}/{r.latency['sent']:<4}"
              f"{r.latency['p50']:>8.3f}{r.latency['p99']:>9.3f}{r.latency['max']:>9.2f}")
    print(f"p50 ratio naive/ours: {naive.latency['p50'] / ours.latency['p50']:.1f}x, "
          f"p99 ratio: {naive.latency['p99'] / ours.latency['p99']:.1f}x")

    print(f"\nSustained PoseStamped throughput ({args.burst_seconds:.0f} s bursts; lag = p50 "
          f"latency in the first and last quarter, ms)")
    print(f"{'relay':<22}{'rate':>7}{'recv/s':>9}{'lag first':>11}{'lag last':>10}")
    for r in results:
        for rate, received, first, last in r.throughput:
            print(f"{r.name:<22}{rate:>7}{received:>9}{first:>11.3f}{last:>10.3f}")

    print("\n640x480 rgb8 Image -> IMAGE at 30 Hz (ms)")
    print(f"{'relay':<22}{'received':>10}{'p50':>9}{'p99':>9}{'max':>9}")
    for r in results:
        print(f"{r.name:<22}{r.image['n']:>6}/{r.image['sent']:<4}{r.image['p50']:>8.3f}"
              f"{r.image['p99']:>9.3f}{r.image['max']:>9.2f}")
    print(f"image p50 ratio naive/ours: {naive.image['p50'] / ours.image['p50']:.1f}x")

    print("\nRelay process memory (MiB): RSS at the end / peak")
    for r in results:
        print(f"{r.name:<22}{r.memory_kib[0] / 1024:>8.1f} / {r.memory_kib[1] / 1024:.1f}")


if __name__ == "__main__":
    sys.exit(main())
