"""Attacks on a running daemon (issues 12 and 22), each bounded, on 127.0.0.1 only, with the
daemon's figures before and after, a fresh client served during each, and another client's
tf stream and hello round trip while each runs, beside their baseline from the same run.

Run: .venv/bin/python bench/attacks.py [--only NAME ...] [--flood-seconds 10] [--json OUT]
     [--flood-depth 10] [--flood-remove] [--storm-seconds 15] [-- DAEMON OPTIONS ...]

The daemon runs as a user runs it (`bridge.cli run`, default options unless given after
``--``), in its own ROS domain, localhost only. Attacks, in order:

- slowloris: 64 connections (the default --max-clients) each send 7 bytes of a header
  and nothing more, and hold on for the frame deadline and 3 s more;
- half-sent bodies: 16 connections each declare a 59 MiB body and send all but its last
  KiB, then hold on;
- hold and go: 6 clients each send 40 MiB of a body, then disconnect without finishing;
- flood (a measurement): a rclpy peer publishes a 20 MB PointCloud2 at 10 Hz to a topic a
  client subscribes to, for --flood-seconds, three floods in a row;
- the storms of issue 22 (bench/storms.py): marker_storm, marker_bomb, marker_bomb_ros,
  polydata, tf_frames, service_slots.

The other client (bench/peers.py ``watch``, its own process) streams the tf lookup base <-
link7 of a 7-link robot that a rclpy peer (bench/peers.py ``publish tf``, sleeping between
messages) publishes at 100 Hz, and sends ``hello`` at 10 Hz. Its figures (tf latency
publish() -> last byte, p50 / p99 / max; hello round trip) are measured for --storm-seconds
before any attack (the baseline) and during each attack. Targets (issue 22): tf p99 under
20 ms and every hello answered within 100 ms during each storm.

Measured for each: the daemon's RSS, open fds, threads and ROS entities (the daemon node's
publishers, subscribers, services and clients in the ROS graph) before, at the peak and
after (once RSS has settled, at most 15 s); whether a fresh client connecting mid-attack
got its hello answered (and in how long); what the attackers were told (STATUS texts) and
how many connections the daemon closed. --flood-remove then removes the flood's
subscriber and measures again, which shows what the subscription itself holds (its ROS
history of --flood-depth messages, its last message, the hub's latest value). Exit code 1
if a fresh client was not served or fds/entities did not come back.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import select
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Callable, Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.storms import STORMS, run_storm  # noqa: E402
from protocol.framing import Decoder  # noqa: E402
from slicer_client.connection import BridgeClientError, Connection  # noqa: E402

MIB = 1 << 20
HEADER = struct.Struct(">H12s20sQQQ")
DAEMON_NODE = "slicer_bridge"
FLOOD_TOPIC = "/attack_cloud"
FLOOD_POINTS = 20_000_000 // 16  # x, y, z, rgb float32: 16 bytes a point, 20 MB a message


def header(body_size: int, type_name: bytes = b"STRING") -> bytes:
    return HEADER.pack(1, type_name, b"attack", 0, body_size, 0)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


# ------------------------------------------------------------------------- measuring


class Graph:
    """The daemon node's ROS entities, as the ROS graph shows them."""

    def __init__(self) -> None:
        import rclpy

        self._rclpy = rclpy
        rclpy.init()
        self.node = rclpy.create_node("attack_bench_observer")

    def entities(self) -> dict[str, int]:
        """Counts per kind; all 0 while the graph has not discovered the node yet."""
        node, ns = DAEMON_NODE, "/"
        if (node, ns) not in self.node.get_node_names_and_namespaces():
            return dict.fromkeys(("publishers", "subscribers", "services", "clients"), 0)
        return {
            "publishers": len(self.node.get_publisher_names_and_types_by_node(node, ns)),
            "subscribers": len(self.node.get_subscriber_names_and_types_by_node(node, ns)),
            "services": len(self.node.get_service_names_and_types_by_node(node, ns)),
            "clients": len(self.node.get_client_names_and_types_by_node(node, ns)),
        }

    def close(self) -> None:
        self.node.destroy_node()
        self._rclpy.try_shutdown()


