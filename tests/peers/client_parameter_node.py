"""An rclpy node with one parameter of every type, for the client's parameter tests.

usage: client_parameter_node.py NODE_NAME
Parameters: flag (bool true), count (integer 42), ratio (double 2.5), label (string
"omni"), flags ([true, false]), counts ([1, 2, 3]), ratios ([0.5, 1.5]), labels (["a",
"b"]). Prints READY, then `SET name=value` (JSON value) for every accepted change.
"""

import json
import sys

import rclpy
from rcl_interfaces.msg import SetParametersResult

from peer_teardown import spin_until_stopped

PARAMETERS = {
    "flag": True, "count": 42, "ratio": 2.5, "label": "omni",
    "flags": [True, False], "counts": [1, 2, 3], "ratios": [0.5, 1.5], "labels": ["a", "b"],
}


def main() -> None:
    rclpy.init()
    node = rclpy.create_node(sys.argv[1])
    for name, value in PARAMETERS.items():
        node.declare_parameter(name, value)

    def on_set(params) -> SetParametersResult:
        for param in params:
            value = param.value
            if hasattr(value, "tolist"):
                value = value.tolist()
            print("SET " + param.name + "=" + json.dumps(list(value) if isinstance(
                value, (list, tuple)) else value), flush=True)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
    print("READY", flush=True)
    spin_until_stopped(node)


if __name__ == "__main__":
    main()
