"""Models from Slicer to ROS through the daemon: CPU per model, beside the ROS floor.

What runs (each its own process): the daemon (`slicer-ros2-bridge run`); a plain rclpy
subscriber of shape_msgs/Mesh that counts (bench/mesh_peers.py count); this script as the
Slicer side, sending icosphere(LEVEL) models as POLYDATA (mm) to a Mesh publisher bridge,
sleeping until each is due. Then, in the same run, the floor: a plain rclpy publisher
(mesh_peers.py publish) sending the same model, already serialized, to the same counter.

Figures: models received by the subscriber; CPU seconds per model of the daemon (decode,
mm -> m, fan triangulation, CDR, publish) and of the plain publisher (publish only).

usage: python bench/bench_slicer_stream.py [--level 6] [--rate 5] [--count 40]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

import numpy as np  # noqa: E402
import trimesh  # noqa: E402

import slicer_client  # noqa: E402
from bench_daemon import Child, free_port, load  # noqa: E402
from protocol.messages import PolyData, cells_from_array  # noqa: E402

MESH_PEERS = REPO / "bench" / "mesh_peers.py"


def _received(counter: Child) -> int:
    counter.say("REPORT")
    return int(json.loads(counter.expect("count"))["count"])


def _wait_for(counter: Child, target: int, timeout: float = 60.0) -> int:
    deadline = time.monotonic() + timeout
    got = _received(counter)
    while got < target and time.monotonic() < deadline:
        time.sleep(0.2)  # polling a counter in another process, not a timed assertion
        got = _received(counter)
    return got


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--level", type=int, default=6, help="icosphere subdivisions")
    parser.add_argument("--rate", type=float, default=5.0, help="models per second")
    parser.add_argument("--count", type=int, default=40, help="models per phase")
    args = parser.parse_args()
    sphere = trimesh.creation.icosphere(args.level, radius=80.0)
    body = PolyData(points=np.asarray(sphere.vertices, dtype=np.float32),
                    polygons=cells_from_array(np.asarray(sphere.faces)))
    port = free_port()
    daemon = Child("daemon", [sys.executable, "-u", "-m", "bridge.cli", "run", "--port",
                              str(port)], ready="listening on")
    counter = Child("counter", [sys.executable, "-u", str(MESH_PEERS), "count", "/bench_mesh"])
    children = [daemon, counter]
    try:
        with slicer_client.connect("127.0.0.1", port) as ros:
            pub = ros.publisher("/bench_mesh", "shape_msgs/msg/Mesh", frame="patient")
            # Warm up until the subscriber has matched (discovery), then measure.
            deadline = time.monotonic() + 60
            while _received(counter) == 0 and time.monotonic() < deadline:
                pub.send(body)
                time.sleep(0.2)
            start_count = _wait_for(counter, 1)
            cpu0 = daemon.cpu_seconds()
            due = time.monotonic()
            for _ in range(args.count):
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                pub.send(body)
                due += 1.0 / args.rate
            got = _wait_for(counter, start_count + args.count) - start_count
            daemon_cpu = daemon.cpu_seconds() - cpu0
        floor = Child("floor", [sys.executable, "-u", str(MESH_PEERS), "publish",
                                "/bench_mesh", str(args.level)])
        children.append(floor)
        before = _received(counter)
        floor.ask(f"RUN 2 {max(10, int(args.rate * 2))}", "DONE")  # discovery, warm-up
        before = _wait_for(counter, before + 1)
        cpu0 = floor.cpu_seconds()
        floor.ask(f"RUN {args.rate} {args.count}", "DONE")
        floor_got = _wait_for(counter, before + args.count) - before
        floor_cpu = floor.cpu_seconds() - cpu0
    finally:
        for child in children:
            child.stop()
    print(f"model icosphere({args.level}): {len(sphere.faces)} triangles, "
          f"{len(body.pack())} bytes POLYDATA; {args.count} models at {args.rate:g}/s; "
          f"load {load()}")
    print(f"  daemon (POLYDATA -> Mesh, published): {got}/{args.count} received, "
          f"{1000 * daemon_cpu / max(got, 1):.1f} ms CPU per model")
    print(f"  floor (plain rclpy publisher of the serialized Mesh): {floor_got}/{args.count} "
          f"received (after its warm-up), {1000 * floor_cpu / max(floor_got, 1):.1f} ms CPU "
          f"per model")
    return 0


if __name__ == "__main__":
    sys.exit(main())
