"""A node with one parameter of every type; prints each change it accepts.

usage: param_node.py NAME [--namespace NS] [--description TEXT] [--busy-at-start SECONDS]
--busy-at-start: the node's only thread is busy that long right after READY, so that
parameter requests arriving then go unanswered until it is over (a slow node).
Prints READY once declared, then `CHANGED {"name": ..., "type": ..., "value": ...}` per
parameter changed (by anyone, through the standard parameter services).
"""

import argparse
import json
import time

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter


def plain(parameter: Parameter) -> dict:
    value = parameter.value
    if parameter.type_ == Parameter.Type.BYTE_ARRAY:
        value = [b[0] for b in value]
    elif isinstance(value, (list, tuple)) or hasattr(value, "tolist"):
        value = list(value)
    return {"name": parameter.name, "type": parameter.type_.name.lower(), "value": value}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("name")
    parser.add_argument("--namespace", default="")
    parser.add_argument("--description", default="<robot name='test'/>")
    parser.add_argument("--busy-at-start", type=float, default=0.0)
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node(args.name, namespace=args.namespace or None)
    node.declare_parameter("flag", True)
    node.declare_parameter("count", 3)
    node.declare_parameter("ratio", 3.0)
    node.declare_parameter("label", node.get_fully_qualified_name())
    node.declare_parameter("blob", [bytes([0]), bytes([7]), bytes([255])])
    node.declare_parameter("flags", [True, False])
    node.declare_parameter("counts", [1, -2, 3])
    node.declare_parameter("ratios", [0.5, -1.25])
    node.declare_parameter("labels", ["a", "b c"])
    node.declare_parameter("robot_description", args.description)

    def changed(parameters: list) -> None:
        for parameter in parameters:
            print("CHANGED " + json.dumps(plain(parameter)), flush=True)

    node.add_post_set_parameters_callback(changed)
    print("READY", flush=True)
    if args.busy_at_start > 0:
        # Not spinning at all: discovery runs in DDS's own threads, so the node is seen, but
        # no request is answered until this is over. (A timer callback could lose the race
        # against a request already queued when spinning starts.)
        time.sleep(args.busy_at_start)
        print("NOT BUSY", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
