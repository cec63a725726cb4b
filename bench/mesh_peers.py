"""Peers of bench_slicer_stream.py, each its own process (never imported by the daemon).

    mesh_peers.py count TOPIC               a plain rclpy subscriber of shape_msgs/Mesh
    mesh_peers.py publish TOPIC LEVEL       a plain rclpy publisher of the same model

Both print READY, then obey stdin lines. The counter: ``REPORT`` prints ``{"count": n}``,
``QUIT`` exits. The publisher (the ROS floor of sending a model): ``RUN RATE COUNT``
publishes the icosphere(LEVEL) model, already serialized, COUNT times at RATE Hz (sleeping
until each is due, never spinning), then prints ``DONE <count>``.
"""

from __future__ import annotations

import json
import sys
import threading
import time


def _model_bytes(level: int) -> bytes:
    import numpy as np
    import trimesh

    from bridge.codecs.slicer_data import mesh_cdr

    sphere = trimesh.creation.icosphere(level, radius=80.0)
    return mesh_cdr(np.asarray(sphere.vertices, dtype=np.float64) / 1000.0,
                    np.asarray(sphere.faces))


def main() -> None:
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parent.parent))
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from shape_msgs.msg import Mesh

    mode, topic = sys.argv[1], sys.argv[2]
    rclpy.init()
    node = rclpy.create_node(f"bench_mesh_{mode}")
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    count = 0

    def on_message(_data: bytes) -> None:
        nonlocal count
        count += 1

    if mode == "count":
        node.create_subscription(Mesh, topic, on_message, qos, raw=True)
        threading.Thread(target=rclpy.spin, args=(node,), daemon=True).start()
        print("READY", flush=True)
        for line in sys.stdin:
            if line.startswith("REPORT"):
                print(json.dumps({"count": count}), flush=True)
            elif line.startswith("QUIT"):
                break
    else:
        data = _model_bytes(int(sys.argv[3]))
        publisher = node.create_publisher(Mesh, topic, qos)
        print("READY", flush=True)
        for line in sys.stdin:
            if line.startswith("RUN"):
                _, rate, total = line.split()
                period = 1.0 / float(rate)
                due = time.monotonic()
                for _ in range(int(total)):
                    delay = due - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                    publisher.publish(data)
                    due += period
                print(f"DONE {total}", flush=True)
            elif line.startswith("QUIT"):
                break
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
