"""A control_msgs/action/GripperCommand server on ACTION whose goal responses are lost: it
never answers a send_goal request, as when Fast DDS drops the response to a reader it has
not matched yet. Everything else is what an action server does: the goal is accepted and
listed on the status topic (transient local), succeeds at once (reached the goal's
position), and get_result answers with the result.

Built from the action's hidden services and topics, since rclpy's ActionServer always
answers. usage: unanswering_action_server.py ACTION
Prints READY, then `GOAL <goal id hex> <position>` for each goal (not answered) and
`RESULT <goal id hex>` for each get_result answered.
"""

import argparse

import rclpy
from action_msgs.msg import GoalInfo, GoalStatus, GoalStatusArray
from action_msgs.srv import CancelGoal
from control_msgs.action import GripperCommand
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.qos import qos_profile_action_status_default
from rclpy.task import Future

from peer_teardown import spin_until_stopped

Impl = GripperCommand.Impl


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("action")
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("test_unanswering_action_server")
    hidden = f"{args.action}/_action"
    group = ReentrantCallbackGroup()
    statuses = node.create_publisher(GoalStatusArray, f"{hidden}/status",
                                     qos_profile_action_status_default)
    node.create_publisher(Impl.FeedbackMessage, f"{hidden}/feedback", 10)
    goals: dict[bytes, GoalStatus] = {}
    results: dict[bytes, GripperCommand.Result] = {}

    async def send_goal(request, response):  # type: ignore[no-untyped-def]
        goal_id = bytes(request.goal_id.uuid)
        position = request.goal.command.position
        print(f"GOAL {goal_id.hex()} {position}", flush=True)
        stamp = node.get_clock().now().to_msg()
        goals[goal_id] = GoalStatus(goal_info=GoalInfo(goal_id=request.goal_id, stamp=stamp),
                                    status=GoalStatus.STATUS_SUCCEEDED)
        results[goal_id] = GripperCommand.Result(position=position, reached_goal=True)
        statuses.publish(GoalStatusArray(status_list=list(goals.values())))
        await Future()  # never answered
        return response

    def get_result(request, response):  # type: ignore[no-untyped-def]
        goal_id = bytes(request.goal_id.uuid)
        if goal_id in results:
            response.status = GoalStatus.STATUS_SUCCEEDED
            response.result = results[goal_id]
            print(f"RESULT {goal_id.hex()}", flush=True)
        else:
            response.status = GoalStatus.STATUS_UNKNOWN
        return response

    def cancel_goal(request, response):  # type: ignore[no-untyped-def]
        response.return_code = CancelGoal.Response.ERROR_GOAL_TERMINATED
        return response

    node.create_service(Impl.SendGoalService, f"{hidden}/send_goal", send_goal,
                        callback_group=group)
    node.create_service(Impl.GetResultService, f"{hidden}/get_result", get_result,
                        callback_group=group)
    node.create_service(Impl.CancelGoalService, f"{hidden}/cancel_goal", cancel_goal,
                        callback_group=group)
    print("READY", flush=True)
    spin_until_stopped(node)


if __name__ == "__main__":
    main()
