"""A node with one parameter of every type; prints each change it accepts.

usage: param_node.py NAME [--namespace NS] [--description TEXT] [--busy-until PATH]
                     [--lose-first-get]
--busy-until: the node's only thread is busy right after READY until PATH exists, so that
parameter requests arriving then go unanswered until it is over (a slow node). Its
robot_description is declared without a parameter event, as a real node's start-up event
reaches no one not yet matched; here it could reach a watcher a moment later, at random.
--lose-first-get: the first get_parameters request is never answered (prints LOST), as
when a request or its answer is lost while DDS is still matching the endpoints; the
later ones are answered as rclpy's own service does.
Prints READY once declared, then `CHANGED {"name": ..., "type": ..., "value": ...}` per
parameter changed (by anyone, through the standard parameter services).
"""

import argparse
import json
import time
from pathlib import Path

import rclpy
from rcl_interfaces.srv import GetParameters
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future

from peer_teardown import spin_until_stopped


def plain(parameter: Parameter) -> dict:
    value = parameter.value
    if parameter.type_ == Parameter.Type.BYTE_ARRAY:
        value = [b[0] for b in value]
    elif isinstance(value, (list, tuple)) or hasattr(value, "tolist"):
        value = list(value)
    return {"name": parameter.name, "type": parameter.type_.name.lower(), "value": value}


def lose_first_get(node: Node) -> None:
    """Replace the node's get_parameters service with one that never answers its first
    request (an async callback that awaits a future nobody completes)."""
    service_name = f"{node.get_fully_qualified_name()}/get_parameters"
    # rclpy names its own parameter services relative to the node ("name/get_parameters").
    for service in [s for s in node.services if s.srv_name.endswith("/get_parameters")]:
        node.destroy_service(service)
    asked = []

    async def get(request, response):
        asked.append(request)
        if len(asked) == 1:
            print("LOST " + json.dumps(list(request.names)), flush=True)
            await Future()
        known = [n for n in request.names if node.has_parameter(n)]
        if len(known) == len(request.names):  # rclpy answers nothing if one is unknown
            response.values = [node.get_parameter(n).get_parameter_value() for n in known]
        print("ANSWERED " + json.dumps(list(request.names)), flush=True)
        return response

    # Reentrant: the unanswered first call must not hold the later ones back.
    node.create_service(GetParameters, service_name, get,
                        callback_group=ReentrantCallbackGroup())


class _NoEvents:
    def publish(self, _event: object) -> None:
        pass


def declare_unannounced(node: Node, name: str, value: str) -> None:
    """Declare without publishing the /parameter_events message (rclpy has no option)."""
    events = node._parameter_event_publisher
    node._parameter_event_publisher = _NoEvents()
    try:
        node.declare_parameter(name, value)
    finally:
        node._parameter_event_publisher = events


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("name")
    parser.add_argument("--namespace", default="")
    parser.add_argument("--description", default="<robot name='test'/>")
    parser.add_argument("--busy-until", type=Path)
    parser.add_argument("--lose-first-get", action="store_true")
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
    if args.busy_until is None:
        node.declare_parameter("robot_description", args.description)
    else:
        declare_unannounced(node, "robot_description", args.description)

    def changed(parameters: list) -> None:
        for parameter in parameters:
            print("CHANGED " + json.dumps(plain(parameter)), flush=True)

    node.add_post_set_parameters_callback(changed)
    if args.lose_first_get:
        lose_first_get(node)
    print("READY", flush=True)
    if args.busy_until is not None:
        # Not spinning at all: discovery runs in DDS's own threads, so the node is seen, but
        # no request is answered until this is over. (A timer callback could lose the race
        # against a request already queued when spinning starts.)
        while not args.busy_until.exists():
            time.sleep(0.05)
        print("NOT BUSY", flush=True)
    spin_until_stopped(node)


if __name__ == "__main__":
    main()
