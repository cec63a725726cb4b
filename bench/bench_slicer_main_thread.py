"""What a pose stream costs 3D Slicer's main thread, in a real Slicer scene.

    .venv/bin/python bench/bench_slicer_main_thread.py [--rate 1000] [--seconds 10]

What runs, each its own process: `slicer-ros2-bridge demo` (its robot moving) in a ROS
domain of its own; a PoseStamped publisher that sleeps between messages (bench/peers.py);
3D Slicer's core (slicer-core with Slicer's own OpenIGTLinkIF connector: the peer of
tools/slicer_core/peer.py) running bench/slicer_scenes/main_thread.py. Two passes in the
same run:
  module    - the ROS2Bridge module connected, the demo robot loaded, and a subscriber
              made as a Slicer user makes it (the reference's CreateAndAddSubscriberNode),
              its observer reading each message;
  connector - a plain OpenIGTLinkIF connector given the same stream: what Slicer itself
              costs (the floor of any Slicer-side client);
  naive     - the same plain connector fed by the naive relay (pyigtl's server + rclpy,
              bench/naive_relay.py) instead of the daemon;
and the rclpy floor: a plain rclpy subscriber of the same stream, its CPU share.
Figures: the share of wall time Slicer's main thread spends in its event loop's work (the
connector's 5 ms timer, the module's timers and spin, observers), its CPU share, messages.
On a 2-core machine one pass moves by a point from run to run (the connector's floor as
much as the module): the module and connector passes alternate `--repeat` times and the
table gives each one's median beside every pass.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
import statistics
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bench_daemon import Child, free_port, load  # noqa: E402
from slicer_client.connection import Connection  # noqa: E402
from tools.slicer_core.demo import peer_or_exit, ros_env, start_demo  # noqa: E402

SCENE = REPO / "bench" / "slicer_scenes" / "main_thread.py"
RUNNER = REPO / "tools" / "slicer_core" / "run_scene.py"
PEERS = REPO / "bench" / "peers.py"
TOPIC = "/bench_slicer_pose"


def cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def slicer_pass(python: Path, mode: str, port: int, publisher: Child, rate: float,
                seconds: float, env: dict[str, str], device: str = TOPIC.lstrip("/"),
                subscribers: int = 1) -> dict[str, float]:
    args = {"mode": mode, "port": port, "topic": TOPIC, "device": device}
    scene = Child(f"slicer-{mode}", [str(python), "-u", str(RUNNER), str(SCENE),
                                     json.dumps(args)], env=dict(env, PYTHONPATH=""))
    publisher.ask(f"WAIT {subscribers}", "MATCHED")
    scene.say(f"MEASURE {seconds}")
    publisher.say(f"RUN {rate} {seconds + 2}")
    result = json.loads(scene.expect("RESULT", timeout=seconds + 120)[len("RESULT "):])
    publisher.expect("DONE", timeout=seconds + 60)
    scene.popen.wait(60)
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--repeat", type=int, default=3,
                        help="module and connector passes, alternating (the median is shown)")
    args = parser.parse_args()
    python = peer_or_exit()
    env = ros_env("bench")
    demo, port = start_demo(env)
    publisher = Child("publisher", [sys.executable, "-u", str(PEERS), "publish", "pose",
                                    TOPIC], env=env)
    # The pose subscriber every pass reads, kept for the run (a client's bridges end with
    # it: the module's would go with the module's pass).
    with Connection("127.0.0.1", port) as setup:
        setup.command("create_subscriber", {"topic": TOPIC, "type": "PoseStamped"})
        setup.command("keep_bridge", {"kind": "subscriber", "topic": TOPIC})
    rows = []
    try:
        print(f"load {load()}; {args.rate:g} Hz PoseStamped for {args.seconds:g} s, "
              f"the demo robot moving", flush=True)
        for _ in range(max(1, args.repeat)):
            for mode in ("module", "connector"):
                rows.append(slicer_pass(python, mode, port, publisher, args.rate,
                                        args.seconds, env))
        # The naive relay (pyigtl's server + rclpy) feeding the same plain connector.
        naive_port = free_port()
        naive = Child("naive", [sys.executable, "-u", str(REPO / "bench" / "naive_relay.py"),
                                str(naive_port), TOPIC, "/bench_slicer_unused_image"], env=env)
        try:
            row = slicer_pass(python, "connector", naive_port, publisher, args.rate,
                              args.seconds, env, device="pose", subscribers=2)
            rows.append(dict(row, mode="naive"))
        finally:
            naive.popen.terminate()
            naive.popen.wait(30)
        floor = Child("floor", [sys.executable, "-u", str(PEERS), "floor", "pose", TOPIC],
                      env=env)
        publisher.ask("WAIT 2", "MATCHED")  # the daemon and the floor
        cpu0 = cpu_seconds(floor.popen.pid)
        start = time.monotonic()
        publisher.say(f"RUN {args.rate} {args.seconds}")
        publisher.expect("DONE", timeout=args.seconds + 60)
        floor_share = (cpu_seconds(floor.popen.pid) - cpu0) / (time.monotonic() - start)
        floor.say("QUIT")
    finally:
        publisher.say("QUIT")
        os.killpg(demo.pid, signal.SIGINT)
        demo.wait(30)
    print(f"{'Slicer side (median of its passes)':<38}{'main thread busy':>18}{'its CPU':>10}"
          f"{'messages':>10}  each pass's busy")
    names = {"module": "ROS2Bridge module + demo robot", "connector": "plain connector (floor)",
             "naive": "plain connector, naive pyigtl relay"}
    for mode, name in names.items():
        passes = [row for row in rows if row["mode"] == mode]
        each = " ".join(f"{100 * row['busy_share']:.1f}" for row in passes)
        print(f"{name:<38}{100 * statistics.median(r['busy_share'] for r in passes):>17.1f}%"
              f"{100 * statistics.median(r['cpu_share'] for r in passes):>9.1f}%"
              f"{int(statistics.median(r['messages'] for r in passes)):>10}  {each}")
    print(f"{'rclpy subscriber (ROS floor)':<38}{'':>18}{100 * floor_share:>9.1f}%")
    print(json.dumps({"rows": rows, "rclpy_floor_cpu_share": floor_share}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
