"""The demo arm's trajectory controller: a control_msgs/action/FollowJointTrajectory server
that moves the demo joints, as ros2_control's joint_trajectory_controller does for a real
arm (same action name shape, ``/<controller>/follow_joint_trajectory``).

A goal is checked like joint_trajectory_controller checks one (its joints must be actuated
joints of the robot, each point gives one position per joint, times from start increase),
and rejected otherwise (the reason goes to the log). An accepted goal pauses the idle motion
(`MotionHold`) and runs from the joints' current positions: positions are interpolated
linearly in time between the points, published on ``joint_states`` by the joint motion
node's own timer, with feedback (desired, actual, error) at each tick. A cancel stops the arm
where it is. After the goal the arm holds its last positions for ``hold_s`` seconds, then
blends back into the idle motion.

`TrajectoryRun` is pure (no ROS), for tests.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Sequence

from bridge.robots.demo.motion_hold import MotionHold

__all__ = ["DEFAULT_ACTION", "InvalidTrajectory", "TrajectoryRun", "create_trajectory_server"]

DEFAULT_ACTION = "/joint_trajectory_controller/follow_joint_trajectory"

log = logging.getLogger(__name__)


class InvalidTrajectory(ValueError):
    """A goal the controller refuses; says what was expected and what came."""


@dataclass(frozen=True)
class _Point:
    t: float
    positions: tuple[float, ...]


class TrajectoryRun:
    """One trajectory over `joints`, from `start` positions at time 0."""

    def __init__(self, joints: Sequence[str], points: Sequence[tuple[float, Sequence[float]]],
                 start: Mapping[str, float], actuated: Sequence[str]) -> None:
        joints = list(joints)
        if not joints:
            raise InvalidTrajectory("a trajectory with joint_names, got none")
        unknown = [j for j in joints if j not in actuated]
        if unknown:
            raise InvalidTrajectory(f"joint names of the robot ({', '.join(actuated)}), got "
                                    f"{', '.join(repr(j) for j in unknown)}")
        if len(set(joints)) != len(joints):
            raise InvalidTrajectory(f"each joint once, got {joints}")
        if not points:
            raise InvalidTrajectory("at least one trajectory point, got none")
        last = 0.0
        kept = []
        for i, (t, positions) in enumerate(points):
            if len(positions) != len(joints):
                raise InvalidTrajectory(f"point {i}: {len(joints)} positions (one per joint), "
                                        f"got {len(positions)}")
            if not t > last and not (i == 0 and t == 0.0 and len(points) == 1):
                raise InvalidTrajectory(f"point {i}: a time_from_start after {last:g} s, "
                                        f"got {t:g} s")
            last = t
            kept.append(_Point(t, tuple(float(p) for p in positions)))
        self.joints = tuple(joints)
        self._points = [_Point(0.0, tuple(float(start[j]) for j in joints)), *kept]
        self.duration = last

    def positions_at(self, elapsed: float) -> dict[str, float]:
        """Linear interpolation between the points (the last point's after the end)."""
        points = self._points
        if elapsed >= points[-1].t:
            return dict(zip(self.joints, points[-1].positions))
        for before, after in zip(points, points[1:]):
            if elapsed < after.t:
                share = (elapsed - before.t) / (after.t - before.t) if after.t > before.t \
                    else 1.0
                return {j: a + share * (b - a) for j, a, b in
                        zip(self.joints, before.positions, after.positions)}
        return dict(zip(self.joints, points[-1].positions))  # pragma: no cover

    def finished(self, elapsed: float) -> bool:
        return elapsed >= self.duration


def _seconds(duration: Any) -> float:
    return float(duration.sec) + float(duration.nanosec) * 1e-9


def create_trajectory_server(node: Any, hold: MotionHold, actuated: Sequence[str],
                             current: Any, *, action: str = DEFAULT_ACTION,
                             hold_s: float = 10.0) -> Any:
    """The FollowJointTrajectory server on `node`. `current()` gives the positions last
    published; the joint motion node calls the returned object's `advance(now)` before it
    computes a joint state and `report(now, published)` after publishing it."""
    from control_msgs.action import FollowJointTrajectory
    from rclpy.action.server import ActionServer, CancelResponse, GoalResponse
    from rclpy.task import Future
    from trajectory_msgs.msg import JointTrajectoryPoint

    class _Server:
        def __init__(self) -> None:
            self.run: Optional[TrajectoryRun] = None
            self.handle: Any = None
            self.started = 0.0
            self.done: Optional[Future] = None
            self.release_at: Optional[float] = None
            self.server = ActionServer(
                node, FollowJointTrajectory, action, execute_callback=self.execute,
                goal_callback=self.check, cancel_callback=self.cancel)

        def _plan(self, goal: Any) -> TrajectoryRun:
            trajectory = goal.trajectory
            return TrajectoryRun(list(trajectory.joint_names),
                                 [(_seconds(p.time_from_start), list(p.positions))
                                  for p in trajectory.points], current(), actuated)

        def check(self, goal: Any) -> GoalResponse:
            try:
                self._plan(goal)
            except InvalidTrajectory as error:
                print(f"trajectory rejected: expected {error}", flush=True)
                return GoalResponse.REJECT
            return GoalResponse.ACCEPT

        def cancel(self, goal_handle: Any) -> CancelResponse:
            return CancelResponse.ACCEPT

        async def execute(self, goal_handle: Any) -> Any:
            result = FollowJointTrajectory.Result()
            # A new goal preempts the running one.
            if self.done is not None and not self.done.done():
                self.done.set_result(False)
            run = self._plan(goal_handle.request)  # from where the arm is now
            now = node.get_clock().now().nanoseconds * 1e-9
            self.run, self.handle, self.started = run, goal_handle, now
            self.done = done = Future()
            self.release_at = None
            hold.hold(current())  # every joint pauses, not only the goal's
            hold.hold(run.positions_at(0.0))
            start = run.positions_at(0.0)
            print(f"trajectory started: {len(run.joints)} joints, {run.duration:g} s, from "
                  + ", ".join(f"{j}={start[j]!r}" for j in run.joints), flush=True)
            finished = await done
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                result.error_string = "canceled"
                print("trajectory canceled", flush=True)
            elif finished:
                goal_handle.succeed()
                result.error_code = FollowJointTrajectory.Result.SUCCESSFUL
                print("trajectory done", flush=True)
            else:
                goal_handle.abort()
                result.error_string = "preempted by a newer goal"
            return result

        def advance(self, now: float) -> None:
            """Before a joint state: where the trajectory is at `now` (or the hold ends)."""
            run, handle = self.run, self.handle
            if run is None:
                if self.release_at is not None and now >= self.release_at and hold.holding:
                    hold.release(now)
                    self.release_at = None
                return
            if not handle.is_cancel_requested:  # a cancel stops the arm where it is
                hold.hold(run.positions_at(now - self.started))

        def report(self, now: float, published: Mapping[str, float]) -> None:
            """After a joint state: feedback, and the end of the trajectory."""
            run, handle, done = self.run, self.handle, self.done
            if run is None or done is None:
                return
            elapsed = now - self.started
            desired = run.positions_at(elapsed)
            feedback = FollowJointTrajectory.Feedback()
            feedback.header.stamp = node.get_clock().now().to_msg()
            feedback.joint_names = list(run.joints)
            feedback.desired = JointTrajectoryPoint(
                positions=[desired[j] for j in run.joints])
            feedback.actual = JointTrajectoryPoint(
                positions=[published[j] for j in run.joints])
            feedback.error = JointTrajectoryPoint(
                positions=[desired[j] - published[j] for j in run.joints])
            handle.publish_feedback(feedback)
            if handle.is_cancel_requested or run.finished(elapsed):
                self.run = None
                self.release_at = now + hold_s
                if not done.done():
                    done.set_result(True)

    return _Server()
