"""Send one control_msgs/action/GripperCommand goal, as any ROS node would, and print what
comes back.

usage: gripper_action_client.py ACTION POSITION [--effort E] [--cancel-after K]
Waits up to 20 s for the server; prints ACCEPTED or REJECTED, `FEEDBACK <position>` for
each feedback, then `RESULT {"status": n, "position": p, "reached_goal": b}` and exits.
--cancel-after K: asks to cancel after the K-th feedback (prints CANCEL <return code>).
"""

import argparse
import json

import rclpy
from control_msgs.action import GripperCommand
from rclpy.action import ActionClient


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("action")
    parser.add_argument("position", type=float)
    parser.add_argument("--effort", type=float, default=1.0)
    parser.add_argument("--cancel-after", type=int, default=0)
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("test_gripper_action_client")
    try:
        client = ActionClient(node, GripperCommand, args.action)
        if not client.wait_for_server(timeout_sec=20.0):
            raise SystemExit(f"no action server {args.action}")
        goal = GripperCommand.Goal()
        goal.command.position = args.position
        goal.command.max_effort = args.effort
        seen = 0
        handle_box: list = []

        def cancel_if_due() -> None:
            # Feedback may come before the acceptance: cancel once both are there.
            if args.cancel_after and seen >= args.cancel_after and handle_box \
                    and len(handle_box) == 1:
                handle_box.append("cancelled")
                handle_box[0].cancel_goal_async().add_done_callback(
                    lambda f: print(f"CANCEL {f.result().return_code}", flush=True))

        def on_feedback(message) -> None:  # type: ignore[no-untyped-def]
            nonlocal seen
            seen += 1
            print(f"FEEDBACK {message.feedback.position}", flush=True)
            cancel_if_due()

        sent = client.send_goal_async(goal, feedback_callback=on_feedback)
        rclpy.spin_until_future_complete(node, sent, timeout_sec=30.0)
        handle = sent.result()
        if handle is None or not handle.accepted:
            print("REJECTED", flush=True)
            return
        handle_box.append(handle)
        print("ACCEPTED", flush=True)
        cancel_if_due()
        result = handle.get_result_async()
        rclpy.spin_until_future_complete(node, result, timeout_sec=60.0)
        response = result.result()
        print("RESULT " + json.dumps({"status": response.status,
                                      "position": response.result.position,
                                      "reached_goal": response.result.reached_goal}),
              flush=True)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
