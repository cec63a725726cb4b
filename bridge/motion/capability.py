"""The daemon's motion capability: inverse kinematics of the robots the daemon loaded.

    solve_ik ─► the robot's model (the robots capability's, by name: `RobotLookup`)
             ─► its pinocchio model, built once per loaded description (`MotionModel`)
             ─► the seed: the request's, else the robot's latest /joint_states
             ─► `solve_ik` in the client's heavy lane (pinocchio is C++; a solve that
                fails tries every restart, up to ~0.5 s), one solve per robot at a time

    set_obstacle ─► subscribe to the topic a Slicer model is published on (publish_model:
                    a Marker TRIANGLE_LIST in its frame, or a Mesh); each message replaces
                    the obstacle's mesh; its pose is looked up in tf (root link <- its frame)
                    at every query, so it follows its transforms
    obstacle_distances ─► link-to-obstacle distances and contacts at the current state
    publish_distance ─► a timer publishing one distance as std_msgs/Float64 (metres)
    plan_motion ─► a straight joint-space path from the current state to a goal, within
                   limits, checked for contact every `resolution` (rad or m)
    execute_motion ─► the same plan; if clear, a FollowJointTrajectory goal sent through
                   the actions capability's goal sender (handed over by the daemon), so
                   its feedback, result and cancel are a send_goal's

solve_ik is a read: nothing is published, the robot does not move. Units: the ops speak mm
(Slicer's), the solver metres, converted by `protocol.conversions`; the Float64 topic is
metres, as ROS has it.

This capability never imports another's handlers: the daemon hands it the robots
capability's public `loaded_model`, the tf buffer's lookup and the goal sender's
`send_goal` as plain functions.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
import asyncio
import math
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, Awaitable, Callable, Iterator, Optional

import numpy as np
import numpy.typing as npt
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from shape_msgs.msg import Mesh
from std_msgs.msg import Float64
from visualization_msgs.msg import Marker

from bridge.core.content_guards import ContentGuard
from bridge.core.dispatch import Handler
from bridge.core.heavy import OffLoop
from bridge.core.threads import OnFailure, start_thread
from bridge.ros.ros_node import RosNode
from bridge.motion.errors import MotionError
from bridge.ros.graph_types import refuse_other_type
from bridge.core.hub import Replier
from protocol.commands import (FOLLOW_JOINT_TRAJECTORY, MAX_OBSTACLES, CommandFailedError,
                               ErrorCode, ExecuteMotion, ExecuteMotionResult, LimitReachedError,
                               Matrix4, ObstacleDistances, ObstacleDistancesResult, ObstacleRemoved,
                               ObstacleSet, Op, OutOfRangeError, PlanMotion, PlanMotionResult,
                               PublishDistance, PublishDistanceResult, RemoveObstacle, SendGoal,
                               SendGoalResult, SetObstacle, SolveIk, SolveIkResult, matrix_rows)
from protocol.commands.fields import Args
from protocol.conversions import metres_to_mm, mm_to_metres, pose_to_matrix

if TYPE_CHECKING:  # pinocchio and coal load when the first robot does (robot_loaded)
    from bridge.motion.collisions import CollisionWorld
    from bridge.motion.model import MotionModel
    from bridge.robots.model import RobotModel

__all__ = ["MotionBridges", "RobotLookup"]

log = logging.getLogger(__name__)

F64 = npt.NDArray[np.float64]

# A loaded robot's model, the topic its joint states are on and its root link's tf frame,
# by robot name; raises the robots capability's CommandFailedError for a robot not there or
# not loaded.
RobotLookup = Callable[[str], "tuple[RobotModel, str, str]"]
# tf: target <- source, latest (the daemon's buffer); raises a TfError when it cannot.
FrameLookup = Callable[[str, str], Any]
# The actions capability's send_goal: (request, client) -> its reply.
GoalSender = Callable[[SendGoal, Optional[Replier]], Awaitable[SendGoalResult]]

_MAX_TRAJECTORY_POINTS = 50
_MAX_WATCHES = 64  # publish_distance topics, all robots together
# How long a robot's first motion request waits for its first joint state (discovery).
_FIRST_STATE_S = 5.0
_DEFAULT_SPEED = 0.5  # rad/s (m/s) for a joint whose URDF gives no velocity limit

# A model published once (latched) or streamed: reliable, and transient local takes both.
_OBSTACLE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.VOLATILE)
# Any joint-state publisher's profile matches a best-effort, volatile subscriber.
_JOINT_STATES_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                               reliability=ReliabilityPolicy.BEST_EFFORT,
                               durability=DurabilityPolicy.VOLATILE)


def _built(done: Any) -> None:
    """A bug in an obstacle's build is said, not lost in its future."""
    if not done.cancelled() and done.exception() is not None:
        log.error("motion: an obstacle mesh failed to build", exc_info=done.exception())


