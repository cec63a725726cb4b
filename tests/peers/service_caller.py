"""Call a service once, as any ROS node would, and print the response.

usage: service_caller.py SERVICE pkg/srv/Type REQUEST_JSON [--timeout S]
Waits up to 20 s for the service, then prints `RESPONSE {...}` (or `TIMEOUT`) and exits.
"""

import argparse
import importlib
import json

import rclpy

from peer_teardown import end_ros


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("service")
    parser.add_argument("type")
    parser.add_argument("request")
    parser.add_argument("--timeout", type=float, default=20.0)
    args = parser.parse_args()
    package, _, name = args.type.split("/")
    srv = getattr(importlib.import_module(f"{package}.srv"), name)
    rclpy.init()
    node = rclpy.create_node("test_service_caller")
    try:
        client = node.create_client(srv, args.service)
        if not client.wait_for_service(timeout_sec=20.0):
            raise SystemExit(f"no service {args.service}")
        request = srv.Request()
        for key, value in json.loads(args.request).items():
            setattr(request, key, value)
        future = client.call_async(request)
        rclpy.spin_until_future_complete(node, future, timeout_sec=args.timeout)
        if not future.done():
            print("TIMEOUT", flush=True)
            return
        response = future.result()
        print("RESPONSE " + json.dumps({k: getattr(response, k)
                                        for k in response.get_fields_and_field_types()}),
              flush=True)
    finally:
        end_ros(node)


if __name__ == "__main__":
    main()
