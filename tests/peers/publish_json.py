"""Publish one message, built from JSON, at 20 Hz until stopped (or --count N times).

usage: publish_json.py TOPIC TYPE JSON [--transient-local] [--count N]
TYPE is pkg/msg/Type; JSON is an object of the message's fields (nested objects for nested
messages, lists for arrays). Prints READY, then PUBLISHED <n> after each publish.
"""

import argparse
import importlib
import json

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy


def fill(msg, fields):  # an independent, minimal JSON -> message walk
    for name, value in fields.items():
        current = getattr(msg, name)
        if isinstance(value, dict):
            fill(current, value)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            item_type = type(msg).SLOT_TYPES[list(msg.get_fields_and_field_types()).index(name)]
            module = importlib.import_module(".".join(item_type.value_type.namespaces))
            item_class = getattr(module, item_type.value_type.name)
            items = []
            for entry in value:
                item = item_class()
                fill(item, entry)
                items.append(item)
            setattr(msg, name, items)
        elif isinstance(value, list) and name == "data" and isinstance(current, bytes):
            setattr(msg, name, bytes(value))
        else:
            setattr(msg, name, value)
    return msg


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("topic")
    parser.add_argument("type")
    parser.add_argument("json")
    parser.add_argument("--transient-local", action="store_true")
    parser.add_argument("--count", type=int, default=0)
    args = parser.parse_args()
    package, _, name = args.type.split("/")
    msg_class = getattr(importlib.import_module(f"{package}.msg"), name)
    message = fill(msg_class(), json.loads(args.json))
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL if args.transient_local
                     else DurabilityPolicy.VOLATILE)
    rclpy.init()
    node = rclpy.create_node("test_json_publisher")
    publisher = node.create_publisher(msg_class, args.topic, qos)
    sent = 0

    def tick() -> None:
        nonlocal sent
        if args.count and sent >= args.count:
            return
        if hasattr(message, "header"):
            message.header.stamp = node.get_clock().now().to_msg()
        publisher.publish(message)
        sent += 1
        print(f"PUBLISHED {sent}", flush=True)

    node.create_timer(0.05, tick)
    print("READY", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass


if __name__ == "__main__":
    main()
