"""Subscribe to a topic and print every message as one JSON line, prefixed `MSG `.

usage: echo_subscriber.py TOPIC TYPE [--transient-local] [--count N]
TYPE is pkg/msg/Type. Exits after N messages (default: runs until stopped).
"""

import argparse
import array
import importlib
import json

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from peer_teardown import end_ros


def to_plain(value):  # an independent, minimal message -> JSON walk
    if hasattr(value, "get_fields_and_field_types"):
        return {name: to_plain(getattr(value, name)) for name in value.get_fields_and_field_types()}
    if isinstance(value, (list, tuple, array.array)):
        return [to_plain(v) for v in value]
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, bytes):
        return list(value)
    return value


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("topic")
    parser.add_argument("type")
    parser.add_argument("--transient-local", action="store_true")
    parser.add_argument("--count", type=int, default=0)
    args = parser.parse_args()
    package, _, name = args.type.split("/")
    msg_class = getattr(importlib.import_module(f"{package}.msg"), name)
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL if args.transient_local
                     else DurabilityPolicy.VOLATILE)
    rclpy.init()
    node = rclpy.create_node("test_echo_subscriber")
    received = 0

    def on_message(msg) -> None:
        nonlocal received
        received += 1
        print("MSG " + json.dumps(to_plain(msg)), flush=True)
        if args.count and received >= args.count:
            raise SystemExit(0)

    node.create_subscription(msg_class, args.topic, on_message, qos)
    print("READY", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except SystemExit:
        pass
    finally:
        end_ros(node)


if __name__ == "__main__":
    main()
