"""Read and set another node's parameters through the standard rcl_interfaces services.

usage: param_caller.py NODE ACTION...
Each ACTION is JSON: {"get": "name"} or {"set": "name", "type": "double", "value": 1.5}
(type: bool, integer, double, string). Prints one `RESULT {...}` line per action:
{"type": <ParameterType number>, "value": ...} for a get, {"successful": ..., "reason": ...}
for a set. Exits when done.
"""

import json
import sys

import rclpy
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters

from peer_teardown import end_ros

_FIELDS = {ParameterType.PARAMETER_BOOL: "bool_value",
           ParameterType.PARAMETER_INTEGER: "integer_value",
           ParameterType.PARAMETER_DOUBLE: "double_value",
           ParameterType.PARAMETER_STRING: "string_value"}
_TYPES = {"bool": ParameterType.PARAMETER_BOOL, "integer": ParameterType.PARAMETER_INTEGER,
          "double": ParameterType.PARAMETER_DOUBLE, "string": ParameterType.PARAMETER_STRING}


def call(node, client, request):
    if not client.wait_for_service(timeout_sec=20.0):
        raise SystemExit(f"no service {client.srv_name}")
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=20.0)
    if not future.done():
        raise SystemExit(f"no response from {client.srv_name}")
    return future.result()


def main() -> None:
    target, actions = sys.argv[1], [json.loads(a) for a in sys.argv[2:]]
    rclpy.init()
    node = rclpy.create_node("test_param_caller")
    getter = node.create_client(GetParameters, f"{target}/get_parameters")
    setter = node.create_client(SetParameters, f"{target}/set_parameters")
    try:
        for action in actions:
            if "get" in action:
                reply = call(node, getter, GetParameters.Request(names=[action["get"]]))
                value = reply.values[0] if reply.values else ParameterValue()
                field = _FIELDS.get(value.type)
                print("RESULT " + json.dumps({"type": value.type,
                                              "value": getattr(value, field) if field else None}),
                      flush=True)
            else:
                kind = _TYPES[action["type"]]
                value = ParameterValue(type=kind)
                setattr(value, _FIELDS[kind], action["value"])
                reply = call(node, setter, SetParameters.Request(
                    parameters=[Parameter(name=action["set"], value=value)]))
                result = reply.results[0]
                print("RESULT " + json.dumps({"successful": result.successful,
                                              "reason": result.reason}), flush=True)
    finally:
        end_ros(node)


if __name__ == "__main__":
    main()