def proc_figures(pid: int) -> dict[str, int]:
    status = Path(f"/proc/{pid}/status").read_text().splitlines()
    fields = {line.split(":")[0]: line.split(":")[1].split() for line in status}
    return {"rss_mb": int(fields["VmRSS"][0]) // 1024, "threads": int(fields["Threads"][0]),
            "fds": len(os.listdir(f"/proc/{pid}/fd"))}


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of the process so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def settled(pid: int, timeout: float = 15.0) -> dict[str, int]:
    """Figures once RSS has stopped falling for a second (or after ``timeout``)."""
    deadline = time.monotonic() + timeout
    last = proc_figures(pid)
    stable_since = time.monotonic()
    while time.monotonic() < deadline:
        time.sleep(0.25)
        now = proc_figures(pid)
        if now["rss_mb"] < last["rss_mb"] - 1 or now["fds"] != last["fds"]:
            stable_since = time.monotonic()
        elif time.monotonic() - stable_since >= 1.0:
            return now
        last = now
    return last


class Peak:
    """Samples the daemon's RSS every 100 ms in the background; the maximum seen."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.rss_mb = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(0.1):
            try:
                self.rss_mb = max(self.rss_mb, proc_figures(self.pid)["rss_mb"])
            except OSError:
                return

    def stop(self) -> int:
        self._stop.set()
        self._thread.join()
        return self.rss_mb


def fresh_client_served(port: int, timeout: float = 20.0) -> Optional[float]:
    """Seconds until a new client's hello is answered (retrying a refused connection), or
    None if it never was."""
    start = time.monotonic()
    while time.monotonic() - start < timeout:
        try:
            with Connection("127.0.0.1", port) as client:
                client.command("hello", timeout=max(0.5, timeout - (time.monotonic() - start)))
                return time.monotonic() - start
        except (BridgeClientError, OSError):  # refused at max-clients, or closed: again
            time.sleep(0.1)
    return None


def statuses(sock: socket.socket) -> list[str]:
    """The texts of the STATUS messages the daemon has sent on ``sock`` so far."""
    decoder = Decoder()
    sock.setblocking(False)
    try:
        while data := sock.recv(1 << 16):
            decoder.feed(data)
    except OSError:  # nothing more for now (BlockingIOError), or reset
        pass
    return [m.body.text for m in decoder.messages() if m.type_name == "STATUS"]


def closed_by_daemon(sock: socket.socket) -> bool:
    readable, _, _ = select.select([sock], [], [], 0)
    return bool(readable)


# ------------------------------------------------------------------------- attacks


def slowloris(port: int, deadline_s: float) -> dict[str, Any]:
    socks = []
    for _ in range(64):
        try:
            sock = socket.create_connection(("127.0.0.1", port), timeout=5)
            sock.sendall(header(64)[:7])
            socks.append(sock)
        except OSError:
            break
    served = fresh_client_served(port)
    end = time.monotonic() + deadline_s + 3.0
    while time.monotonic() < end and not all(closed_by_daemon(s) for s in socks):
        time.sleep(0.1)
    closed = sum(closed_by_daemon(s) for s in socks)
    said = [statuses(s) for s in socks[:1]]
    for sock in socks:
        sock.close()
    return {"connections": len(socks), "closed_by_daemon": closed, "served_s": served,
            "told": said[0][:1] if said else []}


def half_sent_bodies(port: int) -> dict[str, Any]:
    body = 59 * MIB
    chunk = bytes(MIB)
    socks: list[socket.socket] = []
    refused = 0

    def attack(sock: socket.socket) -> None:
        nonlocal refused
        try:
            sock.sendall(header(body))
            for _ in range(58):
                sock.sendall(chunk)
            sock.sendall(bytes(MIB - 1024))  # all but the last KiB
        except OSError:
            refused += 1

    threads = []
    for _ in range(16):
        sock = socket.create_connection(("127.0.0.1", port), timeout=30)
        socks.append(sock)
        thread = threading.Thread(target=attack, args=(sock,))
        thread.start()
        threads.append(thread)
    served = fresh_client_served(port)
    for thread in threads:
        thread.join()
    told = [t for s in socks for t in statuses(s)]
    held = sum(not closed_by_daemon(s) for s in socks)
    for sock in socks:
        sock.close()
    return {"connections": 16, "declared_mib_each": 59, "held_by_daemon": held,
            "refused": 16 - held, "served_s": served, "told": told[:1]}


def hold_and_go(port: int) -> dict[str, Any]:
    socks = []
    for _ in range(6):
        sock = socket.create_connection(("127.0.0.1", port), timeout=30)
        try:
            sock.sendall(header(41 * MIB))
            for _ in range(40):
                sock.sendall(bytes(MIB))
        except OSError:
            pass
        socks.append(sock)
    served = fresh_client_served(port)
    held = sum(not closed_by_daemon(s) for s in socks)
    told = [t for s in socks for t in statuses(s)]
    for sock in socks:
        sock.close()
    return {"clients": 6, "held_40_mib": held, "refused": 6 - held, "served_s": served,
            "told": told[:1]}


def flood(port: int, env: dict[str, str], logs: Path, seconds: float,
          received: Callable[[], int], round_: int) -> dict[str, Any]:
    before = received()
    peer = subprocess.Popen([sys.executable, "-u", __file__, "--flood-peer", FLOOD_TOPIC,
                             str(seconds)], env=env, cwd=str(REPO), stdin=subprocess.DEVNULL,
                            stdout=(logs / f"flood{round_}.log").open("wb"),
                            stderr=subprocess.STDOUT, start_new_session=True)
    try:
        time.sleep(seconds / 2)  # mid-flood
        served = fresh_client_served(port)
        peer.wait(seconds * 3 + 30)
    finally:
        if peer.poll() is None:
            os.killpg(peer.pid, signal.SIGKILL)
            peer.wait()
    text = (logs / f"flood{round_}.log").read_text()
    sent = int(text.split("SENT ")[-1].split()[0]) if "SENT " in text else 0
    return {"seconds": seconds, "sent": sent, "delivered_to_client": received() - before,
            "served_s": served}


def flood_peer(topic: str, seconds: float) -> int:
    """A rclpy peer: a 20 MB PointCloud2 at 10 Hz on ``topic`` for ``seconds``."""
    import numpy as np
    import rclpy
    from sensor_msgs.msg import PointCloud2, PointField

    rclpy.init()
    node = rclpy.create_node("attack_flood_peer")
    publisher = node.create_publisher(PointCloud2, topic, 2)
    deadline = time.monotonic() + 20
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.02)
    fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
              for i, n in enumerate(("x", "y", "z", "rgb"))]
    rng = np.random.default_rng(0)
    points = rng.random((FLOOD_POINTS, 4), dtype=np.float32)
    message = PointCloud2(height=1, width=FLOOD_POINTS, fields=fields, is_bigendian=False,
                          point_step=16, row_step=16 * FLOOD_POINTS, is_dense=True)
    message.data = points.tobytes()
    print("READY", flush=True)
    start = time.monotonic()
    n = 0
    while time.monotonic() - start < seconds:
        n += 1
        due = start + n * 0.1
        if due > time.monotonic():
            time.sleep(due - time.monotonic())
        message.header.frame_id = f"seq:{n}"
        publisher.publish(message)
    print(f"SENT {n}", flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


class Watcher:
    """The other client and its tf source: bench/peers.py ``publish tf`` at 100 Hz and
    ``watch`` (each its own process); `measure` gives its figures over a span."""

    def __init__(self, port: int, env: dict[str, str], logs: Path) -> None:
        peers = str(REPO / "bench" / "peers.py")
        self.publisher = subprocess.Popen(
            [sys.executable, "-u", peers, "publish", "tf", "/tf"], env=env, cwd=str(REPO),
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=(logs / "tf.log").open("wb"),
            text=True, start_new_session=True)
        self.watcher = subprocess.Popen(
            [sys.executable, "-u", peers, "watch", str(port), "base", "link7"], env=env,
            cwd=str(REPO), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=(logs / "watch.log").open("wb"), text=True, start_new_session=True)
        # The floor: a plain rclpy subscriber of the same /tf, its own process. What the
        # machine's load alone does to a ROS stream, beside what the client sees.
        self.floor = subprocess.Popen(
            [sys.executable, "-u", peers, "floor", "tf", "/tf"], env=env, cwd=str(REPO),
            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=(logs / "floor.log").open("wb"), text=True, start_new_session=True)
        for child in (self.publisher, self.watcher, self.floor):
            self._expect(child, "READY")
        self._say(self.publisher, "WAIT 2")
        self._expect(self.publisher, "MATCHED")
        self._say(self.publisher, "RUN 100 100000")  # until stopped

    @staticmethod
    def _say(child: subprocess.Popen[str], line: str) -> None:
        assert child.stdin is not None
        child.stdin.write(line + "\n")
        child.stdin.flush()

    @staticmethod
    def _expect(child: subprocess.Popen[str], word: str) -> str:
        assert child.stdout is not None
        while True:
            line = child.stdout.readline()
            if not line:
                raise RuntimeError(f"a bench peer exited before {word}")
            if line.startswith(word):
                return line

    def reset(self) -> None:
        self._say(self.watcher, "RESET")
        self._say(self.floor, "RESET")

    def report(self) -> dict[str, Any]:
        self._say(self.floor, "REPORT")
        floor = json.loads(self._expect(self.floor, "{"))["all"]
        self._say(self.watcher, "REPORT")
        data = json.loads(self._expect(self.watcher, "{"))
        tf = data["streams"].get("tf", {"n": 0, "p50": None, "p99": None, "max": None})
        hello = data["streams"].get("hello", {"n": 0, "p50": None, "p99": None, "max": None})
        return {"tf_n": tf["n"], "tf_p50_ms": tf["p50"], "tf_p99_ms": tf["p99"],
                "tf_max_ms": tf["max"], "hello_n": hello["n"], "hello_p99_ms": hello["p99"],
                "hello_max_ms": max(hello["max"] or 0.0,
                                    data["hello_unanswered"]["oldest_ms"]),
                "hello_unanswered": data["hello_unanswered"]["n"],
                "disconnected": data["disconnected"],
                "floor_p99_ms": floor["p99"], "floor_max_ms": floor["max"]}

    def close(self) -> None:
        for child in (self.watcher, self.floor, self.publisher):
            try:
                os.killpg(child.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            child.wait()


def _watched(figures: dict[str, Any]) -> str:
    def ms(value: Any) -> str:
        return "-" if value is None else f"{value:.1f}"
    return (f"tf p50 {ms(figures['tf_p50_ms'])} / p99 {ms(figures['tf_p99_ms'])} / max "
            f"{ms(figures['tf_max_ms'])} ms (n {figures['tf_n']}; rclpy floor p99 "
            f"{ms(figures['floor_p99_ms'])} / max {ms(figures['floor_max_ms'])}); hello p99 "
            f"{ms(figures['hello_p99_ms'])} / max {ms(figures['hello_max_ms'])} ms "
            f"(n {figures['hello_n']}, unanswered {figures['hello_unanswered']})"
            + (" DISCONNECTED by the daemon" if figures["disconnected"] else ""))


def _meets_targets(figures: dict[str, Any]) -> bool:
    p99 = figures["tf_p99_ms"]
    return (figures["tf_n"] > 0 and p99 is not None and p99 < 20.0
            and figures["hello_max_ms"] < 100.0 and not figures["disconnected"])


# ------------------------------------------------------------------------- driver


def main() -> int:
    if sys.argv[1:2] == ["--flood-peer"]:
        return flood_peer(sys.argv[2], float(sys.argv[3]))
    argv = sys.argv[1:]
    daemon_args: list[str] = []
    if "--" in argv:
        daemon_args = argv[argv.index("--") + 1:]
        argv = argv[:argv.index("--")]
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", action="append", choices=["slowloris", "half_sent_bodies",
                                                            "hold_and_go", "flood",
                                                            *STORMS])
    parser.add_argument("--storm-seconds", type=float, default=15.0,
                        help="how long a storm runs (and the baseline is measured)")
    parser.add_argument("--flood-seconds", type=float, default=10.0)
    parser.add_argument("--flood-depth", type=int, default=None,
                        help="the flood subscriber's QoS depth (history kept by ROS; default: "
                             "the bridge's, 1 for point clouds)")
    parser.add_argument("--flood-remove", action="store_true",
                        help="remove the flood subscriber after the floods and measure again")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    chosen = args.only or ["slowloris", "half_sent_bodies", "hold_and_go", "flood", *STORMS]

    logs = Path(tempfile.mkdtemp(prefix="attacks-"))
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(102, 200)),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_LOG_DIR=str(logs / "roslog"),
               PYTHONUNBUFFERED="1")
    env.pop("ROS_STATIC_PEERS", None)
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE",
                                           "ROS_LOG_DIR")})
    port = free_port()
    deadline_s = 5.0
    if "--frame-deadline" in daemon_args:
        deadline_s = float(daemon_args[daemon_args.index("--frame-deadline") + 1])
    log_path = logs / "daemon.log"
    daemon = subprocess.Popen([sys.executable, "-u", "-m", "bridge.cli", "run", "--port",
                               str(port), *daemon_args], env=env, cwd=str(REPO),
                              stdin=subprocess.DEVNULL, stdout=log_path.open("wb"),
                              stderr=subprocess.STDOUT, start_new_session=True)
    graph: Optional[Graph] = None
    watcher: Optional[Watcher] = None
    subscriber: Optional[Connection] = None
    clouds_received = [0]

    def count_cloud(message: Any) -> None:
        clouds_received[0] += 1
    results: list[dict[str, Any]] = []
    try:
        start = time.monotonic()
        while "listening on" not in log_path.read_text(errors="replace"):
            if daemon.poll() is not None or time.monotonic() - start > 60:
                raise RuntimeError(f"the daemon did not start:\n{log_path.read_text()}")
            time.sleep(0.05)
        graph = Graph()
        discovered = time.monotonic() + 30
        while graph.entities()["publishers"] == 0 and time.monotonic() < discovered:
            time.sleep(0.1)  # the baseline needs the daemon's node in the graph
        pid = daemon.pid
        print(f"attacks on the daemon (pid {pid}, port {port}, options "
              f"{daemon_args or 'default'}); logs in {logs}", flush=True)
        watcher = Watcher(port, env, logs)
        time.sleep(2.0)  # the lookup streams: the baseline starts on a running stream
        watcher.reset()
        time.sleep(args.storm_seconds)
        baseline = watcher.report()
        baseline_load = round(os.getloadavg()[0], 1)
        print(f"\n== baseline (no attack, {args.storm_seconds:g} s)\n   other client: "
              f"{_watched(baseline)}", flush=True)
        for name in chosen:
            rounds = 3 if name == "flood" else 1
            for round_ in range(1, rounds + 1):
                if name == "flood" and subscriber is None:
                    subscriber = Connection("127.0.0.1", port, on_message=count_cloud)
                    qos = {} if args.flood_depth is None else {"depth": args.flood_depth}
                    subscriber.command("create_subscriber", {
                        "topic": FLOOD_TOPIC, "type": "PointCloud2", "qos": qos})
                before = {**settled(pid), **graph.entities()}
                peak = Peak(pid)
                cpu_before = cpu_seconds(pid)
                started = time.monotonic()
                watcher.reset()
                if name in STORMS:
                    # Measured from the attack proper (its set-up, building its messages,
                    # is not part of it).
                    outcome = run_storm(name, port, env, logs, args.storm_seconds,
                                        started=watcher.reset)
                    outcome["served_s"] = fresh_client_served(port)
                elif name == "slowloris":
                    outcome = slowloris(port, deadline_s)
                elif name == "half_sent_bodies":
                    outcome = half_sent_bodies(port)
                elif name == "hold_and_go":
                    outcome = hold_and_go(port)
                else:
                    outcome = flood(port, env, logs, args.flood_seconds,
                                    lambda: clouds_received[0], round_)
                watched = watcher.report()
                cpu = (cpu_seconds(pid) - cpu_before) / max(1e-9, time.monotonic() - started)
                peak_rss = peak.stop()
                after = {**settled(pid), **graph.entities()}
                label = name if rounds == 1 else f"{name} {round_}"
                result = {"attack": label, "before": before, "peak_rss_mb": peak_rss,
                          "after": after, "watched": watched, "daemon_cpu": round(cpu, 2),
                          "load": round(os.getloadavg()[0], 1), **outcome}
                results.append(result)
                print(f"\n== {label}\n   before {before}\n   peak RSS {peak_rss} MB\n"
                      f"   after  {after}\n   daemon CPU {cpu:.0%} of a core\n"
                      f"   other client: {_watched(watched)} (baseline: tf p99 "
                      f"{baseline['tf_p99_ms']:.1f} ms, hello max "
                      f"{baseline['hello_max_ms']:.1f} ms)\n   {json.dumps(outcome)}",
                      flush=True)
        if subscriber is not None:
            if args.flood_remove:
                before = {**settled(pid), **graph.entities()}
                subscriber.command("remove_subscriber", {"topic": FLOOD_TOPIC})
                after = {**settled(pid), **graph.entities()}
                print(f"\n== flood subscriber removed\n   before {before}\n   after  {after}")
            subscriber.close()
            subscriber = None
        ok = all(r["served_s"] is not None for r in results)
        for r in results:
            b, a = r["before"], r["after"]
            if not r["attack"].startswith("flood") and r["attack"] not in STORMS:
                ok = ok and a["fds"] <= b["fds"] and all(
                    a[k] <= b[k] for k in ("publishers", "subscribers", "services", "clients"))
        print("\n| attack | RSS MB before | peak | after | fds before/after | threads "
              "before/after | entities (pub/sub/srv/cli) before -> after | fresh client "
              "served in |")
        print("|---|---|---|---|---|---|---|---|")
        for r in results:
            b, a = r["before"], r["after"]
            ent = "/".join(str(b[k]) for k in ("publishers", "subscribers", "services",
                                              "clients"))
            ent_after = "/".join(str(a[k]) for k in ("publishers", "subscribers", "services",
                                                    "clients"))
            served = "no" if r["served_s"] is None else f"{r['served_s']:.2f} s"
            print(f"| {r['attack']} | {b['rss_mb']} | {r['peak_rss_mb']} | {a['rss_mb']} | "
                  f"{b['fds']}/{a['fds']} | {b['threads']}/{a['threads']} | {ent} -> "
                  f"{ent_after} | {served} |")
        print(f"\nthe other client while each attack runs (targets: tf p99 < 20 ms, every "
              f"hello within 100 ms); baseline in the same run: {_watched(baseline)}")
        print("\n| attack | tf p50 / p99 / max (ms) | rclpy floor p99 / max (ms) | "
              "hello p99 / max (ms) | daemon CPU | load | targets |")
        print("|---|---|---|---|---|---|---|")
        for r in [{"attack": "baseline (no attack)", "watched": baseline,
                   "daemon_cpu": None, "load": baseline_load}, *results]:
            w = r["watched"]
            cpu = "" if r["daemon_cpu"] is None else f"{r['daemon_cpu']:.0%}"
            print(f"| {r['attack']} | {w['tf_p50_ms'] or 0:.1f} / {w['tf_p99_ms'] or 0:.1f} / "
                  f"{w['tf_max_ms'] or 0:.1f} | {w['floor_p99_ms'] or 0:.1f} / "
                  f"{w['floor_max_ms'] or 0:.1f} | {w['hello_p99_ms'] or 0:.1f} / "
                  f"{w['hello_max_ms']:.1f} | {cpu} | {r.get('load', '')} | "
                  f"{'met' if _meets_targets(w) else 'MISSED'} |")
        if args.json:
            args.json.write_text(json.dumps({"baseline": baseline, "results": results},
                                            indent=2))
        daemon.send_signal(signal.SIGINT)
        code = daemon.wait(30)
        print(f"daemon exit code {code}; {'PASS' if ok and code == 0 else 'FAIL'}")
        return 0 if ok and code == 0 else 1
    finally:
        if subscriber is not None:
            subscriber.close()
        if watcher is not None:
            watcher.close()
        if graph is not None:
            graph.close()
        if daemon.poll() is None:
            daemon.send_signal(signal.SIGINT)
            try:
                daemon.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(daemon.pid, signal.SIGKILL)
                daemon.wait()


if __name__ == "__main__":
    sys.exit(main())