def _pose_m(translation_m: Any, quaternion_xyzw: Any) -> F64:
    """A ROS pose as a 4x4 in METRES (the protocol's conversion gives Slicer's mm)."""
    matrix = pose_to_matrix(translation_m, quaternion_xyzw)
    matrix[:3, 3] = mm_to_metres(matrix[:3, 3])
    return matrix


@dataclass(eq=False)
class _Obstacle:
    """An obstacle as its topic last gave it: triangles (metres) in ``frame``, placed there
    at ``pose`` (a Marker's own pose)."""

    name: str
    request: SetObstacle
    guard: ContentGuard  # the frames its client may see (a Marker names its own)
    subscription: Any = None
    frame: str = ""
    pose: F64 = field(default_factory=lambda: np.eye(4))
    triangles: int = 0
    error: str = "no message yet"
    pending: Any = None  # the newest message not built yet


@dataclass(eq=False)
class _Watch:
    request: PublishDistance
    publisher: Any
    timer: Any
    warned: str = ""


@dataclass(eq=False)
class _Robot:
    """What motion keeps per robot: the model built for one loaded description, its
    collision world, and the latest joint positions heard on its topic."""

    name: str
    source: RobotModel
    model: MotionModel
    topic: str
    root_frame: str
    lock: threading.Lock = field(default_factory=threading.Lock)
    world: Optional[CollisionWorld] = None
    positions: dict[str, float] = field(default_factory=dict)
    subscription: Any = None
    obstacles: dict[str, _Obstacle] = field(default_factory=dict)
    heard: threading.Event = field(default_factory=threading.Event)  # a first joint state

    def current(self) -> dict[str, float]:
        """The latest joint positions (worker thread): the first request after the robot's
        subscription began waits a little for the first state to come."""
        self.heard.wait(_FIRST_STATE_S)
        return dict(self.positions)


