"""Serve control_msgs/action/GripperCommand on ACTION (default /gripper), as any ROS node
would: the gap moves from 0 to the goal's position in STEPS equal steps, one feedback each
PERIOD seconds, then the goal succeeds (position reached).

usage: gripper_action_server.py [--action A] [--steps N] [--period S] [--die-after K]
                                [--threads T] [--accept-delay S]
  * a goal with max_effort < 0 is rejected;
  * a cancel request is accepted; the goal ends canceled at its next step;
  * --accept-delay S: a goal is accepted S seconds after it came (a server slow to answer);
  * --threads T: goals executed at once (each sleeps in its own executor thread);
  * --die-after K: the process exits at once (os._exit, no cleanup: a crash) after sending
    its K-th feedback of any goal.
Prints READY, then `GOAL <position>`, `FEEDBACK <position>`, `CANCELED`, `DONE <position>`.
"""

import argparse
import os
import time

import rclpy
from control_msgs.action import GripperCommand
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor

from peer_teardown import end_ros


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--action", default="/gripper")
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--period", type=float, default=0.1)
    parser.add_argument("--die-after", type=int, default=0)
    parser.add_argument("--threads", type=int, default=4)
    parser.add_argument("--accept-delay", type=float, default=0.0)
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("test_gripper_action_server")
    sent = 0

    def on_goal(goal: GripperCommand.Goal) -> GoalResponse:
        if goal.command.max_effort < 0:
            print("REJECTED", flush=True)
            return GoalResponse.REJECT
        time.sleep(args.accept_delay)  # a slow server, in its own executor thread
        return GoalResponse.ACCEPT

    def on_cancel(goal_handle: object) -> CancelResponse:
        return CancelResponse.ACCEPT

    def execute(goal_handle):  # type: ignore[no-untyped-def]
        nonlocal sent
        target = goal_handle.request.command.position
        print(f"GOAL {target}", flush=True)
        feedback = GripperCommand.Feedback()
        for step in range(1, args.steps + 1):
            time.sleep(args.period)  # a gripper moving, not spinning
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                print("CANCELED", flush=True)
                result = GripperCommand.Result()
                result.position = feedback.position
                return result
            feedback.position = target * step / args.steps
            feedback.effort = goal_handle.request.command.max_effort
            goal_handle.publish_feedback(feedback)
            sent += 1
            print(f"FEEDBACK {feedback.position}", flush=True)
            if args.die_after and sent >= args.die_after:
                os._exit(3)
        goal_handle.succeed()
        result = GripperCommand.Result()
        result.position = target
        result.effort = goal_handle.request.command.max_effort
        result.reached_goal = True
        print(f"DONE {target}", flush=True)
        return result

    ActionServer(node, GripperCommand, args.action, execute_callback=execute,
                 goal_callback=on_goal, cancel_callback=on_cancel,
                 callback_group=ReentrantCallbackGroup())
    executor = MultiThreadedExecutor(num_threads=args.threads)
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
