"""Subscribe raw to topics and write every message's bytes, as received, to a file: the
independent witness a recorded bag is checked against.

usage: raw_recorder_witness.py OUT.jsonl TOPIC=pkg/msg/Type [...] [--latched TOPIC ...]
Each line of OUT.jsonl: {"topic": ..., "data": base64 of the CDR bytes}, written at once.
Prints READY once subscribed, then COUNT <topic> <n> every 100 messages of a topic and at
the first one. SIGINT stops it.
"""

import argparse
import base64
import importlib
import json
import sys

import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from peer_teardown import spin_until_stopped


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("out")
    parser.add_argument("topics", nargs="+")
    parser.add_argument("--latched", nargs="*", default=[])
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("record_witness")
    out = open(args.out, "w", encoding="ascii")
    counts = {}

    def keep(topic, data):
        out.write(json.dumps({"topic": topic,
                              "data": base64.b64encode(data).decode("ascii")}) + "\n")
        out.flush()
        counts[topic] = counts.get(topic, 0) + 1
        if counts[topic] == 1 or counts[topic] % 100 == 0:
            print(f"COUNT {topic} {counts[topic]}", flush=True)

    for spec in args.topics:
        topic, _, type_name = spec.partition("=")
        package, _, name = type_name.split("/")
        cls = getattr(importlib.import_module(f"{package}.msg"), name)
        latched = topic in args.latched
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE if latched
                         else ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                         else DurabilityPolicy.VOLATILE)
        node.create_subscription(cls, topic, lambda data, t=topic: keep(t, data), qos,
                                 raw=True)
    print("READY", flush=True)
    spin_until_stopped(node)
    out.close()
    sys.exit(0)


if __name__ == "__main__":
    main()
