"""Benchmark: action feedback latency, ROS action server -> client, through the daemon and
beside its baseline measured in the same run.

Run: .venv/bin/python bench/bench_actions.py [--quick]

Every party is its own process: the daemon (`bridge.cli run`), an rclpy action server
(control_msgs/action/GripperCommand; this file with ``--peer server``) that sleeps between
feedbacks and stamps each one with the wall clock just before ``publish_feedback``
(``feedback.position``, seconds; ``feedback.effort`` its index), and two readers that
each send one goal and take the arrival time of every feedback:

* the baseline, the rclpy floor: a plain rclpy ActionClient (``--peer floor``, rclpy's
  default executor): the ROS hop alone;
* the daemon's client (``--peer reader``): slicer_client's ``ros.action(...).send_goal(goal,
  feedback=cb)``; the arrival time is taken in the callback, after the STRING message was
  decoded and its JSON read.

The daemon's CPU (user + system, /proc/PID/stat) is measured over its goal and divided by
the feedback count; the floor's own CPU likewise (its getrusage).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import resource
import signal
import socket
import subprocess
import sys
import tempfile
import time
from typing import Any

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

ACTION = "/bench_gripper"
CLK_TCK = os.sysconf("SC_CLK_TCK")


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    k = min(len(ordered) - 1, max(0, int(round(q / 100 * (len(ordered) - 1)))))
    return ordered[k]


def cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


# ---------------------------------------------------------------------------- peers


def run_server(count: int, period: float) -> None:
    import rclpy
    from control_msgs.action import GripperCommand
    from rclpy.action import ActionServer
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor

    rclpy.init()
    node = rclpy.create_node("bench_action_server")

    def execute(goal_handle: Any) -> Any:
        feedback = GripperCommand.Feedback()
        for i in range(count):
            time.sleep(period)  # a server doing its work, not spinning
            feedback.effort = float(i)
            feedback.position = time.time()
            goal_handle.publish_feedback(feedback)
        goal_handle.succeed()
        return GripperCommand.Result(reached_goal=True)

    ActionServer(node, GripperCommand, ACTION, execute_callback=execute)
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    print("READY", flush=True)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()


def report(latencies: list[float], cpu: float, count: int, seen: list[int]) -> None:
    missing = sorted(set(range(count)) - set(seen))
    print("REPORT " + json.dumps({"latencies_ms": latencies, "cpu_s": cpu, "count": count,
                                  "missing": missing}), flush=True)


def run_floor(count: int) -> None:
    import rclpy
    from control_msgs.action import GripperCommand
    from rclpy.action import ActionClient

    rclpy.init()
    node = rclpy.create_node("bench_action_floor")
    client = ActionClient(node, GripperCommand, ACTION)
    if not client.wait_for_server(timeout_sec=30):
        raise SystemExit("no action server")
    latencies: list[float] = []
    seen: list[int] = []

    def on_feedback(message: Any) -> None:
        latencies.append((time.time() - message.feedback.position) * 1e3)
        seen.append(int(message.feedback.effort))

    start = cpu_s()
    sent = client.send_goal_async(GripperCommand.Goal(), feedback_callback=on_feedback)
    rclpy.spin_until_future_complete(node, sent, timeout_sec=30)
    result = sent.result().get_result_async()
    rclpy.spin_until_future_complete(node, result, timeout_sec=count * 0.1 + 30)
    report(latencies, cpu_s() - start, count, seen)
    rclpy.try_shutdown()


def run_reader(port: int, count: int) -> None:
    import slicer_client

    ros = slicer_client.connect("127.0.0.1", port, reconnect=False)
    latencies: list[float] = []
    seen: list[int] = []

    def on_feedback(fields: dict[str, Any]) -> None:
        latencies.append((time.time() - fields["position"]) * 1e3)
        seen.append(int(fields["effort"]))

    start = cpu_s()
    handle = ros.action(ACTION, "control_msgs/action/GripperCommand").send_goal(
        {}, feedback=on_feedback, timeout=30)
    handle.result(timeout=count * 0.1 + 30)
    report(latencies, cpu_s() - start, count, seen)
    ros.close()


# ---------------------------------------------------------------------------- main


def start(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-u", os.path.abspath(__file__), *args],
                            stdout=subprocess.PIPE, text=True, cwd=REPO)


def wait_line(proc: subprocess.Popen[str], prefix: str) -> str:
    assert proc.stdout is not None
    for line in proc.stdout:
        if line.startswith(prefix):
            return line
    raise RuntimeError(f"the peer ended before printing {prefix!r}")


def daemon_cpu(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer feedbacks (a smoke run)")
    parser.add_argument("--peer", choices=("server", "floor", "reader"))
    parser.add_argument("--count", type=int, default=2000)
    parser.add_argument("--period", type=float, default=0.005)
    parser.add_argument("--port", type=int, default=0)
    args = parser.parse_args()
    if args.quick:
        args.count = 500
    if args.peer == "server":
        run_server(args.count, args.period)
        return 0
    if args.peer == "floor":
        run_floor(args.count)
        return 0
    if args.peer == "reader":
        run_reader(args.port, args.count)
        return 0

    os.environ["ROS_DOMAIN_ID"] = str(random.randint(1, 100))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ["ROS_LOG_DIR"] = tempfile.mkdtemp(prefix="bench-actions-roslog-")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    common = ["--count", str(args.count), "--period", str(args.period)]
    daemon = subprocess.Popen([sys.executable, "-m", "bridge.cli", "run", "--port", str(port),
                               "--log-level", "WARNING"], cwd=REPO)
    server = start("--peer", "server", *common)
    children = [server]
    try:
        wait_line(server, "READY")
        floor = start("--peer", "floor", *common)
        children.append(floor)
        floor_report = json.loads(wait_line(floor, "REPORT ")[7:])
        floor.wait(timeout=30)
        deadline = time.monotonic() + 30
        while True:  # the daemon listening
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        before = daemon_cpu(daemon.pid)
        reader = start("--peer", "reader", "--port", str(port), *common)
        children.append(reader)
        reader_report = json.loads(wait_line(reader, "REPORT ")[7:])
        spent = daemon_cpu(daemon.pid) - before
        reader.wait(timeout=30)
        load = os.getloadavg()[0]
    finally:
        for child in children:
            if child.poll() is None:
                child.send_signal(signal.SIGINT)
        for child in children:
            try:
                child.wait(timeout=10)
            except subprocess.TimeoutExpired:
                child.kill()
        daemon.send_signal(signal.SIGINT)
        try:
            daemon.wait(timeout=10)
        except subprocess.TimeoutExpired:
            daemon.kill()

    def row(name: str, rep: dict[str, Any], cpu_ms: float) -> str:
        values = rep["latencies_ms"]
        return (f"| {name:<44} | {len(values):>5}/{rep['count']:<5} | "
                f"{percentile(values, 50):>6.2f} | {percentile(values, 99):>6.2f} | "
                f"{max(values):>7.2f} | {cpu_ms:>9.3f} |")

    n = args.count
    print(f"\naction feedback latency: rclpy ActionServer publish_feedback -> reader; {n} "
          f"feedbacks, one every {args.period * 1e3:g} ms (server sleeps); load {load:.2f}\n")
    print(f"| {'reader':<44} | {'received':>11} | {'p50 ms':>6} | {'p99 ms':>6} | "
          f"{'max ms':>7} | {'CPU ms/fb':>9} |")
    print(f"|{'-' * 46}|{'-' * 13}|{'-' * 8}|{'-' * 8}|{'-' * 9}|{'-' * 11}|")
    print(row("baseline: plain rclpy ActionClient (floor)", floor_report,
              floor_report["cpu_s"] * 1e3 / n))
    print(row("through the daemon (slicer_client callback)", reader_report,
              reader_report["cpu_s"] * 1e3 / n))
    print(f"\ndaemon CPU over its goal: {spent:.2f} s = {spent * 1e3 / n:.3f} ms per feedback "
          f"(/proc, {1 / CLK_TCK * 1e3:g} ms ticks); the CPU column above is each reader "
          f"process's own")
    added = percentile(reader_report["latencies_ms"], 50) - \
        percentile(floor_report["latencies_ms"], 50)
    print(f"the daemon adds {added:.2f} ms at p50 over the rclpy floor")
    for name, rep in (("floor", floor_report), ("daemon", reader_report)):
        if rep["missing"]:
            print(f"{name}: feedbacks not received: {rep['missing'][:20]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
