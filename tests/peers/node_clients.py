"""Print the service clients another node has, as the ROS graph shows them.

usage: node_clients.py NODE NAMESPACE WANTED
Waits (up to 60 s) until the graph lists the client WANTED on node NAMESPACE/NODE, then
prints `CLIENTS [...]` (every client service name of that node, sorted) and exits: the graph
then reflects the node as it was when it made WANTED, and everything it made before.
"""

import json
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor

from peer_teardown import end_ros


def main() -> int:
    name, namespace, wanted = sys.argv[1], sys.argv[2], sys.argv[3]
    rclpy.init()
    node = rclpy.create_node("test_node_clients")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    print("READY", flush=True)
    deadline = time.monotonic() + 60.0
    try:
        while time.monotonic() < deadline:
            try:
                clients = sorted(service for service, _ in
                                 node.get_client_names_and_types_by_node(name, namespace))
            except rclpy.node.NodeNameNonExistentError:
                clients = []
            if wanted in clients:
                print("CLIENTS " + json.dumps(clients), flush=True)
                return 0
            executor.spin_once(timeout_sec=0.05)  # graph updates arrive meanwhile
        print(f"TIMEOUT no client {wanted} on {namespace}/{name}", flush=True)
        return 1
    finally:
        end_ros(node)


if __name__ == "__main__":
    sys.exit(main())
