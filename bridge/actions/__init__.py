"""Action bridges: clients send goals to any installed ROS action (`goals`), and serve
actions to ROS (`served`); this capability puts the two together with `list_actions`.

`send_goal` (Slicer -> ROS): the goal is built from JSON with the generic codec (as service
requests are) and sent by a cached rclpy `ActionClient`. Every call on an ActionClient runs
in the executor thread (it keeps its pending requests in plain dicts that the executor
reads); the loop hands work there with ``executor.create_task`` and gets the outcome back
with ``hub.call_soon``. The reply comes once the server accepted (or refused) the goal;
then feedback and the result go to the sending client as STRING messages (`GoalEvent` JSON)
on the goal's device. Nothing waits on a goal: the loop never blocks.

A server that disappears mid-goal never sends a result: a watchdog on the loop looks at
each action client with goals in flight, and once its server has been gone for
`lost_server_s` the goals end with status ``lost``.

`advertise_action` (ROS -> Slicer): an rclpy `ActionServer` whose execute callback is a
coroutine (the node's SingleThreadedExecutor runs it without blocking other callbacks).
It hands the goal to the loop, which sends the serving client an `action_goal` COMMAND and
waits for its RTS_COMMAND; `action_feedback` commands publish feedback meanwhile. A ROS
cancel request is accepted and passed on as an `action_cancel` COMMAND. The client's
answer (or an abort after `goal_timeout`, or when the client leaves) ends the goal.
"""

from __future__ import annotations

from typing import Any, Optional

from rclpy.action.graph import get_action_server_names_and_types_by_node
from rclpy.node import NodeNameNonExistentError

from bridge.actions.goals import GoalSender
from bridge.actions.served import ServedActions
from bridge.core.client_replies import ClientReplies
from bridge.core.content_guards import ContentGuard
from bridge.core.dispatch import Handler
from bridge.core.hub import Hub, Replier
from bridge.ros.ros_node import RosNode
from protocol.commands import (ActionFeedback, AdvertiseAction, CancelGoal, ListActions,
                               ListActionsResult, Op, SendGoal, UnadvertiseAction)
from protocol.naming import DeviceNameRegistry

__all__ = ["ActionBridges"]


class ActionBridges:
    """The action capability: goals sent (`GoalSender`), actions served (`ServedActions`)."""

    def __init__(self, ros: RosNode, hub: Hub, names: DeviceNameRegistry, *,
                 max_action_clients: int = 32, max_goals_per_client: int = 32,
                 idle_client_s: float = 60.0, lost_server_s: float = 1.0,
                 linger_s: float = 10.0, replies: Optional[ClientReplies] = None) -> None:
        self._ros = ros
        self.sender = GoalSender(ros, hub, names, max_action_clients=max_action_clients,
                                 max_goals_per_client=max_goals_per_client,
                                 idle_client_s=idle_client_s, lost_server_s=lost_server_s)
        self.servers = ServedActions(ros, hub, names, linger_s=linger_s, replies=replies)

    def list_actions(self, request: ListActions,
                     client: Optional[Replier]) -> ListActionsResult:
        """The actions some node serves: a goal can be sent to them. (The graph's action
        names also hold those that only have clients, the daemon's own after a goal that
        found no server among them.)"""
        node = self._ros.node
        served: dict[str, set[str]] = {}
        for name, namespace in set(node.get_node_names_and_namespaces()):
            try:
                found = get_action_server_names_and_types_by_node(node, name, namespace)
            except NodeNameNonExistentError:  # gone since the graph was read
                continue
            for action, types in found:
                served.setdefault(action, set()).update(types)
        return ListActionsResult(tuple({"action": action, "types": sorted(types)}
                                       for action, types in sorted(served.items())))

    def handlers(self) -> dict[type[Op], Handler]:
        return {
            ListActions: self.list_actions,
            SendGoal: self.sender.send_goal,
            CancelGoal: self.sender.cancel_goal,
            AdvertiseAction: self.servers.advertise_action,
            UnadvertiseAction: self.servers.unadvertise_action,
            ActionFeedback: self.servers.action_feedback,
        }

    def describe(self) -> list[dict[str, Any]]:
        return self.servers.describe()

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        return self.sender.state()

    def close(self) -> None:
        self.servers.close()
        self.sender.close()
