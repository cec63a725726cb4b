"""Daemon benchmark: ROS -> OpenIGTLink latency, throughput and CPU, each figure measured in
the same run beside its baselines, every party in its own process.

    .venv/bin/python bench/bench_daemon.py            # about 9 minutes
    .venv/bin/python bench/bench_daemon.py --quick    # about 2 minutes, shorter phases
    .venv/bin/python bench/bench_daemon.py --only pose --busy 2   # beside 2 CPU-bound processes
    .venv/bin/python bench/bench_daemon.py --only image --daemon-profile \
        bench/fastdds_reader_at_once.xml              # the daemon with a Fast DDS profile

Parties (bench/peers.py): a publisher that sleeps between messages and stamps each one
with ``time.time_ns()`` just before ``publish()``; raw OpenIGTLink readers (one process,
any number of connections; header v2 announced as 3D Slicer does) that take the arrival
time of each message's last byte; and the baselines:

* the rclpy floor: a plain rclpy subscriber (``rclpy.spin``, default executor) in its own
  process; its latency is the ROS hop alone, its CPU what one plain subscriber costs;
* the naive relay (bench/naive_relay.py): pyigtl's server + rclpy, what a Python user would
  write. pyigtl's server serves one client at a time, so it has no multi-client figures;
* for 8 and 32 clients, the pose fan-out floor (bench/fanout_relay.py): a bare subscriber
  that writes the same bytes to each client, one after another, and nothing else. What
  any relay gets with that many clients, on this machine at this load;
* for the tf phase, the fan-out floor (bench/bench_fanout_floor.py, run right after it): a
  bare EventsExecutor subscriber of the same /tf writing the same bytes to 8 clients, with
  no tf work. The daemon's figure minus it is what its tf work costs.

The user's path, in the pose phase: the same daemon with two clients as users make them,
each its own process, both connected: a subscriber node made through the CamelCase facade
(its ModifiedEvent observer reads ``GetLastMessage()``), and a Pythonic subscriber whose
callback records publish() -> callback; the daemon's CPU, beside the floor's.

Real traffic as well as steady streams: the burst rate published evenly and in bursts of
10 back to back (a driver that batches), beside the floor and the naive relay; and the
isolation phase: 32 raw clients with a facade client (slicer_client, decoding every
message in Python), then the same with one more client that stops reading for 5 s, the
32's figures side by side and what the stopped one read when it read again.

Images (VGA rgb8 at 30 Hz) twice: from a publisher with Fast DDS's defaults, and from one
whose shared-memory segment holds a whole frame (bench/fastdds_image_publisher.xml). With
the defaults, most frames lose fragments at the publisher and wait about 10 ms for their
resend: on some machines at every reader alike, on others at each reader on its own, and
then the per-message share there also measures which reader's resend came first (README,
"Performance"); the second set-up shows the relay's own share without that.
That race's size is measured too, in the same run: two plain subscribers, the second's
receive minus the first's (the share row's floor column). With the defaults, a third daemon
runs with ``--receive-priority 10`` (its DDS receive threads under SCHED_FIFO, so it is not
the reader that waits; left out, and said so, where the system does not allow it).

Each relay runs alone while it is measured. Every pose subscriber (floor, daemon, naive
relay) keeps the last 5,000 messages (peers.POSE_DEPTH). CPU is the relay process's user +
system time (/proc/PID/stat) over the phase, as a share of one core; "per kHz" divides it by the
message rate in thousands of messages a second (so it is the cost of 1,000 msg/s).
A raw reader also reports when each message reached its socket (the kernel's receive
time, SO_TIMESTAMPNS): the table gives that p99 beside the multi-client rows ("in the
sockets"), the relay's latency before the readers' own scheduling adds to it.
Latency figures depend on the machine's load, CPU time much less: the load average is
printed with every phase. The table at the end is the one in README.md ("Performance").
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bridge.platform import receive_priority  # noqa: E402
from peers import POSE_DEPTH  # noqa: E402

PEERS = REPO / "bench" / "peers.py"
POSE_TOPIC = "/bench_pose"
IMAGE_TOPIC = "/bench_image"
# The image phase's publisher set-ups: Fast DDS as it comes, and with a shared-memory
# segment that holds a whole VGA frame (bench/fastdds_image_publisher.xml).
IMAGE_PUBLISHERS: dict[str, Optional[Path]] = {
    "Fast DDS defaults": None,
    "an 8 MB shared-memory segment": REPO / "bench" / "fastdds_image_publisher.xml"}
# The image phase's daemon whose DDS receive threads run under SCHED_FIFO.
RT_KIND = "bridge, --receive-priority"
RECEIVE_PRIORITY = 10
LINKS = 7
CLK_TCK = os.sysconf("SC_CLK_TCK")


# ------------------------------------------------------------------------------ processes


class Child:
    """A child process speaking the peers' line protocol (READY, commands on stdin)."""

    def __init__(self, name: str, argv: list[str], ready: str = "READY",
                 env: Optional[dict[str, str]] = None) -> None:
        self.name = name
        self.popen = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True, cwd=REPO,
                                      start_new_session=True, bufsize=1,
                                      env=None if env is None else {**os.environ, **env})
        self.expect(ready, 60)

    def expect(self, word: str, timeout: float = 120) -> str:
        assert self.popen.stdout is not None
        deadline = time.monotonic() + timeout
        seen = []
        while time.monotonic() < deadline:
            line = self.popen.stdout.readline()
            if not line:
                raise SystemExit(f"{self.name} exited before {word!r}: {''.join(seen)[-2000:]}")
            if word in line:
                return line.strip()
            seen.append(line)
        raise SystemExit(f"{self.name}: no {word!r} within {timeout} s")

    def say(self, line: str) -> None:
        assert self.popen.stdin is not None
        self.popen.stdin.write(line + "\n")
        self.popen.stdin.flush()

    def ask(self, line: str, answer: str, timeout: float = 120) -> str:
        self.say(line)
        return self.expect(answer, timeout)

    def report(self) -> dict[str, Any]:
        self.say("REPORT")
        assert self.popen.stdout is not None
        while True:
            line = self.popen.stdout.readline()
            if not line:
                raise SystemExit(f"{self.name} exited before its report")
            if line.startswith("{"):
                return json.loads(line)  # type: ignore[no-any-return]

    def cpu_seconds(self) -> float:
        fields = Path(f"/proc/{self.popen.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / CLK_TCK

    def rss_mib(self) -> float:
        for line in Path(f"/proc/{self.popen.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
        return float("nan")

    def stop(self) -> None:
        if self.popen.poll() is None:
            try:
                self.say("QUIT")
            except (BrokenPipeError, OSError):
                pass
            try:
                self.popen.wait(3)
            except subprocess.TimeoutExpired:
                self.popen.terminate()
                try:
                    self.popen.wait(10)
                except subprocess.TimeoutExpired:
                    self.popen.kill()
                    self.popen.wait()


def peer(name: str, *args: str, env: Optional[dict[str, str]] = None) -> Child:
    return Child(name, [sys.executable, str(PEERS), *args], env=env)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def load() -> str:
    return f"{os.getloadavg()[0]:.2f}"


class Relay:
    """The daemon or the naive relay: a process listening on a port."""

    def __init__(self, kind: str, topics: dict[str, str],
                 daemon_profile: Optional[Path] = None, daemon_args: tuple[str, ...] = ()) -> None:
        self.kind = kind
        self.port = free_port()
        self.tail: deque[str] = deque(maxlen=50)  # its last lines of output
        if kind == "bridge":
            env = (None if daemon_profile is None
                   else {"FASTRTPS_DEFAULT_PROFILES_FILE": str(daemon_profile)})
            self.child = Child("daemon", [sys.executable, "-m", "bridge.cli", "run", "--port",
                                          str(self.port), "--log-level", "INFO", *daemon_args],
                               "listening on", env=env)
            threading.Thread(target=self._drain_output, daemon=True).start()
            from slicer_client.connection import Connection

            self.devices = {}
            with Connection("127.0.0.1", self.port) as setup:
                for name, topic in topics.items():
                    ros_type = {"pose": "PoseStamped", "image": "Image"}[name]
                    self.devices[name] = setup.command("create_subscriber", {
                        "topic": topic, "type": ros_type,
                        "qos": {"depth": POSE_DEPTH if name == "pose" else 10}})["device"]
                    # The readers connect later: kept, as an operator's bridge would be.
                    setup.command("keep_bridge", {"kind": "subscriber", "topic": topic})
        elif kind == "fanout":
            self.child = Child("fan-out floor", [sys.executable, str(REPO / "bench" /
                                                                    "fanout_relay.py"),
                                                 str(self.port), topics["pose"],
                                                 str(POSE_DEPTH)])
            threading.Thread(target=self._drain_output, daemon=True).start()
            self.devices = {"pose": "bench_pose"}
        else:
            self.child = Child("naive relay", [sys.executable, str(REPO / "bench" /
                                                                    "naive_relay.py"),
                                               str(self.port), topics.get("pose", POSE_TOPIC),
                                               topics.get("image", IMAGE_TOPIC),
                                               str(POSE_DEPTH),
                                               *([topics["cloud"]] if "cloud" in topics
                                                 else [])])
            threading.Thread(target=self._drain_output, daemon=True).start()
            self.devices = {"pose": "pose", "image": "camera", "cloud": "cloud"}

    def _drain_output(self) -> None:
        assert self.child.popen.stdout is not None
        for line in self.child.popen.stdout:
            self.tail.append(line)

    def stop(self) -> None:
        self.child.popen.terminate()
        try:
            self.child.popen.wait(10)
        except subprocess.TimeoutExpired:
            self.child.popen.kill()
            self.child.popen.wait()


# ------------------------------------------------------------------------------ phases


@dataclass
class Figure:
    """One party's figures in one phase."""

    sent: int = 0
    delivered: list[int] = field(default_factory=list)  # per client (or the one subscriber)
    p50: float = float("nan")
    p99: float = float("nan")
    max: float = float("nan")
    out_of_order: int = 0
    per_second: list[float] = field(default_factory=list)  # p50 of each second (lag)
    cpu: float = float("nan")  # share of one core
    rate: float = 0.0
    load: str = ""
    extra: dict[str, float] = field(default_factory=dict)

    @property
    def all_delivered(self) -> bool:
        return bool(self.delivered) and min(self.delivered) >= self.sent

    def delivered_text(self) -> str:
        if not self.delivered:
            return "-"
        low = min(self.delivered)
        clients = f" (each of {len(self.delivered)})" if len(self.delivered) > 1 else ""
        return f"{low:,}/{self.sent:,}{clients}"

    @property
    def cpu_per_khz(self) -> float:
        return self.cpu / (self.rate / 1000.0) if self.rate else float("nan")


def run_phase(publisher: Child, readers: list[Child], rate: float, seconds: float,
              measured: Optional[Child], subscribers: int, *, warmup: bool = True,
              burst: int = 1, during: Optional[Callable[[], None]] = None,
              ) -> tuple[list[dict[str, Any]], float, str]:
    """Publish at `rate` for `seconds` (`burst` at a time) once `subscribers` ROS
    subscribers matched, calling `during` once the publishing has begun; returns the
    readers' reports, the measured process's CPU share, and the load average."""
    publisher.ask(f"WAIT {subscribers}", "MATCHED")
    if warmup:
        _warm_up(publisher, readers, rate)
    for reader in readers:
        reader.say("RESET")
    time.sleep(0.2)
    cpu0, t0 = (measured.cpu_seconds() if measured else 0.0), time.monotonic()
    publisher.say(f"RUN {rate} {seconds} {burst}")
    if during is not None:
        during()
    publisher.expect("DONE", timeout=seconds * 10 + 60)
    cpu1, t1 = (measured.cpu_seconds() if measured else 0.0), time.monotonic()
    average_load = load()
    time.sleep(max(0.5, seconds * 0.05))  # the last messages arrive
    reports = [reader.report() for reader in readers]
    return reports, (cpu1 - cpu0) / (t1 - t0), average_load


def _warm_up(publisher: Child, readers: list[Child], rate: float) -> None:
    """Publish until every reader has received messages published after a reset: the whole
    path works end to end (a publisher may see its subscriber before the subscriber has
    matched it, and then reliable delivery resends late), first allocations are done."""
    deadline = time.monotonic() + 30
    while True:
        publisher.ask(f"RUN {min(rate, 500)} 0.5", "DONE")
        for reader in readers:
            reader.say("RESET")
        publisher.ask(f"RUN {min(rate, 200)} 0.3", "DONE")
        time.sleep(0.3)
        if all(r.report()["all"]["n"] > 0 for r in readers) or time.monotonic() > deadline:
            return


def figure_from(reports: list[dict[str, Any]], sent: int, rate: float, cpu: float,
                average_load: str, device: Optional[str] = None) -> Figure:
    streams = [s for r in reports for name, s in r["streams"].items()
               if device is None or name.endswith(":" + device) or name == device]
    latencies = {"p50": [], "p99": [], "max": []}  # type: dict[str, list[float]]
    for s in streams:
        for key in latencies:
            latencies[key].append(s[key])
    fig = Figure(sent=sent, delivered=[s["n"] for s in streams], rate=rate, cpu=cpu,
                 load=average_load, out_of_order=sum(s["out_of_order"] for s in streams))
    if streams:
        # Clients see the same messages at nearly the same time: the median client's p50,
        # the worst client's p99 and max.
        fig.p50 = sorted(latencies["p50"])[len(streams) // 2]
        fig.p99 = max(latencies["p99"])
        fig.max = max(latencies["max"])
        fig.per_second = streams[0]["per_second"]
        queued = [s for s in streams if "queued_p99" in s]
        if len(queued) == len(streams):  # a raw reader's: when its socket had the bytes
            fig.extra["queued_p50"] = sorted(s["queued_p50"] for s in queued)[len(queued) // 2]
            fig.extra["queued_p99"] = max(s["queued_p99"] for s in queued)
    return fig


def readers_for(port: int, clients: int, *, v1: bool = False,
                setup: Optional[list[dict[str, Any]]] = None) -> list[Child]:
    """Reader processes, up to 16 connections each (their parsing must not be the limit)."""
    out = []
    left = clients
    first = True
    while left > 0:
        n = min(16, left)
        args = ["read", str(port), str(n)]
        if v1:
            args.append("--v1")
        if setup and first:
            args += ["--setup", json.dumps(setup)]
        out.append(peer(f"reader x{n}", *args))
        left -= n
        first = False
    return out


def stop_all(children: list[Child]) -> None:
    for child in children:
        child.stop()


@dataclass
class Results:
    pose: dict[str, Figure] = field(default_factory=dict)
    clients: dict[int, Figure] = field(default_factory=dict)
    clients_floor: dict[int, Figure] = field(default_factory=dict)  # bench/fanout_relay.py
    burst: dict[str, Figure] = field(default_factory=dict)
    bursty: dict[str, Figure] = field(default_factory=dict)  # bursts of BURST, same rate
    isolation: dict[str, Figure] = field(default_factory=dict)  # "facade", "stopped"
    # The user's path (`user_path`), relay -> its callback client's figures, steady and in
    # bursts; what the facade node saw.
    user: dict[str, Figure] = field(default_factory=dict)
    user_bursty: dict[str, Figure] = field(default_factory=dict)
    facade_seen: dict[str, int] = field(default_factory=dict)
    resumed: dict[str, float] = field(default_factory=dict)  # the stopped client's
    tf: Optional[Figure] = None
    tf_floor: float = float("nan")  # bench_fanout_floor.py's CPU share, 8 clients
    image: dict[str, dict[str, Figure]] = field(default_factory=dict)  # set-up -> relay
    rss: dict[str, float] = field(default_factory=dict)


def pose_phases(args: argparse.Namespace, results: Results) -> None:
    publisher = peer("pose publisher", "publish", "pose", POSE_TOPIC)
    try:
        # The floor: a plain rclpy subscriber.
        floor = peer("rclpy floor", "floor", "pose", POSE_TOPIC)
        try:
            reports, cpu, avg = run_phase(publisher, [floor], args.rate, args.seconds, floor, 1)
            results.pose["floor"] = figure_from(reports, int(args.rate * args.seconds),
                                                args.rate, cpu, avg)
            print_progress("floor, pose 1 client", results.pose["floor"])
            reports, cpu, avg = run_phase(publisher, [floor], args.burst_rate,
                                          args.burst_seconds, floor, 1)
            results.burst["floor"] = figure_from(reports, int(args.burst_rate *
                                                              args.burst_seconds),
                                                 args.burst_rate, cpu, avg)
            print_progress("floor, pose burst", results.burst["floor"])
            results.bursty["floor"] = bursty_run(args, publisher, [floor], floor)
            print_progress(f"floor, bursts of {BURST}", results.bursty["floor"])
        finally:
            floor.stop()
        for kind in ("bridge", "naive"):
            relay = Relay(kind, {"pose": POSE_TOPIC}, args.daemon_profile, args.daemon_arg)
            try:
                readers = readers_for(relay.port, 1, v1=kind == "naive")
                try:
                    reports, cpu, avg = run_phase(publisher, readers, args.rate, args.seconds,
                                                  relay.child, 1)
                    results.pose[kind] = figure_from(reports, int(args.rate * args.seconds),
                                                     args.rate, cpu, avg)
                    print_progress(f"{kind}, pose 1 client", results.pose[kind])
                    reports, cpu, avg = run_phase(publisher, readers, args.burst_rate,
                                                  args.burst_seconds, relay.child, 1)
                    results.burst[kind] = figure_from(
                        reports, int(args.burst_rate * args.burst_seconds), args.burst_rate,
                        cpu, avg)
                    print_progress(f"{kind}, pose burst", results.burst[kind])
                    results.bursty[kind] = bursty_run(args, publisher, readers, relay.child)
                    print_progress(f"{kind}, bursts of {BURST}", results.bursty[kind])
                finally:
                    stop_all(readers)
                user_path(args, publisher, relay, kind, results)
                if kind == "bridge":
                    many_clients(args, publisher, relay, "bridge", results.clients)
                results.rss[kind] = relay.child.rss_mib()
            finally:
                relay.stop()
        # The same clients' floor: a bare subscriber writing the same bytes to each.
        relay = Relay("fanout", {"pose": POSE_TOPIC})
        try:
            many_clients(args, publisher, relay, "fan-out floor", results.clients_floor)
        finally:
            relay.stop()
    finally:
        publisher.stop()


def user_path(args: argparse.Namespace, publisher: Child, relay: Relay, kind: str,
              results: Results) -> None:
    """The stream as users take it, each client its own process. The daemon's: a
    subscriber node made through the CamelCase facade (an observer reading each message
    it is told of) and a Pythonic subscriber's callback, both connected; the naive relay's:
    pyigtl's client in a `wait_for_message` loop (it serves one client). The relay's CPU,
    and publish -> callback."""
    facade = (peer("facade client", "facade", str(relay.port), POSE_TOPIC)
              if kind == "bridge" else None)
    caller = (peer("callback client", "callback", str(relay.port), POSE_TOPIC)
              if kind == "bridge" else
              peer("pyigtl client", "naive-callback", str(relay.port), "pose"))
    try:
        reports, cpu, avg = run_phase(publisher, [caller], args.rate, args.seconds,
                                      relay.child, 1)
        results.user[kind] = figure_from(reports, int(args.rate * args.seconds),
                                         args.rate, cpu, avg)
        print_progress(f"{kind}, user's path", results.user[kind])
        results.user_bursty[kind] = bursty_run(args, publisher, [caller], relay.child)
        print_progress(f"{kind}, user's path, bursts of {BURST}", results.user_bursty[kind])
        if facade is not None:
            facade.say("REPORT")
            seen = json.loads(facade.expect('"received"'))
            results.facade_seen = {key: int(value) for key, value in seen.items()}
    finally:
        if facade is not None:
            facade.stop()
        caller.stop()


MANY_CLIENTS = (8, 32)


def many_clients(args: argparse.Namespace, publisher: Child, relay: Relay, name: str,
                 figures: dict[int, Figure]) -> None:
    """The pose stream at `args.rate` to each of MANY_CLIENTS raw clients of `relay`."""
    for clients in MANY_CLIENTS:
        readers = readers_for(relay.port, clients)
        try:
            reports, cpu, avg = run_phase(publisher, readers, args.rate, args.seconds,
                                          relay.child, 1)
            figures[clients] = figure_from(reports, int(args.rate * args.seconds), args.rate,
                                           cpu, avg)
            print_progress(f"{name}, pose {clients} clients", figures[clients])
        finally:
            stop_all(readers)


BURST = 10  # messages back to back, as a driver that batches sends them
ISOLATION_CLIENTS = 32
STOP_S = 5.0  # how long the stopped client reads nothing


def bursty_run(args: argparse.Namespace, publisher: Child, readers: list[Child],
               measured: Child) -> Figure:
    """`args.burst_rate` messages a second, BURST at a time."""
    reports, cpu, avg = run_phase(publisher, readers, args.burst_rate, args.burst_seconds,
                                  measured, 1, burst=BURST)
    return figure_from(reports, int(args.burst_rate * args.burst_seconds), args.burst_rate,
                       cpu, avg)


def isolation_phase(args: argparse.Namespace, results: Results) -> None:
    """32 raw clients at 1 kHz with a facade client (it decodes everything in Python), then
    the same with one more client that stops reading for STOP_S and reads on: the 32's
    figures side by side, and what the stopped one read when it resumed."""
    publisher = peer("pose publisher", "publish", "pose", POSE_TOPIC)
    relay = Relay("bridge", {"pose": POSE_TOPIC}, args.daemon_profile, args.daemon_arg)
    readers = readers_for(relay.port, ISOLATION_CLIENTS)
    facade = peer("facade client", "facade", str(relay.port), POSE_TOPIC)
    seconds = STOP_S + 3.0
    try:
        # One unmeasured pass first: the two measured ones are then alike but for the
        # stopped client. A fresh daemon's first seconds at this load (32 new connections,
        # a new facade, histories filling) ran slower, and made the second look better.
        run_phase(publisher, readers, args.rate, seconds, relay.child, 1)
        reports, cpu, avg = run_phase(publisher, readers, args.rate, seconds, relay.child, 1)
        results.isolation["facade"] = figure_from(reports, int(args.rate * seconds),
                                                  args.rate, cpu, avg)
        print_progress(f"bridge, {ISOLATION_CLIENTS} + facade", results.isolation["facade"])
        stopped = readers_for(relay.port, 1)[0]
        try:
            def stop_reading() -> None:
                time.sleep(1.0)
                stopped.ask(f"PAUSE {STOP_S}", "PAUSED")

            reports, cpu, avg = run_phase(publisher, [*readers, stopped], args.rate, seconds,
                                          relay.child, 1, during=stop_reading)
            results.isolation["stopped"] = figure_from(reports[:-1], int(args.rate * seconds),
                                                       args.rate, cpu, avg)
            results.resumed = reports[-1].get("resumed", {})
            print_progress(f"bridge, {ISOLATION_CLIENTS} + facade + stopped",
                           results.isolation["stopped"])
            print(f"  {'':<34} the stopped client, reading again: {resumed_text(results)}",
                  flush=True)
        finally:
            stopped.stop()
    finally:
        facade.stop()
        stop_all(readers)
        relay.stop()
        publisher.stop()


def resumed_text(results: Results) -> str:
    r = results.resumed
    if not r:
        return "-"
    return (f"its own socket buffer held {r['held_values']:.0f} values "
            f"({r['held_bytes'] / 1024:.0f} KiB, the first {ms(r['first_age_ms'])} ms old); "
            f"{r['read_before_fresh'] - r['held_values']:.0f} more older than 100 ms came "
            f"from the relay, then the newest ({ms(r['fresh_after_ms'])} ms after resuming); "
            f"{r['stale_after_fresh']:.0f} older than 100 ms after those")


def tf_phase(args: argparse.Namespace, results: Results) -> None:
    publisher = peer("tf publisher", "publish", "tf", "/tf")
    relay = Relay("bridge", {}, args.daemon_profile, args.daemon_arg)
    # Each lookup kept: the readers, other clients than the one that makes them, get its
    # stream (a client's bridge goes to its holders only; docs/security.md).
    setup = [command for i in range(1, LINKS + 1) for command in (
        {"op": "create_tf_lookup", "arguments": {"parent": "base", "child": f"link{i}"}},
        {"op": "keep_bridge", "arguments": {"kind": "tf_lookup", "parent": "base",
                                             "child": f"link{i}"}})]
    readers = readers_for(relay.port, 8, setup=setup)
    try:
        reports, cpu, avg = run_phase(publisher, readers, args.rate, args.seconds, relay.child,
                                      1)
        fig = figure_from(reports, int(args.rate * args.seconds), args.rate, cpu, avg)
        # Every (client, link) stream counts: 8 x 7 of them.
        fig.extra["streams"] = len(fig.delivered)
        results.tf = fig
        print_progress("bridge, tf 7 links 8 clients", fig)
    finally:
        stop_all(readers)
        relay.stop()
        publisher.stop()
    results.tf_floor = fanout_floor(args.seconds)
    print(f"  {'fan-out floor, 8 clients':<34} CPU {results.tf_floor * 100:5.1f}% of a core "
          f"(bench_fanout_floor.py: the same bytes, no tf work)  (load {load()})", flush=True)


def fanout_floor(seconds: float) -> float:
    """bench_fanout_floor.py for 8 clients, in its own processes: the tf phase's baseline
    (an EventsExecutor subscriber of the same /tf writing the same bytes, no tf work)."""
    out = subprocess.run([sys.executable, str(REPO / "bench" / "bench_fanout_floor.py"),
                          "--clients", "8", "--seconds", str(seconds)],
                         capture_output=True, text=True, timeout=seconds * 20 + 120, cwd=REPO)
    found = re.search(r"\(([\d.]+)% of a core", out.stdout)
    if out.returncode != 0 or found is None:
        raise RuntimeError(f"bench_fanout_floor.py failed: {out.stdout[-500:]}{out.stderr[-2000:]}")
    return float(found.group(1)) / 100


def image_phase(args: argparse.Namespace, results: Results) -> None:
    """VGA images, once per publisher set-up (`IMAGE_PUBLISHERS`): the floor subscriber and
    the relay receive the same messages; the relay's share is, per message, the reader's
    last byte minus the floor's receive time."""
    for setup, profile in IMAGE_PUBLISHERS.items():
        env = {} if profile is None else {"FASTRTPS_DEFAULT_PROFILES_FILE": str(profile)}
        publisher = peer("image publisher", "publish", "image", IMAGE_TOPIC, env=env)
        kinds: dict[str, tuple[str, ...]] = {"bridge": (), "naive": ()}
        if profile is None:  # where the resend race is: the daemon that does not wait for it
            if receive_priority.allowed(RECEIVE_PRIORITY):
                kinds[RT_KIND] = ("--receive-priority", str(RECEIVE_PRIORITY))
            else:
                print(f"  (the daemon with --receive-priority {RECEIVE_PRIORITY} is left out: "
                      f"SCHED_FIFO needs CAP_SYS_NICE or `ulimit -r` >= {RECEIVE_PRIORITY})")
        try:
            _floor_race(args, results, setup, publisher)
            for kind, daemon_args in kinds.items():
                floor = peer("rclpy floor", "floor", "image", IMAGE_TOPIC)
                relay = Relay("naive" if kind == "naive" else "bridge",
                              {"image": IMAGE_TOPIC, "pose": POSE_TOPIC}, args.daemon_profile,
                              (*args.daemon_arg, *daemon_args))
                readers = readers_for(relay.port, 1, v1=kind == "naive")
                try:
                    reports, cpu, avg = run_phase(publisher, [*readers, floor], 30,
                                                  args.image_seconds, relay.child, 2)
                    reports, floor_report = reports[:-1], reports[-1]
                    fig = figure_from(reports, int(30 * args.image_seconds), 30, cpu, avg)
                    fig.extra.update(_image_share(reports[0], floor_report))
                    results.image.setdefault(setup, {})[kind] = fig
                    print_progress(f"{kind}, VGA image, publisher {setup}", fig)
                    print(f"{'':37}ROS hop p50 / p99 {ms(fig.extra['hop_p50'])} / "
                          f"{ms(fig.extra['hop_p99'])} ms; own share p50 / p99 "
                          f"{ms(fig.extra.get('share_p50', float('nan')))} / "
                          f"{ms(fig.extra.get('share_p99', float('nan')))} ms", flush=True)
                finally:
                    stop_all(readers)
                    relay.stop()
                    floor.stop()
        finally:
            publisher.stop()


def _floor_race(args: argparse.Namespace, results: Results, setup: str,
                publisher: Child) -> None:
    """The share's baseline: a second plain subscriber's receive minus the first's, same
    message. Fast DDS delivers a frame to each reader in its own time (a fragment the
    publisher's segment lost for one reader is resent to it alone, about 10 ms later), and
    that race is in the relay's share too."""
    first = peer("rclpy floor", "floor", "image", IMAGE_TOPIC)
    second = peer("second rclpy floor", "floor", "image", IMAGE_TOPIC)
    try:
        reports, _, _ = run_phase(publisher, [first, second], 30, args.image_seconds, None, 2)
        fig = Figure(rate=30)
        fig.extra.update(_image_share(reports[1], reports[0]))
        results.image.setdefault(setup, {})["floor"] = fig
        print(f"  {'a second plain subscriber':<34} its share over the first p50 / p99 "
              f"{ms(fig.extra.get('share_p50', float('nan')))} / "
              f"{ms(fig.extra.get('share_p99', float('nan')))} ms (publisher {setup})",
              flush=True)
    finally:
        first.stop()
        second.stop()


def _image_share(reader: dict[str, Any], floor: dict[str, Any]) -> dict[str, float]:
    """The ROS hop (the floor's latency) and, per message matched by stamp, the reader's
    last byte minus the floor's receive time: the relay's own share."""
    hop = floor["streams"].get("image", {})
    out = {"hop_p50": hop.get("p50", float("nan")), "hop_p99": hop.get("p99", float("nan"))}
    received = {stamp // 1000: arrival for stamp, arrival in hop.get("arrivals", [])}
    shares = sorted((arrival - received[stamp // 1000]) / 1e6
                    for s in reader["streams"].values() for stamp, arrival in s.get("arrivals", [])
                    if stamp // 1000 in received)
    if shares:
        out["share_p50"] = shares[len(shares) // 2]
        out["share_p99"] = shares[min(len(shares) - 1, int(0.99 * len(shares)))]
        out["matched"] = len(shares)
    return out


def print_progress(what: str, fig: Figure) -> None:
    print(f"  {what:<34} delivered {fig.delivered_text():<24} p50 {fig.p50:7.3f} ms  "
          f"p99 {fig.p99:7.3f} ms  CPU {fig.cpu * 100:5.1f}% of a core  (load {fig.load})",
          flush=True)
    if "queued_p99" in fig.extra:
        print(f"  {'':<34} in the clients' sockets: p50 {fig.extra['queued_p50']:7.3f} ms  "
              f"p99 {fig.extra['queued_p99']:7.3f} ms", flush=True)
    if len(fig.per_second) > 1:
        print(f"  {'':<34} p50 of each second (ms): "
              + " ".join(f"{v:.2f}" for v in fig.per_second), flush=True)


# ------------------------------------------------------------------------------ report


def ms(value: float) -> str:
    return "-" if value != value else (f"{value:.2f}" if value < 10 else f"{value:.0f}")


def pct(value: float) -> str:
    return "-" if value != value else f"{value * 100:.0f}%" if value >= 0.1 else \
        f"{value * 100:.1f}%"


def lag(fig: Figure) -> str:
    if not fig.per_second:
        return "-"
    return f"{ms(fig.per_second[0])} → {ms(fig.per_second[-1])}"


def latencies(fig: Figure) -> str:
    """p50 / p99, and where a raw reader measured it, the p99 to its socket (before its
    own scheduling)."""
    text = f"{ms(fig.p50)} / {ms(fig.p99)}"
    if "queued_p99" in fig.extra:
        text += f" (in the sockets: {ms(fig.extra['queued_p99'])})"
    return text


def _row(label: str, figures: tuple[Figure, ...], cell: Any) -> str:
    return f"| {label} | " + " | ".join(cell(f) if f.rate else "" for f in figures) + " |"


def table(results: Results, args: argparse.Namespace) -> str:
    rows = ["| | rclpy floor | slicer-ros2-bridge | naive pyigtl relay |", "|---|---|---|---|"]
    pose = tuple(results.pose.get(k, Figure()) for k in ("floor", "bridge", "naive"))
    rate = f"{args.rate / 1000:g} kHz"
    rows.append(_row(f"PoseStamped at {rate} → 1 client: p50 / p99 (ms)", pose,
                     lambda f: f"{ms(f.p50)} / {ms(f.p99)}"))
    rows.append(_row("… delivered", pose, Figure.delivered_text))
    rows.append(_row("… process CPU (share of one core)", pose, lambda f: pct(f.cpu)))
    if results.user:
        user = (results.pose.get("floor", Figure()), results.user.get("bridge", Figure()),
                results.user.get("naive", Figure()))
        rows.append(_row(f"PoseStamped at {rate}, the user's path (bridge: a facade "
                         f"subscriber node and a Pythonic callback, both connected; naive: "
                         f"pyigtl's client): publish() → callback p50 / p99 (ms); CPU", user,
                         lambda f: f"{ms(f.p50)} / {ms(f.p99)}; {pct(f.cpu)}"))
        user_bursty = (results.bursty.get("floor", Figure()),
                       results.user_bursty.get("bridge", Figure()),
                       results.user_bursty.get("naive", Figure()))
        rows.append(_row(f"… in bursts of {BURST} at {args.burst_rate:,.0f}/s: delivered; "
                         f"p50 / p99 (ms); CPU", user_bursty,
                         lambda f: f"{f.delivered_text()}; {ms(f.p50)} / {ms(f.p99)}; "
                                   f"{pct(f.cpu)}"))
        seen = results.facade_seen
        rows.append(f"| … the facade node: ModifiedEvents (each reads GetLastMessage()); "
                    f"GetNumberOfMessages() | | {seen.get('received', 0):,}; "
                    f"{seen.get('messages', 0):,} | |")
    for clients, fig in sorted(results.clients.items()):
        rows.append(_row(f"PoseStamped at {rate} → {clients} clients: delivered; p50 / p99 "
                         "(ms); CPU (floor: bench/fanout_relay.py, a bare subscriber writing "
                         "the same bytes to each)", (results.clients_floor.get(clients, Figure()),
                                                     fig),
                         lambda f: f"{f.delivered_text()}; {latencies(f)}; "
                                   f"{pct(f.cpu)}") + " (serves one client) |")
    burst = tuple(results.burst.get(k, Figure()) for k in ("floor", "bridge", "naive"))
    rows.append(_row(f"{args.burst_rate:,.0f} PoseStamped/s for {args.burst_seconds:g} s → "
                     "1 client: delivered", burst, Figure.delivered_text))
    rows.append(_row("… lag, p50 of the first → last second (ms)", burst, lag))
    rows.append(_row("… process CPU", burst, lambda f: pct(f.cpu)))
    bursty = tuple(results.bursty.get(k, Figure()) for k in ("floor", "bridge", "naive"))
    rows.append(_row(f"the same rate in bursts of {BURST} (every {BURST / args.burst_rate * 1000:g}"
                     f" ms) → 1 client: delivered; p50 / p99 (ms)", bursty,
                     lambda f: f"{f.delivered_text()}; {ms(f.p50)} / {ms(f.p99)}"))
    rows.append(_row("… lag, p50 of the first → last second (ms)", bursty, lag))
    rows.append(_row("… process CPU", bursty, lambda f: pct(f.cpu)))
    for key, what in (("facade", f"{ISOLATION_CLIENTS} raw clients and a facade client"),
                      ("stopped", f"… and one more client that stops reading for "
                                  f"{STOP_S:g} s")):
        fig = results.isolation.get(key)
        if fig is not None:
            rows.append(f"| PoseStamped at {rate} → {what}: the raw clients' delivered; "
                        f"p50 / p99 (ms); CPU | | {fig.delivered_text()}; {latencies(fig)}; "
                        f"{pct(fig.cpu)} | |")
    if results.resumed:
        rows.append(f"| … the stopped client, reading again | | {resumed_text(results)} | |")
    if results.tf is not None:
        tf = results.tf
        rows.append(f"| tf of a {LINKS}-link robot at {rate}, {LINKS} streamed lookups → 8 "
                    f"clients: CPU; p50 / p99 (ms) | {pct(results.tf_floor)} (fan-out floor: "
                    f"the same bytes, no tf work) | {pct(tf.cpu)}; {ms(tf.p50)} / "
                    f"{ms(tf.p99)} | |")
    nan = float("nan")
    for setup, figures in results.image.items():
        image = (figures.get("floor", Figure()), figures.get("bridge", Figure()),
                 figures.get("naive", Figure()))
        hop = image[1].extra
        rows.append(f"| 640×480 rgb8 Image at 30 Hz, publisher with {setup}: ROS hop "
                    f"(publish() → plain subscriber), p50 / p99 (ms) | "
                    f"{ms(hop.get('hop_p50', nan))} / {ms(hop.get('hop_p99', nan))} | | |")
        rows.append(_row("… publish() → last byte at the client: p50 / p99 (ms)",
                         (Figure(), *image[1:]), lambda f: f"{ms(f.p50)} / {ms(f.p99)}"))
        rows.append(_row("… the relay's own share (its client's last byte minus the plain "
                         "subscriber's receive, same message; floor: a second plain "
                         "subscriber's receive minus the first's): p50 / p99 (ms)", image,
                         lambda f: f"{ms(f.extra.get('share_p50', nan))} / "
                                   f"{ms(f.extra.get('share_p99', nan))}"))
        rt = figures.get(RT_KIND)
        if rt is not None:
            rows.append(f"| … the daemon with --receive-priority {RECEIVE_PRIORITY} (its DDS "
                        f"receive threads under SCHED_FIFO): publish() → last byte; its own "
                        f"share: p50 / p99 (ms) | | {ms(rt.p50)} / {ms(rt.p99)}; "
                        f"{ms(rt.extra.get('share_p50', nan))} / "
                        f"{ms(rt.extra.get('share_p99', nan))} | |")
    if results.rss:
        rows.append(f"| relay process memory (RSS, MiB) | | {results.rss.get('bridge', 0):.0f} | "
                    f"{results.rss.get('naive', 0):.0f} |")
    return "\n".join(rows)


def per_khz(results: Results) -> str:
    lines = ["CPU per 1,000 msg/s (share of one core per kHz of messages in):"]
    for name, fig in (("floor", results.pose.get("floor")),
                      ("bridge, 1 client", results.pose.get("bridge")),
                      ("naive, 1 client", results.pose.get("naive")),
                      ("bridge, the user's path", results.user.get("bridge")),
                      ("naive, the user's path", results.user.get("naive")),
                      *((f"bridge, {c} clients", f) for c, f in sorted(results.clients.items())),
                      ("bridge, burst", results.burst.get("bridge")),
                      ("naive, burst", results.burst.get("naive")),
                      (f"bridge, bursts of {BURST}", results.bursty.get("bridge")),
                      (f"naive, bursts of {BURST}", results.bursty.get("naive")),
                      ("bridge, tf (per TFMessage)", results.tf)):
        if fig is not None:
            lines.append(f"  {name:<28} {pct(fig.cpu_per_khz):>7}   (load {fig.load})")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="shorter phases (~1 minute)")
    parser.add_argument("--rate", type=float, default=1000.0, help="pose and tf rate (Hz)")
    parser.add_argument("--burst-rate", type=float, default=10_000.0,
                        help="the sustained-throughput phase's rate (msg/s)")
    parser.add_argument("--only", choices=("pose", "isolation", "tf", "image"),
                        action="append",
                        help="run only these phases (repeatable)")
    parser.add_argument("--busy", type=int, default=0, metavar="N",
                        help="keep N CPU-bound processes running beside the bench, as a "
                             "workstation that renders or compiles (a busy machine)")
    parser.add_argument("--daemon-profile", type=Path, metavar="XML",
                        help="a Fast DDS profiles file that the daemon alone loads "
                             "(FASTRTPS_DEFAULT_PROFILES_FILE), such as "
                             "bench/fastdds_reader_at_once.xml; the baselines keep the defaults")
    parser.add_argument("--daemon-arg", action="append", default=[], metavar="ARG",
                        help="an option for the daemon alone (repeatable), such as "
                             "--daemon-arg=--send-batch=off: a fast path turned off, to "
                             "weigh it (bridge/platform/README.md)")
    args = parser.parse_args()
    args.daemon_arg = tuple(args.daemon_arg)
    if args.daemon_profile is not None and not args.daemon_profile.is_file():
        parser.error(f"--daemon-profile: expected a Fast DDS profiles file, got "
                     f"{args.daemon_profile} (no such file)")
    if args.busy < 0:
        parser.error(f"--busy: expected 0 or more processes, got {args.busy}")
    args.daemon_profile = args.daemon_profile and args.daemon_profile.resolve()
    args.seconds = 2.0 if args.quick else 5.0
    args.burst_seconds = 3.0 if args.quick else 10.0
    args.image_seconds = 5.0 if args.quick else 20.0  # 30 a second: p99 of 600 frames
    os.environ["ROS_DOMAIN_ID"] = str(random.randint(101, 200))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="bench-roslog-"))
    phases = args.only or ["pose", "isolation", "tf", "image"]
    print(f"{os.cpu_count()} CPUs, load {load()} at the start; "
          f"{'quick' if args.quick else 'full'} run"
          + (f"; the daemon loads {args.daemon_profile}" if args.daemon_profile else "")
          + (f"; the daemon runs with {' '.join(args.daemon_arg)}" if args.daemon_arg else "")
          + (f"; {args.busy} CPU-bound processes beside it" if args.busy else ""),
          flush=True)
    results = Results()
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(args.busy)]
    try:
        if "pose" in phases:
            pose_phases(args, results)
        if "isolation" in phases:
            isolation_phase(args, results)
        if "tf" in phases:
            tf_phase(args, results)
        if "image" in phases:
            image_phase(args, results)
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    print()
    print(table(results, args))
    print()
    print(per_khz(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
