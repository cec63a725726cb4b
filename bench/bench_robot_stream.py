"""Benchmark: robots through the daemon (create_robot -> meshes at a client; link streaming CPU).

Run: .venv/bin/python bench/bench_robot_stream.py [--quick]

Everything runs as separate processes, as in real use: the daemon (`bridge.console run`,
the installed command), our state publisher(s) (`bridge.robots.state_publisher`), the
demo's joint motion node (`bridge.robots.demo.joint_motion --rate HZ`) and a TCP client
(slicer_client) here.

Measured in the same run:
1. load time: from sending create_robot to the client holding the last link mesh, for the
   demo robot (11 links, 14 visuals) and the Phantom Omni (7 STL meshes, ~1.9 MB; skipped
   without ../shared). Source: the state publisher's robot_description parameter (node
   already discovered), and a file. "cold" is the first load in the daemon (meshes read and
   converted), "warm" the median of the next ones (the daemon's mesh cache hit).
2. streaming cost: daemon CPU seconds per second (utime + stime from /proc/<pid>/stat)
   while joint states are published at 100 Hz and 1 kHz and every demo link follows, with
   a client connected and receiving, for:
   - idle: the daemon with nothing to do (baseline floor);
   - tf lookups: the same 11 link transforms through plain create_tf_lookup (baseline:
     what a client would do without the robot capability);
   - robot: create_robot (link transforms streamed by the robot capability).
   The /tf rate the daemon actually received and the link poses/s the client got (a
   TRANSFORM each, or an element of the robot's TDATA) are printed beside, since a Python
   publisher may not reach 1 kHz on a loaded machine.
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Callable

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bridge.robots.demo import DEMO_PACKAGE, demo_urdf_path  # noqa: E402
from protocol.messages import Message, PolyData, TrackingData, Transform  # noqa: E402
from slicer_client.connection import Connection  # noqa: E402

OMNI = REPO.parent / "shared" / "robots" / "sensable_omni_model"
CLK_TCK = os.sysconf("SC_CLK_TCK")


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class Child:
    def __init__(self, name: str, argv: list[str], log_dir: Path) -> None:
        self.name = name
        self.log = log_dir / f"{name}.log"
        with self.log.open("wb") as out:
            self.popen = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT,
                                          stdin=subprocess.DEVNULL, cwd=str(REPO),
                                          start_new_session=True)

    def wait_for(self, needle: str, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while needle not in self.log.read_text(errors="replace"):
            if self.popen.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"{self.name} did not print {needle!r}:\n"
                                   f"{self.log.read_text(errors='replace')[-2000:]}")
            time.sleep(0.05)

    def stop(self) -> None:
        if self.popen.poll() is None:
            os.killpg(self.popen.pid, signal.SIGINT)
            try:
                self.popen.wait(10)
            except subprocess.TimeoutExpired:
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait()

    def cpu_s(self) -> float:
        fields = Path(f"/proc/{self.popen.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / CLK_TCK  # utime, stime


class Recorder:
    """Client-side receive log: when each device's last mesh / transform arrived."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.mesh_at: dict[str, float] = {}
        self.transforms = 0
        self.changed = threading.Condition(self.lock)

    def __call__(self, message: Message) -> None:
        now = time.perf_counter()
        with self.lock:
            if isinstance(message.body, PolyData):
                self.mesh_at[message.device_name] = now
                self.changed.notify_all()
            elif isinstance(message.body, Transform):
                self.transforms += 1
            elif isinstance(message.body, TrackingData):  # a robot's: one element per link
                self.transforms += len(message.body.elements)

    def wait_meshes(self, devices: set[str], since: float, timeout: float = 60.0) -> float:
        deadline = time.monotonic() + timeout
        with self.lock:
            while True:
                times = [self.mesh_at.get(d, 0.0) for d in devices]
                if all(t >= since for t in times):
                    return max(times)
                if time.monotonic() > deadline:
                    missing = sorted(d for d in devices if self.mesh_at.get(d, 0.0) < since)
                    raise RuntimeError(f"meshes not received: {missing}")
                self.changed.wait(0.5)


