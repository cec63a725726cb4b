"""Serve std_srvs services: set_enabled (SetBool), trigger (Trigger), slow (Trigger that
sleeps), all relative to the node's namespace.

usage: service_server.py [--namespace NS] [--slow-seconds S]
Prints READY, then `CALL <service> {request}` for every call.
"""

import argparse
import json
import time

import rclpy
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from std_srvs.srv import SetBool, Trigger

from peer_teardown import end_ros


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--namespace", default="")
    parser.add_argument("--slow-seconds", type=float, default=3.0)
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("test_service_server", namespace=args.namespace or None)
    where = node.get_namespace()
    triggered = 0
    group = ReentrantCallbackGroup()  # `slow` must not hold up the others

    def set_enabled(request, response):
        print("CALL set_enabled " + json.dumps({"data": request.data}), flush=True)
        response.success = request.data
        response.message = f"{where} enabled={request.data}"
        return response

    def trigger(request, response):
        nonlocal triggered
        triggered += 1
        print("CALL trigger {}", flush=True)
        response.success = True
        response.message = f"triggered {triggered}"
        return response

    def slow(request, response):
        print("CALL slow {}", flush=True)
        time.sleep(args.slow_seconds)
        response.success = True
        response.message = "slow"
        return response

    node.create_service(SetBool, "set_enabled", set_enabled, callback_group=group)
    node.create_service(Trigger, "trigger", trigger, callback_group=group)
    node.create_service(Trigger, "slow", slow, callback_group=group)
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    print("READY", flush=True)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        end_ros(node, executor)


if __name__ == "__main__":
    main()
