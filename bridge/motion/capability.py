"""The daemon's motion capability: inverse kinematics of the robots the daemon loaded.

    solve_ik ─► the robot's model (the robots capability's, by name: `RobotLookup`)
             ─► its pinocchio model, built once per loaded description (`MotionModel`)
             ─► the seed: the request's, else the robot's latest /joint_states
             ─► `solve_ik` in the client's heavy lane (pinocchio is C++; a solve that
                fails tries every restart, up to ~0.5 s), one solve per robot at a time

It is a read: nothing is published, the robot does not move. Units: the op's target is in
mm (Slicer's), the solver's in metres, converted by `protocol.conversions`.

This capability never imports another's handlers: the daemon hands it the robots
capability's public `loaded_model` as a plain function.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Optional

import numpy as np
import numpy.typing as npt
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from bridge.core.dispatch import Handler, Result
from bridge.core.heavy import OffLoop
from bridge.ros.ros_node import RosNode
from bridge.motion.errors import MotionError
from protocol.commands import Op, OutOfRangeError, SolveIk
from protocol.conversions import metres_to_mm, mm_to_metres

if TYPE_CHECKING:  # pinocchio and coal load with the first motion query
    from bridge.motion.collisions import CollisionWorld
    from bridge.motion.model import MotionModel
    from bridge.robots.model import RobotModel

__all__ = ["MotionBridges", "RobotLookup"]

log = logging.getLogger(__name__)

# A loaded robot's model and the topic its joint states are on, by robot name; raises the
# robots capability's CommandFailedError for a robot not there or not loaded.
RobotLookup = Callable[[str], "tuple[RobotModel, str]"]

# Any joint-state publisher's profile matches a best-effort, volatile subscriber.
_JOINT_STATES_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                               reliability=ReliabilityPolicy.BEST_EFFORT,
                               durability=DurabilityPolicy.VOLATILE)


@dataclass(eq=False)
class _Robot:
    """What motion keeps per robot: the model built for one loaded description, its
    collision world, and the latest joint positions heard on its topic."""

    name: str
    source: RobotModel
    model: MotionModel
    topic: str
    lock: threading.Lock = field(default_factory=threading.Lock)
    world: Optional[CollisionWorld] = None
    positions: dict[str, float] = field(default_factory=dict)
    subscription: Any = None


class MotionBridges:
    """solve_ik for loaded robots."""

    def __init__(self, ros: RosNode, *, robots: RobotLookup) -> None:
        self._ros = ros
        self._lookup = robots
        self._robots: dict[str, _Robot] = {}
        self._lock = threading.Lock()  # _robots: the loop adds, lanes read

    # ------------------------------------------------------------------ robots

    def _robot(self, name: str) -> _Robot:
        """The motion state of robot ``name``, rebuilt when its description was reloaded
        (on the loop: it may subscribe)."""
        source, topic = self._lookup(name)
        with self._lock:
            robot = self._robots.get(name)
        if robot is not None and robot.source is source and robot.topic == topic:
            return robot
        from bridge.motion.model import MotionModel

        fresh = _Robot(name, source, MotionModel(source), topic)
        if robot is not None:
            self._forget(robot)
        fresh.subscription = self._ros.node.create_subscription(
            JointState, topic, lambda msg: self._on_joint_state(fresh, msg), _JOINT_STATES_QOS)
        with self._lock:
            self._robots[name] = fresh
        log.info("motion: robot %s (%d actuated joints), current state from %s", name,
                 len(fresh.model.joint_names), topic)
        return fresh

    @staticmethod
    def _on_joint_state(robot: _Robot, msg: JointState) -> None:
        """A joint state of the robot (executor thread): positions kept as given."""
        for name, position in zip(msg.name, msg.position):
            robot.positions[str(name)] = float(position)

    def _forget(self, robot: _Robot) -> None:
        if robot.subscription is not None:
            self._ros.destroy(robot.subscription)
            robot.subscription = None

    # ------------------------------------------------------------------ ops

    def solve_ik(self, request: SolveIk) -> OffLoop[Result]:
        robot = self._robot(request.name)
        target_m = np.array(request.target, dtype=np.float64)
        target_m[:3, 3] = mm_to_metres(target_m[:3, 3])
        if request.seed is not None:
            seed, seed_from = dict(request.seed), "given"
        elif robot.positions:
            seed, seed_from = dict(robot.positions), "joint_states"
        else:
            seed, seed_from = {}, "zero"

        def work() -> Result:
            from bridge.motion.ik import solve_ik

            with robot.lock:  # one pinocchio Data per robot
                world = self._world(robot) if request.collisions else None
                try:
                    result = solve_ik(robot.model, target_m, request.tip, seed, world=world)
                except MotionError as error:  # the request's fault: a refusal, not a bug
                    raise OutOfRangeError(error.field, error.expected, error.got) from None
                links = robot.model.link_poses(result.theta)
            out: dict[str, Any] = {
                "name": robot.name, "tip": request.tip, "solved": result.ok,
                "positions": result.positions, "residual_mm": result.residual_mm,
                "residual_deg": result.residual_deg, "iterations": result.iterations,
                "attempts": result.attempts, "seed": seed_from,
                "links": {link: _mm_rows(pose) for link, pose in links.items()}}
            if result.failure is not None:
                out["failure"] = result.failure.to_dict()
            return out

        return OffLoop(work)

    def _world(self, robot: _Robot) -> Optional[CollisionWorld]:
        """The robot's collision world once it has obstacles; None before (no cost)."""
        world = robot.world
        return world if world is not None and world.obstacles else None

    # ------------------------------------------------------------------ capability

    def handlers(self) -> dict[type[Op], Handler]:
        return {SolveIk: lambda request, _: self.solve_ik(request)}

    def describe(self) -> list[dict[str, Any]]:
        return []

    def state(self, guard: Any) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        with self._lock:
            robots = list(self._robots.values())
            self._robots.clear()
        for robot in robots:
            self._forget(robot)


def _mm_rows(pose_m: npt.NDArray[np.float64]) -> list[list[float]]:
    """A pose in metres as the wire's 4 rows in millimetres."""
    rows = np.array(pose_m, dtype=np.float64)
    rows[:3, 3] = metres_to_mm(rows[:3, 3])
    return [[float(v) for v in row] for row in rows]