def wait_until(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out waiting for {what}")
        time.sleep(0.02)


def robot_state(client: Connection, name: str) -> str:
    robots = client.command("list_robots")["robots"]
    return next((r["state"] for r in robots if r["name"] == name), "absent")


def time_load(client: Connection, recorder: Recorder, arguments: dict[str, Any],
              repeats: int) -> list[float]:
    """Seconds from create_robot to the last link mesh at the client, per repeat."""
    out = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = client.command("create_robot", arguments, timeout=60)
        if result["state"] != "loaded":  # discovery of the node still running: wait
            wait_until(lambda: robot_state(client, arguments["name"]) == "loaded", 60,
                       "the robot to load")
            result = client.command("create_robot", arguments, timeout=60)
        devices = {v["device"] for v in result["visuals"]}
        last = recorder.wait_meshes(devices, start)
        out.append(last - start)
        client.command("remove_robot", {"name": arguments["name"]})
    return out


def tf_received(client: Connection) -> int:
    return int(client.command("list_bridges")["tf_buffer"]["received"].get("tf", 0))


def measure_cpu(daemon: Child, client: Connection, recorder: Recorder,
                seconds: float) -> tuple[float, float, float]:
    """(daemon CPU s/s, /tf messages/s received by the daemon, TRANSFORMs/s at the client)."""
    tf0, cpu0 = tf_received(client), daemon.cpu_s()
    with recorder.lock:
        n0 = recorder.transforms
    t0 = time.perf_counter()
    time.sleep(seconds)  # a measurement window, not synchronisation
    cpu1, elapsed = daemon.cpu_s(), time.perf_counter() - t0
    with recorder.lock:
        n1 = recorder.transforms
    tf1 = tf_received(client)
    return (cpu1 - cpu0) / elapsed, (tf1 - tf0) / elapsed, (n1 - n0) / elapsed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats, shorter windows")
    args = parser.parse_args()
    repeats = 3 if args.quick else 6
    window = 3.0 if args.quick else 6.0
    os.environ["ROS_DOMAIN_ID"] = str(random.randint(1, 100))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="bench-roslog-"))
    # An empty mesh cache folder for the daemon: "cold" reads every mesh file.
    os.environ["XDG_CACHE_HOME"] = tempfile.mkdtemp(prefix="bench-cache-")
    log_dir = Path(tempfile.mkdtemp(prefix="bench-robot-"))
    urdf, packages = demo_urdf_path()
    py = [sys.executable, "-u"]
    port = free_port()
    daemon_args = [*py, "-m", "bridge.console", "run", "--port", str(port), "--log-level",
                   "WARNING", "--package-path", f"{DEMO_PACKAGE}={packages[DEMO_PACKAGE]}"]
    have_omni = OMNI.exists()
    if have_omni:
        daemon_args += ["--package-path", f"sensable_omni_model={OMNI}"]
    children: list[Child] = []

    def start(name: str, argv: list[str], ready: str) -> Child:
        child = Child(name, argv, log_dir)
        children.append(child)
        child.wait_for(ready)
        return child

    try:
        # --log-level WARNING: nothing is printed when it listens; wait for the port instead.
        daemon = Child("daemon", daemon_args, log_dir)
        children.append(daemon)
        wait_until(lambda: _connectable(port), 60, "the daemon's port")
        start("demo-state-publisher", [*py, "-m", "bridge.robots.state_publisher", str(urdf),
                                       f"--package-path={DEMO_PACKAGE}={packages[DEMO_PACKAGE]}"],
              "ready")
        if have_omni:
            start("omni-state-publisher", [*py, "-m", "bridge.robots.state_publisher",
                                           str(OMNI / "urdf" / "omni.urdf"),
                                           f"--package-path=sensable_omni_model={OMNI}",
                                           "--namespace", "omni", "--frame-prefix", "omni/"],
                  "ready")
        recorder = Recorder()
        client = Connection("127.0.0.1", port, on_message=recorder)
        # Discover the parameter nodes first: load time, not DDS discovery, is measured.
        for node in ["/robot_state_publisher"] + (["/omni/robot_state_publisher"]
                                                   if have_omni else []):
            client.command("create_parameter_client", {"node": node}, timeout=30)
            wait_until(lambda node=node: any(b.get("node") == node and b.get("ready") for b in
                                   client.command("list_bridges")["bridges"]), 30,
                       f"{node} to be discovered")

        # 1. load times ---------------------------------------------------------------
        cases: list[tuple[str, dict[str, Any]]] = []
        if have_omni:
            cases.append(("Omni, file", {"name": "omni", "source": {
                "kind": "file", "path": str(OMNI / "urdf" / "omni.urdf")}}))
            cases.append(("Omni, parameter", {"name": "omni", "namespace": "omni",
                                              "tf_prefix": "omni/"}))
        cases.append(("demo, file", {"name": "demo", "source": {"kind": "file",
                                                                "path": str(urdf)}}))
        cases.append(("demo, parameter", {"name": "demo"}))
        load_rows = []
        for label, arguments in cases:
            times = time_load(client, recorder, arguments, repeats)
            load_rows.append((label, times[0], statistics.median(times[1:])))
        if not have_omni:
            load_rows.insert(0, ("Omni", float("nan"), float("nan")))

        # 2. streaming cost -------------------------------------------------------------
        idle = measure_cpu(daemon, client, recorder, window)
        link_names = [item["link"] for item in client.command(
            "create_robot", {"name": "demo"}, timeout=60)["links"]]
        client.command("remove_robot", {"name": "demo"})
        stream_rows = [("idle (no robot, no motion)", "-", *idle)]
        for rate in (100, 1000):
            motion = start(f"joint-motion-{rate}", [*py, "-m", "bridge.robots.demo.joint_motion",
                                                    str(urdf), "--rate", str(rate)],
                           "joint motion ready")
            # baseline: one plain tf lookup per link, no robot capability
            for link in link_names:
                client.command("create_tf_lookup", {"parent": "base_link", "child": link})
            time.sleep(1.0)  # let the stream settle before the window
            stream_rows.append((f"{len(link_names)} x create_tf_lookup", f"{rate} Hz",
                                *measure_cpu(daemon, client, recorder, window)))
            for link in link_names:
                client.command("remove_tf_lookup", {"parent": "base_link", "child": link})
            # the robot capability: meshes + the same link transforms
            client.command("create_robot", {"name": "demo"}, timeout=60)
            time.sleep(1.0)
            stream_rows.append(("create_robot demo", f"{rate} Hz",
                                *measure_cpu(daemon, client, recorder, window)))
            client.command("remove_robot", {"name": "demo"})
            motion.stop()
            children.remove(motion)
        client.close()
    finally:
        for child in reversed(children):
            child.stop()

    print(f"\nrobot load: create_robot -> last link mesh at the client "
          f"({repeats} loads each; warm = median of loads 2..{repeats})")
    print(f"{'robot, source':<20} {'cold (ms)':>10} {'warm (ms)':>10}")
    for label, cold, warm in load_rows:
        print(f"{label:<20} {cold * 1000:>10.1f} {warm * 1000:>10.1f}" if cold == cold else
              f"{label:<20} {'skipped (../shared/robots absent)':>21}")
    print(f"\nstreaming the demo's {len(link_names)} link transforms "
          f"({window:g} s windows, one client connected)")
    print(f"{'daemon doing':<28} {'joints':>8} {'CPU s/s':>8} {'/tf in/s':>9} "
          f"{'poses out/s':>16} {'CPU ms per /tf':>15}")
    for label, rate_text, cpu, tf_rate, out_rate in stream_rows:
        per = f"{cpu / tf_rate * 1000:.3f}" if tf_rate else "-"
        print(f"{label:<28} {rate_text:>8} {cpu:>8.3f} {tf_rate:>9.0f} {out_rate:>16.0f} "
              f"{per:>15}")
    print("(the /tf rate is what the state publisher reached on this machine; 'CPU ms per "
          "/tf' compares the two ways at equal load)")
    return 0


def _connectable(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


if __name__ == "__main__":
    sys.exit(main())
