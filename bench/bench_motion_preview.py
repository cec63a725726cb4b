"""The Motion section's live preview while a target is dragged, in a real Slicer scene.

    .venv/bin/python bench/bench_motion_preview.py [--seconds 10]

What runs, each its own process: `slicer-ros2-bridge demo` (its arm moving) in a ROS domain of
its own; 3D Slicer's core (slicer-core with Slicer's own OpenIGTLinkIF connector, the peer of
tools/slicer_core/peer.py) running bench/slicer_scenes/motion_preview.py: the ROS2Bridge
module with the demo robot, a target of the flange moved every 60 Hz display frame on a
30 mm circle, Follow on. Beside it, in the same run, the baseline: a plain Python client
(slicer_client, no Slicer) solving the same kind of targets back to back with robot.ik:
the round trip a preview cannot beat. Printed: preview updates a second, each solve's time
on Slicer's main thread (p50/p99), how far the preview trailed the newest target at each
frame (p50/p99), and the client's round trip (p50/p99) and solves a second.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bench_daemon import Child, load  # noqa: E402
from tools.slicer_core.demo import peer_or_exit, ros_env, start_demo  # noqa: E402

SCENE = REPO / "bench" / "slicer_scenes" / "motion_preview.py"
RUNNER = REPO / "tools" / "slicer_core" / "run_scene.py"


def client_baseline(port: int, seconds: float) -> dict[str, float]:
    """robot.ik back to back for targets on the same circle around the flange's pose."""
    import slicer_client

    ros = slicer_client.connect("127.0.0.1", port, reconnect=False)
    try:
        robot = ros.robot("demo")
        robot.wait_until_loaded(60)
        start = robot.links["tool_flange"].matrix
        assert start is not None
        times = []
        began = time.monotonic()
        step = 0
        while time.monotonic() - began < seconds:
            angle = 2 * math.pi * step / 120
            pose = np.array(start, dtype=float)
            pose[:3, 3] += (30.0 * math.cos(angle) - 30.0, 30.0 * math.sin(angle), 0.0)
            t0 = time.perf_counter()
            robot.ik(pose, tip="tool_flange")
            times.append(1000 * (time.perf_counter() - t0))
            step += 1
        return {"solves_per_s": len(times) / (time.monotonic() - began),
                "p50": float(np.percentile(times, 50)), "p99": float(np.percentile(times, 99))}
    finally:
        ros.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    python = peer_or_exit()
    env = ros_env("bench")
    demo, port = start_demo(env)
    try:
        print(f"load {load()}; a target dragged at 60 Hz for {args.seconds:g} s", flush=True)
        scene = Child("slicer-preview", [str(python), "-u", str(RUNNER), str(SCENE),
                                         json.dumps({"port": port,
                                                     "seconds": args.seconds})],
                      env=dict(env, PYTHONPATH=""), ready="Connected")
        got = json.loads(scene.expect("RESULT", timeout=args.seconds + 300)[len("RESULT "):])
        scene.popen.wait(60)
        base = client_baseline(port, args.seconds)
    finally:
        os.killpg(demo.pid, signal.SIGINT)
        demo.wait(30)
    solve = np.array(got["solve_ms"]) if got["solve_ms"] else np.zeros(1)
    behind = np.array(got["behind_mm"])
    print(f"{'':<44}{'per s':>8}{'p50':>9}{'p99':>9}")
    print(f"{'target moved (display frames)':<44}{got['frames'] / got['seconds']:>8.1f}")
    print(f"{'preview solved again (module, Follow)':<44}"
          f"{got['solves'] / got['seconds']:>8.1f}{np.percentile(solve, 50):>7.1f}ms"
          f"{np.percentile(solve, 99):>7.1f}ms")
    print(f"{'preview behind the newest target':<44}{'':>8}"
          f"{np.percentile(behind, 50):>7.1f}mm{np.percentile(behind, 99):>7.1f}mm")
    print(f"{'baseline: robot.ik back to back (client)':<44}{base['solves_per_s']:>8.1f}"
          f"{base['p50']:>7.1f}ms{base['p99']:>7.1f}ms")
    print(json.dumps({"preview": {k: got[k] for k in ("frames", "seconds", "solves")},
                      "baseline": base}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
