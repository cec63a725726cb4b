"""Soak: hours-of-use load in minutes. 1 kHz tf of a 7-link robot, 8 clients, N minutes.

Run: .venv/bin/python bench/soak.py [--minutes 10] [--rate 1000] [--clients 8] [--json OUT]

Separate processes, as in real use: the daemon (`bridge.cli run`), an rclpy peer
publishing /tf with 7 transforms per message at --rate Hz (tests/hardening/peers/
tf_robot_publisher.py), and here 8 TCP clients (slicer_client.Connection), each with a
streamed lookup base -> link1..link7 (56 streams). Its own ROS_DOMAIN_ID, localhost only.

Measured:
- updates delivered per second to the clients (all together and the slowest client), and
  that the latest value always arrives: once the peer stops, every lookup of every client
  must show the peer's very last tick;
- the daemon's RSS, open file descriptors (/proc/PID/fd) and CPU, sampled every 10 s;
  RSS growth is judged from the end of warm-up (first minute, or a third of a short run)
  to the end, fds from before the clients connect to after they leave.
Exit code 1 if the latest value did not arrive, fds leaked or RSS grew by more than
--max-rss-growth-mb.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from protocol.messages import Message, Transform  # noqa: E402
from slicer_client.connection import Connection  # noqa: E402

PEER = REPO / "tests" / "hardening" / "peers" / "tf_robot_publisher.py"
LINKS = 7
STEP_MM = 0.01  # the peer moves each joint 10 um a tick


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def proc_figures(pid: int) -> dict[str, float]:
    status = Path(f"/proc/{pid}/status").read_text().splitlines()
    rss = next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmRSS:"))
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    cpu = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return {"rss": rss, "fds": len(os.listdir(f"/proc/{pid}/fd")), "cpu": cpu,
            "time": time.monotonic()}


class Child:
    def __init__(self, name: str, argv: list[str], env: dict[str, str], logs: Path) -> None:
        self.log = logs / f"{name}.log"
        with self.log.open("wb") as out:
            self.popen = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT,
                                          stdin=subprocess.DEVNULL, env=env, cwd=str(REPO),
                                          start_new_session=True)

    def wait_for(self, needle: str, timeout: float) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            text = self.log.read_text(errors="replace")
            for line in text.splitlines():
                if needle in line:
                    return line
            if self.popen.poll() is not None:
                break
            time.sleep(0.05)
        raise RuntimeError(f"{self.log.name}: no {needle!r}:\n{self.log.read_text()[-2000:]}")

    def stop(self, sig: int = signal.SIGINT) -> Optional[int]:
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait(5)
        return self.popen.returncode


class SoakClient:
    """One client: 7 lookups; counts updates and keeps the newest tick seen per link."""

    def __init__(self, port: int) -> None:
        self.lock = threading.Lock()
        self.devices: dict[str, int] = {}  # device -> link index
        self.updates = 0
        self.latest: dict[int, int] = {}
        self.connection = Connection("127.0.0.1", port, on_message=self.on_message)
        for link in range(1, LINKS + 1):
            reply = self.connection.command("create_tf_lookup", {"parent": "base",
                                                                 "child": f"link{link}"})
            self.devices[reply["device"]] = link

    def on_message(self, message: Message) -> None:
        link = self.devices.get(message.device_name)
        if link is None or not isinstance(message.body, Transform):
            return
        tick = round(float(message.body.matrix[0, 3]) / (STEP_MM * link))
        with self.lock:
            self.updates += 1
            self.latest[link] = tick


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument("--max-rss-growth-mb", type=float, default=50.0)
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args()

    logs = Path(tempfile.mkdtemp(prefix="soak-"))
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(102, 200)),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_LOG_DIR=str(logs / "roslog"),
               PYTHONUNBUFFERED="1")
    env.pop("ROS_STATIC_PEERS", None)
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
    port = free_port()
    seconds = args.minutes * 60
    daemon = Child("daemon", [sys.executable, "-u", "-m", "bridge.cli", "run", "--port",
                              str(port)], env, logs)
    peer: Optional[Child] = None
    clients: list[SoakClient] = []
    samples: list[dict[str, float]] = []
    try:
        daemon.wait_for("listening on", 60)
        pid = daemon.popen.pid
        baseline = proc_figures(pid)
        clients = [SoakClient(port) for _ in range(args.clients)]
        peer = Child("peer", [sys.executable, "-u", str(PEER), str(args.rate), "--links",
                              str(LINKS), "--seconds", str(seconds)], env, logs)
        peer.wait_for("READY", 60)
        print(f"soak: {args.minutes:g} min, {args.rate:g} Hz x {LINKS} transforms, "
              f"{args.clients} clients x {LINKS} lookups; logs in {logs}", flush=True)
        start = time.monotonic()
        warm_up = min(60.0, seconds / 3)
        warm: Optional[dict[str, float]] = None
        last_updates, last_time = 0, start
        while time.monotonic() - start < seconds:
            time.sleep(min(10.0, max(0.1, seconds - (time.monotonic() - start))))
            sample = proc_figures(pid)
            updates = sum(c.updates for c in clients)
            sample["updates_per_s"] = (updates - last_updates) / (sample["time"] - last_time)
            last_updates, last_time = updates, sample["time"]
            samples.append(sample)
            if warm is None and sample["time"] - start >= warm_up:
                warm = sample
            print(f"  t={sample['time'] - start:6.0f} s  {sample['updates_per_s']:8.0f} "
                  f"updates/s  RSS {sample['rss'] / 1e6:6.1f} MB  fds {sample['fds']:.0f}  "
                  f"CPU {100 * (sample['cpu'] - baseline['cpu']) / (sample['time'] - start):4.0f}%",
                  flush=True)
        done = peer.wait_for("DONE", 60)
        last_tick = int(done.split()[1])
        # The latest value always arrives: every lookup of every client ends on the last tick.
        deadline = time.monotonic() + 15
        def all_latest() -> bool:
            return all(c.latest.get(link) == last_tick for c in clients
                       for link in range(1, LINKS + 1))
        while not all_latest() and time.monotonic() < deadline:
            time.sleep(0.05)
        latest_ok = all_latest()
        stragglers = {i: {k: v for k, v in c.latest.items() if v != last_tick}
                      for i, c in enumerate(clients) if any(v != last_tick
                                                            for v in c.latest.values())}
        end = proc_figures(pid)
        elapsed = end["time"] - start
        for client in clients:
            client.connection.close()
        clients_gone = time.monotonic() + 10
        after = proc_figures(pid)
        while after["fds"] > baseline["fds"] and time.monotonic() < clients_gone:
            time.sleep(0.1)
            after = proc_figures(pid)
        warm = warm or samples[0]
        total_updates = sum(c.updates for c in clients)
        figures: dict[str, Any] = {
            "minutes": elapsed / 60, "rate_hz": args.rate, "clients": args.clients,
            "ticks_published": last_tick,
            "ticks_per_s_published": last_tick / elapsed,
            "updates_delivered": total_updates,
            "updates_per_s": total_updates / elapsed,
            "updates_per_s_per_lookup": total_updates / elapsed / (args.clients * LINKS),
            "slowest_client_updates_per_s": min(c.updates for c in clients) / elapsed,
            "latest_value_arrived": latest_ok, "stragglers": stragglers,
            "rss_mb_baseline": baseline["rss"] / 1e6, "rss_mb_after_warm_up": warm["rss"] / 1e6,
            "rss_mb_end": end["rss"] / 1e6,
            "rss_growth_mb_after_warm_up": (end["rss"] - warm["rss"]) / 1e6,
            "rss_mb_max": max(s["rss"] for s in samples) / 1e6,
            "fds_before": baseline["fds"], "fds_with_clients": end["fds"],
            "fds_after": after["fds"],
            "cpu_percent": 100 * (end["cpu"] - baseline["cpu"]) / elapsed,
        }
        print(json.dumps(figures, indent=2))
        if args.json:
            args.json.write_text(json.dumps(figures, indent=2))
        ok = (latest_ok and after["fds"] <= baseline["fds"]
              and figures["rss_growth_mb_after_warm_up"] <= args.max_rss_growth_mb)
        code = daemon.stop()
        print(f"daemon exit code {code}; {'PASS' if ok and code == 0 else 'FAIL'}")
        return 0 if ok and code == 0 else 1
    finally:
        for client in clients:
            client.connection.close()
        if peer is not None:
            peer.stop()
        daemon.stop()


if __name__ == "__main__":
    sys.exit(main())