class MotionBridges:
    """Inverse kinematics, obstacles, distances, plans and their execution for the robots
    the robots capability loaded."""

    def __init__(self, ros: RosNode, *, robots: RobotLookup, frames: FrameLookup,
                 send_goal: GoalSender) -> None:
        self._ros = ros
        self._lookup = robots
        self._frames = frames
        self._send_goal = send_goal
        self._robots: dict[str, _Robot] = {}
        self._watches: dict[str, _Watch] = {}  # by topic
        # Obstacle meshes are read and built here, one at a time, off the ROS executor.
        self._builder = ThreadPoolExecutor(1, thread_name_prefix="motion-obstacles")
        self._lock = threading.Lock()  # _robots: the loop adds, lanes read
        self._importing = False

    def robot_loaded(self, name: str) -> None:
        """A robot's model was loaded (loop): pinocchio and coal are imported now, off the
        loop, in a thread of their own. Imported by the first motion request instead, on
        the loop, they stalled every client's replies and heartbeats (past 3 s under load,
        and Slicer's module took the link for lost); a daemon with no robot never loads
        them."""
        if not self._importing:
            self._importing = True
            start_thread("motion-import", _import_motion_libraries, OnFailure.RESTART)

    # ------------------------------------------------------------------ robots

    def _robot(self, name: str) -> _Robot:
        """The motion state of robot ``name``, rebuilt when its description was reloaded
        (on the loop: it may subscribe)."""
        try:
            source, topic, root_frame = self._lookup(name)
        except CommandFailedError:
            self._drop(name)  # removed (or not loaded any more): nothing of it stays here
            raise
        with self._lock:
            robot = self._robots.get(name)
        if robot is not None and robot.source is source and robot.topic == topic:
            return robot
        from bridge.motion.model import MotionModel

        fresh = _Robot(name, source, MotionModel(source), topic, root_frame)
        kept = [(o.request, o.guard) for o in robot.obstacles.values()] if robot else []
        if robot is not None:
            self._forget(robot)
        fresh.subscription = self._ros.node.create_subscription(
            JointState, topic, lambda msg: self._on_joint_state(fresh, msg), _JOINT_STATES_QOS)
        with self._lock:
            self._robots[name] = fresh
        log.info("motion: robot %s (%d actuated joints), current state from %s", name,
                 len(fresh.model.joint_names), topic)
        for request, guard in kept:  # a reloaded description keeps its obstacles
            self.set_obstacle(request, guard)
        return fresh

    def robot_removed(self, name: str) -> None:
        """The robots capability removed robot ``name`` (loop): its motion state goes."""
        self._drop(name)

    def _drop(self, name: str) -> None:
        with self._lock:
            robot = self._robots.pop(name, None)
        topics = [t for t, watch in self._watches.items() if watch.request.name == name]
        for topic in topics:
            self._stop_watch(topic)
        if robot is not None:
            log.info("motion: robot %s dropped (%d obstacle(s), %d distance topic(s))", name,
                     len(robot.obstacles), len(topics))
            self._forget(robot)

    def _stop_watch(self, topic: str) -> None:
        watch = self._watches.pop(topic, None)
        if watch is not None:
            self._ros.destroy(watch.timer)
            self._ros.destroy(watch.publisher)

    @staticmethod
    def _on_joint_state(robot: _Robot, msg: JointState) -> None:
        """A joint state of the robot (executor thread): positions kept as given."""
        for name, position in zip(msg.name, msg.position):
            robot.positions[str(name)] = float(position)
        robot.heard.set()

    def _forget(self, robot: _Robot) -> None:
        if robot.subscription is not None:
            self._ros.destroy(robot.subscription)
            robot.subscription = None
        for obstacle in robot.obstacles.values():
            self._ros.destroy(obstacle.subscription)
        robot.obstacles.clear()

    # ------------------------------------------------------------------ ops

    def solve_ik(self, request: SolveIk) -> OffLoop[SolveIkResult]:
        robot = self._robot(request.name)
        target_m = np.array(request.target, dtype=np.float64)
        target_m[:3, 3] = mm_to_metres(target_m[:3, 3])

        def work() -> SolveIkResult:
            from bridge.motion.ik import solve_ik

            current = robot.current() if request.seed is None else {}
            if request.seed is not None:
                seed, seed_from = dict(request.seed), "given"
            elif current:
                seed, seed_from = current, "joint_states"
            else:
                seed, seed_from = {}, "zero"

            with robot.lock:  # one pinocchio Data per robot
                unplaced: list[dict[str, str]] = []
                try:
                    if request.collisions and robot.world is not None and robot.obstacles:
                        with self._placed(robot) as (world, unplaced):
                            result = solve_ik(robot.model, target_m, request.tip, seed,
                                              world=world if world.obstacles else None)
                    else:
                        result = solve_ik(robot.model, target_m, request.tip, seed)
                except MotionError as error:  # the request's fault: a refusal, not a bug
                    raise OutOfRangeError(error.field, error.expected, error.got) from None
                links = robot.model.link_poses(result.theta)
            return SolveIkResult(
                robot.name, request.tip, result.ok, result.positions, result.residual_mm,
                result.residual_deg, result.iterations, result.attempts, seed_from,
                {link: _mm_rows(pose) for link, pose in links.items()},
                failure=result.failure.to_dict() if result.failure is not None else None,
                unplaced=tuple(unplaced) or None)

        return OffLoop(work)

    @contextmanager
    def _placed(self, robot: _Robot, only: Optional[str] = None
                ) -> Iterator[tuple[CollisionWorld, list[dict[str, str]]]]:
        """The robot's collision world (under ``robot.lock``) with its obstacles posed in the
        root link frame as tf has them now (they follow their transforms); those tf cannot
        place, not received yet, or other than ``only`` are out of the query, the first two
        said (name, why)."""
        world = robot.world
        assert world is not None
        unplaced: list[dict[str, str]] = []
        hidden: dict[str, Any] = {}
        for obstacle in robot.obstacles.values():
            if obstacle.name not in world.obstacles:
                unplaced.append({"obstacle": obstacle.name, "reason": obstacle.error})
                continue
            if only is not None and obstacle.name != only:
                hidden[obstacle.name] = world.obstacles.pop(obstacle.name)
                continue
            refusal = obstacle.guard.frame_refusal(obstacle.frame.lstrip("/"))
            if refusal is not None:  # a Marker's frame_id its client may not see
                unplaced.append({"obstacle": obstacle.name, "reason": refusal})
                hidden[obstacle.name] = world.obstacles.pop(obstacle.name)
                continue
            try:
                if obstacle.frame.lstrip("/") == robot.root_frame:
                    frame = np.eye(4)
                else:
                    t = self._frames(robot.root_frame, obstacle.frame.lstrip("/"))
                    frame = _pose_m(t.translation, t.rotation)
            except Exception as error:  # noqa: BLE001 - tf's errors say what is missing
                unplaced.append({"obstacle": obstacle.name, "reason": f"tf: {error}"})
                hidden[obstacle.name] = world.obstacles.pop(obstacle.name)
                continue
            world.move_obstacle(obstacle.name, frame @ obstacle.pose)
        try:
            yield world, unplaced
        finally:
            world.obstacles.update(hidden)

    # ------------------------------------------------------------------ obstacles

    def set_obstacle(self, request: SetObstacle, guard: ContentGuard) -> ObstacleSet:
        robot = self._robot(request.name)
        with robot.lock:
            if robot.world is None:
                from bridge.motion.collisions import CollisionWorld

                world = CollisionWorld(robot.model)
                try:
                    world.require_geometry("name")
                except MotionError as error:
                    raise OutOfRangeError(error.field, error.expected, error.got) from None
                robot.world = world
        if request.obstacle not in robot.obstacles and len(robot.obstacles) >= MAX_OBSTACLES:
            raise LimitReachedError("obstacle", f"at most {MAX_OBSTACLES} obstacles per robot",
                                    "one more")
        refuse_other_type(self._ros, request.topic, request.ros_type, "topic")
        old = robot.obstacles.pop(request.obstacle, None)
        if old is not None:
            self._ros.destroy(old.subscription)
            with robot.lock:
                robot.world.obstacles.pop(request.obstacle, None)
        obstacle = _Obstacle(request.obstacle, request, guard,
                             frame=request.frame or robot.root_frame)
        kind = Marker if request.type == "Marker" else Mesh
        obstacle.subscription = self._ros.node.create_subscription(
            kind, request.topic, lambda msg: self._on_obstacle(robot, obstacle, msg),
            _OBSTACLE_QOS)
        robot.obstacles[request.obstacle] = obstacle
        log.info("motion: robot %s: obstacle %s from %s (%s)", robot.name, request.obstacle,
                 request.topic, request.type)
        return ObstacleSet(robot.name, request.obstacle, request.topic, request.type,
                           tuple(robot.world.links))

    def _on_obstacle(self, robot: _Robot, obstacle: _Obstacle, msg: Any) -> None:
        """A model on an obstacle's topic (executor thread): handed to the builder thread
        (reading 100k triangles out of a message and building their hierarchy takes most of
        a second: never on the executor, which delivers every other ROS message). Only the
        newest message waiting is built."""
        with self._lock:
            queued = obstacle.pending is not None
            obstacle.pending = msg
        if not queued:
            self._builder.submit(self._build, robot, obstacle).add_done_callback(_built)

    def _build(self, robot: _Robot, obstacle: _Obstacle) -> None:
        """The newest model of an obstacle into its collision world (builder thread)."""
        from bridge.motion.collisions import mesh_bvh

        with self._lock:
            msg, obstacle.pending = obstacle.pending, None
        if msg is None:
            return
        if isinstance(msg, Marker):
            points = np.array([(p.x, p.y, p.z) for p in msg.points], dtype=np.float64)
            triangles = np.arange(len(points) - len(points) % 3).reshape(-1, 3)
            o = msg.pose.orientation
            pose = _pose_m((msg.pose.position.x, msg.pose.position.y, msg.pose.position.z),
                           (o.x, o.y, o.z, o.w))
            frame = msg.header.frame_id
        else:
            points = np.array([(p.x, p.y, p.z) for p in msg.vertices], dtype=np.float64)
            triangles = np.array([t.vertex_indices for t in msg.triangles],
                                 dtype=np.int64).reshape(-1, 3)
            pose, frame = np.eye(4), obstacle.frame
        try:
            bvh = mesh_bvh(points, triangles, f"obstacle {obstacle.name!r}")
        except MotionError as error:
            bvh, problem = None, str(error)
        with robot.lock:
            world = robot.world
            if world is None or robot.obstacles.get(obstacle.name) is not obstacle:
                return  # removed meanwhile
            if bvh is None:
                obstacle.error = problem
                world.obstacles.pop(obstacle.name, None)
                log.warning("motion: robot %s: obstacle %s from %s not used: %s", robot.name,
                            obstacle.name, obstacle.request.topic, problem)
                return
            world.put_obstacle(obstacle.name, bvh)
            obstacle.frame, obstacle.pose = frame or robot.root_frame, pose
            obstacle.triangles, obstacle.error = len(triangles), ""

    def remove_obstacle(self, request: RemoveObstacle) -> ObstacleRemoved:
        robot = self._robot(request.name)
        obstacle = robot.obstacles.pop(request.obstacle, None)
        if obstacle is None:
            raise CommandFailedError("obstacle", f"an obstacle of robot {robot.name!r} "
                                     f"({', '.join(robot.obstacles) or 'none'})",
                                     request.obstacle, code=ErrorCode.NOT_FOUND)
        self._ros.destroy(obstacle.subscription)
        with robot.lock:
            if robot.world is not None:
                robot.world.obstacles.pop(request.obstacle, None)
        return ObstacleRemoved(robot.name, request.obstacle)

    # ------------------------------------------------------------------ distances

    def obstacle_distances(self, request: ObstacleDistances,
                           ) -> OffLoop[ObstacleDistancesResult]:
        robot = self._robot(request.name)

        def work() -> ObstacleDistancesResult:
            positions = robot.current()
            with robot.lock:
                if robot.world is None:
                    raise OutOfRangeError("name", "a robot with obstacles (set_obstacle)",
                                          f"robot {robot.name!r} has none")
                theta = robot.model.theta_of(positions)
                with self._placed(robot) as (world, unplaced):
                    try:
                        distances = world.distances(theta, request.link)
                        contacts = world.contacts(theta)
                    except MotionError as error:
                        raise OutOfRangeError(error.field, error.expected, error.got) from None
            return ObstacleDistancesResult(
                robot.name, request.link, robot.model.positions_of(theta),
                tuple(d.to_dict() for d in distances),
                tuple({"link": c.link, "obstacle": c.obstacle} for c in contacts),
                tuple(unplaced))

        return OffLoop(work)

    def publish_distance(self, request: PublishDistance) -> PublishDistanceResult:
        robot = self._robot(request.name)
        self._stop_watch(request.topic)
        if request.rate_hz == 0:
            return PublishDistanceResult(robot.name, request.topic, False)
        if request.obstacle not in robot.obstacles:
            raise CommandFailedError("obstacle", f"an obstacle of robot {robot.name!r} "
                                     f"({', '.join(robot.obstacles) or 'none'})",
                                     request.obstacle, code=ErrorCode.NOT_FOUND)
        if request.link not in robot.model.link_names:
            raise OutOfRangeError("link", f"a link of robot {robot.name!r}", request.link)
        if len(self._watches) >= _MAX_WATCHES:
            raise LimitReachedError("topic", f"at most {_MAX_WATCHES} distance topics",
                                    "one more (stop one with rate_hz 0)")
        refuse_other_type(self._ros, request.topic, "std_msgs/msg/Float64", "topic")
        publisher = self._ros.node.create_publisher(Float64, request.topic, 10)
        watch = _Watch(request, publisher, None)
        watch.timer = self._ros.node.create_timer(1.0 / request.rate_hz,
                                                  lambda: self._tick(watch))
        self._watches[request.topic] = watch
        return PublishDistanceResult(robot.name, request.topic, True, request.rate_hz)

    def _tick(self, watch: _Watch) -> None:
        """One distance on a watch's topic (executor thread), for the robot of that name as
        it is now (a reloaded description included); nothing while it cannot be measured
        (said once in the log)."""
        request = watch.request
        why = ""
        with self._lock:
            robot = self._robots.get(request.name)
        if robot is None:
            why = f"robot {request.name!r} is gone"
        else:
            why = self._measure(robot, watch)
        if why:
            if why != watch.warned:
                log.warning("motion: %s: no distance from %s to %s: %s", request.topic,
                            request.link, request.obstacle, why)
                watch.warned = why
            return
        watch.warned = ""

    def _measure(self, robot: _Robot, watch: _Watch) -> str:
        """Publish one distance on the watch's topic, or say why not."""
        request = watch.request
        why = ""
        with robot.lock:
            if robot.world is None:
                why = "no collision world"
            else:
                with self._placed(robot, only=request.obstacle) as (world, unplaced):
                    if request.obstacle not in world.obstacles:
                        why = next((u["reason"] for u in unplaced
                                    if u["obstacle"] == request.obstacle), "removed")
                    else:
                        [distance] = world.distances(robot.model.theta_of(robot.positions),
                                                     request.link)
        if not why:
            watch.publisher.publish(Float64(data=distance.distance_m))
        return why

    # ------------------------------------------------------------------ plan, execute

    def _plan(self, robot: _Robot, goal: tuple[tuple[str, float], ...],
              resolution: float, preview: int = 0) -> PlanMotionResult:
        """The straight joint-space path from the current state to ``goal`` (worker
        thread), checked for limits (the goal; the box of limits holds the whole line) and
        for contact at every ``resolution``."""
        from bridge.robots.joints import joint_positions

        current = robot.current()
        if not current:
            raise CommandFailedError("name", f"the robot's current joint state (on "
                                     f"{robot.topic})", f"none heard in {_FIRST_STATE_S:g} s",
                                     code=ErrorCode.UNAVAILABLE)
        joint_positions(robot.source.joints, goal)  # names and limits, refused by field
        model = robot.model
        with robot.lock:
            start = model.theta_of(current)
            end = start.copy()
            index = {name: i for i, name in enumerate(model.joint_names)}
            for name, value in goal:
                end[index[name]] = value
            delta = end - start
            steps = max(1, math.ceil(float(np.max(np.abs(delta), initial=0.0)) / resolution))
            path = start + np.outer(np.linspace(0.0, 1.0, steps + 1), delta)
            collision: Optional[dict[str, Any]] = None
            unplaced: list[dict[str, str]] = []
            if robot.world is not None and robot.obstacles:
                with self._placed(robot) as (world, unplaced):
                    hit = world.path_contact(path) if world.obstacles else None
                if hit is not None:
                    step, contact = hit
                    collision = {"link": contact.link, "obstacle": contact.obstacle,
                                 "step": step, "fraction": step / steps,
                                 "positions": model.positions_of(path[step])}
            picks: list[int] = (np.unique(np.linspace(0, len(path) - 1, min(preview, len(path)))
                                          .round().astype(int)).tolist() if preview else [])
            poses = [(k, model.link_poses(path[k])) for k in picks]
        moving = [i for i in range(len(delta)) if abs(delta[i]) > 0.0]
        duration = 1.0
        for i in moving:
            joint = robot.source.joints[model.joint_names[i]]
            speed = (joint.limits.velocity if joint.limits is not None and
                     joint.limits.velocity else 2 * _DEFAULT_SPEED) * 0.5
            duration = max(duration, abs(float(delta[i])) / speed)
        return PlanMotionResult(
            robot.name, tuple(model.joint_names[i] for i in moving), model.positions_of(start),
            model.positions_of(end), tuple(tuple(float(row[i]) for i in moving) for row in path),
            resolution, len(path), collision is None, collision, tuple(unplaced), duration,
            preview=tuple({"step": k, "time_s": duration * k / max(1, len(path) - 1),
                           "links": {link: _mm_rows(pose) for link, pose in links.items()}}
                          for k, links in poses) if preview else None)

    async def plan_motion(self, request: PlanMotion) -> PlanMotionResult:
        robot = self._robot(request.name)
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(
            None, lambda: self._plan(robot, request.positions, request.resolution,
                                     request.preview))

    async def execute_motion(self, request: ExecuteMotion,
                             client: Optional[Replier]) -> ExecuteMotionResult:
        robot = self._robot(request.name)
        loop = asyncio.get_running_loop()
        plan = await loop.run_in_executor(
            None, lambda: self._plan(robot, request.positions, request.resolution))
        collision = plan.collision
        if collision is not None:
            raise CommandFailedError(
                "positions", f"a path clear of the robot's obstacles (checked every "
                f"{request.resolution:g} rad or m)", f"link {collision['link']!r} touches "
                f"obstacle {collision['obstacle']!r} {collision['fraction']:.0%} of the way "
                f"(configuration {collision['step']} of {plan.checked - 1}); nothing sent",
                code=ErrorCode.REJECTED)
        duration = request.duration_s or plan.duration_s
        path = plan.path
        picks = np.unique(np.linspace(0, len(path) - 1,
                                      min(len(path), _MAX_TRAJECTORY_POINTS)).round().astype(int))
        points = []
        for k in picks[1:] if len(picks) > 1 else picks:
            at = duration * k / max(1, len(path) - 1)
            sec = int(at)
            points.append({"positions": list(path[k]), "time_from_start": {
                "sec": sec, "nanosec": int(round((at - sec) * 1e9)) % 1_000_000_000}})
        goal = {"trajectory": {"joint_names": list(plan.joints), "points": points}}
        fields: dict[str, Any] = {"action": request.action, "type": FOLLOW_JOINT_TRAJECTORY,
                                  "goal": goal, "timeout": request.timeout}
        if request.result_timeout is not None:
            fields["result_timeout"] = request.result_timeout
        if request.goal_id is not None:
            fields["goal_id"] = request.goal_id
        send = SendGoal.from_args(Args(fields, ""))  # its own checks (the goal id's form)
        reply = await self._send_goal(send, client)
        log.info("motion: robot %s: %d joint(s) to %s in %.2f s, %d configurations clear "
                 "(every %g)", robot.name, len(plan.joints), request.action, duration,
                 plan.checked, request.resolution)
        return ExecuteMotionResult(reply.action, reply.type, reply.goal_id, reply.device,
                                   reply.status, reply.stamp, name=robot.name,
                                   joints=plan.joints, checked=plan.checked,
                                   resolution=request.resolution, duration_s=duration,
                                   unplaced=plan.unplaced)

    # ------------------------------------------------------------------ capability

    def handlers(self) -> dict[type[Op], Handler]:
        return {SolveIk: lambda request, _: self.solve_ik(request),
                SetObstacle: lambda request, _, guard: self.set_obstacle(request, guard),
                RemoveObstacle: lambda request, _: self.remove_obstacle(request),
                ObstacleDistances: lambda request, _: self.obstacle_distances(request),
                PublishDistance: lambda request, _: self.publish_distance(request),
                PlanMotion: lambda request, _: self.plan_motion(request),
                ExecuteMotion: self.execute_motion}

    def describe(self) -> list[dict[str, Any]]:
        return []

    def state(self, guard: Any) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        for topic in list(self._watches):
            self._stop_watch(topic)
        self._builder.shutdown(wait=False, cancel_futures=True)
        with self._lock:
            robots = list(self._robots.values())
            self._robots.clear()
        for robot in robots:
            self._forget(robot)


def _mm_rows(pose_m: npt.NDArray[np.float64]) -> Matrix4:
    """A pose in metres as the wire's 4 rows in millimetres."""
    rows = np.array(pose_m, dtype=np.float64)
    rows[:3, 3] = metres_to_mm(rows[:3, 3])
    return matrix_rows(rows)


def _import_motion_libraries() -> None:
    try:
        import bridge.motion.collisions  # noqa: F401  (pinocchio and coal)
        import bridge.motion.model  # noqa: F401
    except Exception as error:  # noqa: BLE001 - the motion ops say so when asked
        log.info("motion: its libraries did not load (%s); the motion ops are refused", error)
