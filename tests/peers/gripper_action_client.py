"""Send one control_msgs/action/GripperCommand goal, as any ROS node would, and print what
comes back.

usage: gripper_action_client.py ACTION POSITION [--effort E] [--cancel-after K]
Waits up to 20 s for the server; prints ACCEPTED or REJECTED (NO_RESPONSE if neither came
in time), `FEEDBACK <position>` for each feedback, then
`RESULT {"status": n, "position": p, "reached_goal": b}` and exits.
--cancel-after K: asks to cancel after the K-th feedback (prints CANCEL <return code>).
--feedbacks N: also reads the action's feedback topic itself (`FEEDBACK_TOPIC <position>`)
and, after the result, stays until N of those came: rclpy's ActionClient drops a goal's
feedback once its result is in, and takes a ready result before a ready feedback, so
feedback published just before the end may never reach `feedback_callback`.

Fast DDS can drop a service response when the server has not yet matched the client's reply
reader (rmw_fastrtps sends nothing and reports success); on a loaded machine that hits the
goal response. The goal then runs, so this client also watches the action's status topic:
its goal id listed there is an acceptance as good as the response. The get_result request
or its answer can be lost the same way: once the status topic shows the goal ended, a result
still missing is asked for again.
"""

import argparse
import json
import os
import time
import uuid

import rclpy
from action_msgs.msg import GoalStatus, GoalStatusArray
from control_msgs.action import GripperCommand
from rclpy.action import ActionClient
from rclpy.action.client import ClientGoalHandle
from rclpy.qos import qos_profile_action_status_default
from unique_identifier_msgs.msg import UUID

from peer_teardown import end_ros

TERMINAL = {GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_ABORTED}
TIME_SCALE = float(os.environ.get("SLICER_BRIDGE_TEST_TIME_SCALE", "3"))


def wait_for_result(node, handle: ClientGoalHandle, ended: list[float]):  # type: ignore[no-untyped-def]
    """The goal's result. The get_result request, or its answer, is lost like the goal
    response can be; once the status topic shows the goal ended, a result still missing a
    second later is asked for again (as often as needed)."""
    asked = [handle.get_result_async()]
    last_ask = time.monotonic()
    deadline = last_ask + 60.0 * TIME_SCALE
    while time.monotonic() < deadline:
        for future in asked:
            if future.done():
                return future.result()
        if ended and time.monotonic() - max(last_ask, ended[0]) > 1.0:
            print("the result did not come; asked again", flush=True)
            asked.append(handle.get_result_async())
            last_ask = time.monotonic()
        rclpy.spin_once(node, timeout_sec=0.1)
    raise SystemExit("no result")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("action")
    parser.add_argument("position", type=float)
    parser.add_argument("--effort", type=float, default=1.0)
    parser.add_argument("--cancel-after", type=int, default=0)
    parser.add_argument("--feedbacks", type=int, default=0)
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

        goal_uuid = UUID(uuid=list(uuid.uuid4().bytes))
        listed: list[bool] = []

        ended: list[float] = []  # when the status topic first showed the goal ended

        def on_status(message: GoalStatusArray) -> None:
            for status in message.status_list:
                if status.goal_info.goal_id.uuid.tolist() == goal_uuid.uuid.tolist():
                    listed.append(True)
                    if status.status in TERMINAL and not ended:
                        ended.append(time.monotonic())

        node.create_subscription(GoalStatusArray, args.action + "/_action/status", on_status,
                                 qos_profile_action_status_default)
        on_topic: list[float] = []

        def on_feedback_topic(message) -> None:  # type: ignore[no-untyped-def]
            if message.goal_id.uuid.tolist() == goal_uuid.uuid.tolist():
                on_topic.append(message.feedback.position)
                print(f"FEEDBACK_TOPIC {message.feedback.position}", flush=True)

        if args.feedbacks:  # the topic and QoS rclpy's action server publishes feedback on
            node.create_subscription(GripperCommand.Impl.FeedbackMessage,
                                     args.action + "/_action/feedback", on_feedback_topic, 10)
        sent = client.send_goal_async(goal, feedback_callback=on_feedback,
                                      goal_uuid=goal_uuid)
        deadline = time.monotonic() + 30.0 * TIME_SCALE
        while not sent.done() and not listed and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
        if sent.done():
            handle = sent.result()
        elif listed:  # accepted, its response lost: follow the goal by its id
            print("the goal response was lost; the status topic lists the goal", flush=True)
            accepted = GripperCommand.Impl.SendGoalService.Response(accepted=True)
            handle = ClientGoalHandle(client, goal_uuid, accepted)
        else:
            # Seen now and then under load (a served action, its first goal after the
            # server was revived): whether this node still sees the server and its status
            # publisher says which way the goal's answers were lost.
            publishers = node.get_publishers_info_by_topic(args.action + "/_action/status")
            print(f"seen: server ready {client.server_is_ready()}, status published by "
                  f"{sorted(p.node_namespace.rstrip('/') + '/' + p.node_name for p in publishers)}",
                  flush=True)
            print("NO_RESPONSE", flush=True)
            return
        if not handle.accepted:
            print("REJECTED", flush=True)
            return
        handle_box.append(handle)
        print("ACCEPTED", flush=True)
        cancel_if_due()
        response = wait_for_result(node, handle, ended)
        print("RESULT " + json.dumps({"status": response.status,
                                      "position": response.result.position,
                                      "reached_goal": response.result.reached_goal}),
              flush=True)
        deadline = time.monotonic() + 30.0 * TIME_SCALE
        while len(on_topic) < args.feedbacks and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
    finally:
        end_ros(node)


if __name__ == "__main__":
    main()
