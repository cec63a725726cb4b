"""The daemon's robot capability: a URDF -> one POLYDATA per link visual (sent once per
connection) + every link's pose in one TDATA (``poses:<robot>``, streamed by tf when a
link moves; each element is named by its link's device, ``<robot>:<link>``).

    create_robot ─► URDF from a parameter (ParameterBridges.watch_parameter), a latched
                    topic (our subscription) or a file
                 ─► load_robot in a worker thread (meshes: ms to seconds, never on the loop;
                    the files parsed several at once in reader processes, as the daemon
                    gives them: `bridge.robots.mesh_readers`)
                 ─► loop: hub.publish_persistent(POLYDATA per visual)
                          tf.stream_lookup(fixed_frame <- tf_prefix + link) per link,
                          grouped: one TDATA per tf update for all the links

Why one TDATA and not a TRANSFORM per link: 3D Slicer's connector spends about 90 us of
its main thread on each message whatever its size; a moving 11-link robot at 50 Hz was
550 messages a second, and is 50 as TDATA (its connector makes the same linear transform
node per link, named by the element, and updates them all from one message).

What SlicerROS2 does differently, and why not here: it reads the URDF from the parameter
name ``robot_description`` whatever name was given (here: the name given), skips URDF
primitives (here: boxes, cylinders, spheres are meshed), applies one mesh scale to every
link (here: per visual), and polls every link's lookup at 50 Hz (here: a link's TRANSFORM
goes out only when tf changed it, through the tf capability's change-driven registry).

A description that is not there yet (node not up, nothing on the topic) is not an error:
the robot is "waiting" and loads when the URDF appears; a STATUS on its description device
(``urdf:<name>``) says which state it is in. A changed description (parameter event, new
topic message, the node coming back) reloads the robot: meshes are re-published under the
same device names, devices of links that are gone are forgotten. A malformed URDF is an
error reply at creation; on a reload it leaves the robot as it was and says why (STATUS).

Device names come from the daemon's `DeviceNameRegistry`, so they are the same on every
reconnect (3D Slicer finds its nodes again by name).

Units: the model's vertices are already in mm; the tf capability turns metres into mm.

Frame globs (``--allow-frame``/``--deny-frame``) hold for robots too: a link whose tf frame
the policy denies is withheld (no TRANSFORM, no mesh; listed under "withheld"), and a robot
whose fixed frame is denied does not load.

Files: a robot reads meshes only inside the mesh roots (``--robot-dir`` and
``--package-path`` folders) whatever the source of its description, since a client can put
any URDF in a parameter or on a topic (and change the one an operator's robot reads); a
mesh outside them is a warning worded as for a missing one (`bridge.robots.resources`).
Only a URDF file named by the operator's start-up config is trusted to read meshes from
anywhere.
"""

from __future__ import annotations

import asyncio
import json
import functools
import hashlib
import logging
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Optional

from bridge.core.content_guards import ContentGuard
from bridge.core.dispatch import Created, Handler, made_bridge
from bridge.core.hub import Hub, Replier
from bridge.robots.errors import RobotError
from bridge.robots.joints import describe_joints, joint_positions
from bridge.robots.resources import PackageResolver
from bridge.tf.lookups import LookupKey, LookupStreams
from protocol.commands import (JOINT_STATE_TYPE, CommandFailedError, CreateRobot, CreatedRobot,
                               DescribeRobotJoints, DescribeRobotJointsResult, ErrorCode,
                               ForbiddenError, ListRobots, ListRobotsResult, Op, OutOfRangeError,
                               ParameterValue, RemoveRobot, RemovedRobot, RobotSource, RobotSummary,
                               SetRobotJoints, SetRobotJointsResult)
from protocol.messages import Message, PolyData, Status, StatusCode
from protocol.naming import (KEY_CHILD, KEY_COLOR, KEY_LINK_COUNT, KEY_LINK_DEVICES,
                             KEY_PARENT, KEY_PARENT_DEVICE, KEY_VISUAL_COUNT, KEY_WARNINGS,
                             UNITS_MM,
                             DeviceNameRegistry, NameKey, NamingError, metadata_for)

if TYPE_CHECKING:  # bridge.robots.model (trimesh, yourdfpy) loads with the first robot;
    # ROS only where the daemon reads a description from it (`RobotServing` is ROS-free)
    from bridge.parameters.watch import ParameterWatch, ParameterWatcher
    from bridge.robots.description import RobotDescription
    from bridge.robots.mesh_readers import MeshReaders
    from bridge.robots.model import RobotModel, VisualMesh
    from bridge.ros.ros_node import RosNode

__all__ = ["RobotBridges", "RobotServing"]

log = logging.getLogger(__name__)

_STATUS_NAME = "slicer-ros2-bridge"
# How long create_robot waits for a latched description on a topic before saying "waiting".
_TOPIC_WAIT_S = 2.0
# With "wait": false, how long its source may take to be discovered before the request is
# refused (discovery takes seconds on a busy machine; as `echo --wait`).
_REFUSE_AFTER_S = 10.0
_JOINT_STATES_TYPE = "sensor_msgs/msg/JointState"
_DESCRIPTION_TYPE = "std_msgs/msg/String"


def _joint_states_qos() -> Any:
    """As joint_states publishers do (robot_state_publisher subscribes reliable, depth 10)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def _description_qos() -> Any:
    """robot_state_publisher's own profile for robot_description: a late subscriber gets it."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


@dataclass
class _Link:
    link: str
    frame: str  # the tf frame: tf_prefix + link
    key: NameKey
    device: str
    handle: LookupKey
    visuals: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class _VisualInfo:
    device: str
    key: NameKey
    link: str
    index: int
    name: str
    vertices: int
    triangles: int
    rgba: tuple[float, float, float, float]
    source: str

    def to_dict(self) -> dict[str, Any]:
        return {"device": self.device, "link": self.link, "index": self.index,
                "name": self.name, "vertices": self.vertices, "triangles": self.triangles,
                "color": list(self.rgba), "source": self.source}


@dataclass(eq=False)
class _Robot:
    name: str
    request: CreateRobot
    source: RobotSource  # names resolved (namespace applied)
    tf_prefix: str
    description_key: NameKey
    description_device: str
    poses_key: NameKey
    poses_device: str  # the TDATA of every link's pose
    guard: ContentGuard  # which of its frames a client may see (from its create request)
    state: str = "waiting"  # waiting | loaded | error
    reason: str = ""  # why waiting, or the last load error
    model: Optional[RobotModel] = None
    urdf_digest: str = ""  # of the loaded text: an unchanged description is not reloaded
    loading_digest: str = ""  # of the text being loaded now (an event and a fetch may both
    # bring the same new description)
    fixed_frame: str = ""
    links: dict[str, _Link] = field(default_factory=dict)
    withheld: dict[str, str] = field(default_factory=dict)  # link -> why (frame policy)
    visuals: dict[str, _VisualInfo] = field(default_factory=dict)  # device -> info
    warnings: tuple[str, ...] = ()
    loads: int = 0
    generation: int = 0  # bumped per description received: only the newest load applies
    watch: Optional["ParameterWatch"] = None
    subscription: Any = None
    first_description: Optional[asyncio.Future[str]] = None
    removed: bool = False
    # Meshes only from these folders; None: an operator's URDF file, trusted.
    mesh_roots: Optional[tuple[Path, ...]] = None
    loaded: asyncio.Event = field(default_factory=asyncio.Event)
    # While a worker reads a description: (its generation, the parsed description), once
    # its links are wired; the meshes it has sent so far (device -> info), and by
    # (generation, link, visual index), so that the load's end does not send them again.
    reading: Optional[tuple[int, Any]] = None
    streamed: dict[str, _VisualInfo] = field(default_factory=dict)
    sent: dict[tuple[int, str, int], _VisualInfo] = field(default_factory=dict)
    # set_robot_joints: one JointState publisher per robot (its latest topic), so the op
    # creates at most one ROS entity per robot whatever clients send.
    joint_publisher: Any = None
    joint_topic: str = ""


class RobotServing:
    """Robots from URDF: meshes once per connection, link transforms from tf. Where the
    description comes from is a subclass's: the daemon's `RobotBridges` reads it from ROS,
    the player (bridge/playback) from a bag; this part needs no ROS."""

    def __init__(self, hub: Hub, names: DeviceNameRegistry, *, tf: LookupStreams,
                 package_paths: Mapping[str, Path] | None = None,
                 mesh_readers: Optional[MeshReaders] = None) -> None:
        self._hub = hub
        # Mesh files parsed in these processes (None: in a worker thread of this one).
        self._readers = mesh_readers
        self._names = names
        self._tf = tf
        self._package_paths = {name: Path(folder) for name, folder in
                               (package_paths or {}).items()}
        self.robots: dict[str, _Robot] = {}
        self._tasks: set[asyncio.Task[None]] = set()
        # Told a robot's name when it is removed (on the loop): what others keep of it goes.
        self.removed_listeners: list[Callable[[str], None]] = []
        # Told a robot's name when a model of it is loaded (on the loop).
        self.loaded_listeners: list[Callable[[str], None]] = []

    # ------------------------------------------------------------------ ops

    async def create_robot(self, request: CreateRobot, client: Optional[Replier],
                           guard: ContentGuard) -> Created[CreatedRobot]:
        """`client` None: the operator's start-up robot. ``guard`` says which of its frames
        a client may see and where its meshes may be read from (anywhere only for a URDF
        file the operator's config names: `SecurityPolicy.content_guard`)."""
        existing = self.robots.get(request.name)
        if existing is not None:
            if existing.request == request:  # a reconnecting client re-creates what it had
                return Created(self._describe(existing), existed=True)
            raise CommandFailedError("name", "a robot name not in use (remove_robot first, "
                                     "or repeat the same request)", request.name,
                                     code=ErrorCode.ALREADY_EXISTS)
        try:
            description_key = NameKey.robot_description(request.name)
            poses_key = NameKey.robot_poses(request.name)
            description_device = self._device(request, description_key)
            poses_device = self._device(request, poses_key)
        except NamingError as error:
            raise OutOfRangeError("name", "a robot name usable as a device name",
                                  f"{request.name!r} ({error})") from None
        # The request's source comes placed and resolved (CreateRobot.with_names).
        robot = _Robot(request.name, request, request.source,
                       request.tf_prefix, description_key, description_device, poses_key,
                       poses_device, guard,
                       mesh_roots=guard.readable_roots())
        self.robots[robot.name] = robot
        if "bridge.robots.model" not in sys.modules:  # the first robot: while its URDF comes
            asyncio.get_running_loop().run_in_executor(None, _import_mesh_libraries)
        try:
            text = await self._first_description(robot)
            if text is not None:
                await self._load(robot, text, robot.generation, initial=True)
            else:
                self._status(robot, StatusCode.NOT_READY, f"waiting: {robot.reason}")
                log.info("robot %s: %s", robot.name, robot.reason)
        except BaseException:
            self._drop(robot)
            raise
        return Created(self._describe(robot), existed=False)

    def remove_robot(self, request: RemoveRobot) -> RemovedRobot:
        robot = self.robots.get(request.name)
        if robot is None:
            raise CommandFailedError("name", "a robot created by create_robot", request.name,
                                     code=ErrorCode.NOT_FOUND)
        devices = self._devices_of(robot)
        self._drop(robot)
        log.info("robot %s removed (%d devices)", robot.name, len(devices))
        return RemovedRobot(robot.name, tuple(devices))

    async def wait_loaded(self, name: str, timeout: float) -> dict[str, Any]:
        """The `create_robot` result of robot ``name`` once it has loaded, or as it is after
        ``timeout`` (for `demo`, which creates a robot whose node is still starting)."""
        robot = self.robots[name]
        try:
            await asyncio.wait_for(robot.loaded.wait(), timeout)
        except asyncio.TimeoutError:
            pass
        return self._describe(robot).to_dict()

    def list_robots(self, request: ListRobots) -> ListRobotsResult:
        return ListRobotsResult(tuple(self._summary(robot) for robot in self.robots.values()))

    # ------------------------------------------------------------------ sources

    async def _first_description(self, robot: _Robot) -> Optional[str]:
        """The URDF text now, or None (then ``robot.reason`` says what it waits for);
        ``"<file>"`` for a file source (read by the loader)."""
        raise NotImplementedError

    def _joint_states_topic(self, robot: _Robot) -> str:
        """Where this robot's joint states come from (`describe_robot_joints`)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ loading

    def _reload(self, robot: _Robot, text: str) -> None:
        digest = _digest(text)
        if digest == robot.loading_digest or (robot.state == "loaded" and
                                              digest == robot.urdf_digest):
            return  # the node re-announced the same description, or it is loading already
        robot.loading_digest = digest
        robot.generation += 1
        self._spawn(self._load(robot, text, robot.generation, initial=False))

    async def _load(self, robot: _Robot, text: str, generation: int, *,
                    initial: bool) -> None:
        """Load in a worker thread, then apply on the loop unless a newer description came.
        A failure raises at creation (the error reply) and is reported otherwise.

        The worker tells the loop the parsed description first (the link poses start
        streaming) and then each visual as it is made (its mesh goes out while the rest
        are read): a client has the robot as soon as its last mesh is read, not after all
        of them are and then sent (issue 44)."""
        source = robot.source
        loop = asyncio.get_running_loop()
        post = self._hub.call_soon
        listeners = {
            "on_description": lambda description: post(self._described, robot, generation,
                                                       description),
            "on_visual": lambda visual: post(self._visual_read, robot, generation, visual),
            "readers": self._readers}
        if source.kind == "file":
            path = self._file_path(source.path)
            call = functools.partial(_read_robot_file, path, package_paths=self._package_paths,
                                     allowed_roots=robot.mesh_roots, **listeners)
            field_name = "source.path"
        else:
            call = functools.partial(_read_robot, text, package_paths=self._package_paths,
                                     allowed_roots=robot.mesh_roots, **listeners)
            field_name = "source.parameter" if source.kind == "parameter" else "source.topic"
        try:
            model = await loop.run_in_executor(None, call)
        except RobotError as error:
            if generation == robot.generation:
                robot.loading_digest = ""
            # A file's error names its path already; say it once.
            what = "a valid URDF" if source.kind == "file" else \
                f"a valid URDF ({_source_text(source)})"
            problem = CommandFailedError(field_name, what, str(error),
                                         code=ErrorCode.OUT_OF_RANGE)
            if initial:
                raise problem from None
            if generation == robot.generation and not robot.removed:
                self._load_failed(robot, str(problem))
            return
        if robot.removed or generation != robot.generation:
            return  # removed, or a newer description is being loaded
        robot.loading_digest = ""
        fixed = _fixed_frame(robot, model)
        try:
            robot.guard.check_frame("fixed_frame", fixed)
        except ForbiddenError as refused:
            if initial:
                raise
            self._load_failed(robot, str(refused))
            return
        self._apply(robot, model, text)

    def _current(self, robot: _Robot, generation: int,
                 description: RobotDescription) -> bool:
        """Is what a worker reads for `generation` still wanted, and may its frames go
        out (the robot's fixed frame allowed)? Loop thread."""
        if robot.removed or generation != robot.generation:
            return False
        return robot.guard.frame_refusal(_fixed_frame(robot, description)) is None

    def _described(self, robot: _Robot, generation: int,
                   description: RobotDescription) -> None:
        """A worker parsed the description: its links' poses start streaming (loop)."""
        if self._current(robot, generation, description):
            self._apply_links(robot, description)
            robot.reading = (generation, description)

    def _visual_read(self, robot: _Robot, generation: int, visual: VisualMesh) -> None:
        """A worker made one visual: its mesh goes out now (loop)."""
        if robot.reading is None or robot.reading[0] != generation or \
                not self._current(robot, generation, robot.reading[1]):
            return
        if visual.link in robot.withheld or visual.link not in robot.links:
            return
        info = self._publish_visual(robot, visual)
        robot.streamed[info.device] = info
        robot.sent[(generation, visual.link, visual.index)] = info

    def file_path(self, spec: str) -> Path:
        """The file a file source names (the security policy checks where it lies)."""
        return self._file_path(spec)

    def _file_path(self, spec: str) -> Path:
        try:  # a path, or a package:// / file:// URI resolved with --package-path
            return PackageResolver(dict(self._package_paths)).resolve(spec)
        except RobotError as error:
            raise CommandFailedError("source.path", "a readable URDF file (path, package:// "
                                     "or file:// URI)", str(error),
                                     code=ErrorCode.NOT_FOUND) from None

    def _load_failed(self, robot: _Robot, reason: str) -> None:
        robot.reason = reason
        if robot.state != "loaded":
            robot.state = "error"
        log.warning("robot %s: description not loaded: %s%s", robot.name, reason,
                    " (the previous one stays)" if robot.state == "loaded" else "")
        self._status(robot, StatusCode.CONFIG_ERROR, f"description not loaded: {reason}")

    def _apply(self, robot: _Robot, model: RobotModel, text: str) -> None:
        """Publish the meshes and (re)wire the link lookups of a freshly loaded model (what
        the worker's listeners did not send yet: all of it where there were none)."""
        for listener in self.loaded_listeners:
            listener(robot.name)
        if robot.reading is None or robot.reading[1] is not model.description:
            self._apply_links(robot, model.description)
        for link in robot.links.values():
            link.visuals = []
        # Meshes: publish_persistent replaces a device's mesh; stale devices are forgotten.
        fresh: dict[str, _VisualInfo] = {}
        for visual in model.visuals:
            if visual.link in robot.withheld:
                continue
            info = robot.sent.get((robot.generation, visual.link, visual.index)) or \
                self._publish_visual(robot, visual)
            fresh[info.device] = info
            robot.links[visual.link].visuals.append(info.device)
        for device, info in {**robot.streamed, **robot.visuals}.items():
            if device not in fresh:
                self._hub.forget(device)
                self._names.release(info.key)
        robot.visuals = fresh
        robot.streamed, robot.sent, robot.reading = {}, {}, None
        fixed = robot.fixed_frame
        robot.model = model
        robot.urdf_digest = _digest(text)
        robot.warnings = model.warnings
        robot.state = "loaded"
        robot.reason = ""
        robot.loads += 1
        robot.loaded.set()
        summary = (f"loaded {model.name!r}: {len(model.links)} links, {len(model.visuals)} "
                   f"visuals, fixed frame {fixed}")
        if robot.withheld:
            summary += (f"; {len(robot.withheld)} link(s) withheld by the frame policy: "
                        + ", ".join(sorted(robot.withheld)))
        warned = f"; {len(model.warnings)} warning(s)" if model.warnings else ""
        # The counts let a client that created the robot while it was waiting know when
        # every link and mesh has arrived.
        self._status(robot, StatusCode.OK,
                     summary + (warned + ": " + "; ".join(model.warnings) if warned else ""),
                     {KEY_LINK_COUNT: str(len(robot.links)),
                      KEY_LINK_DEVICES: json.dumps({name: link.device
                                                    for name, link in robot.links.items()}),
                      KEY_VISUAL_COUNT: str(len(robot.visuals)),
                      KEY_WARNINGS: json.dumps(list(model.warnings))})
        # The loader logged each warning as it met it: the log counts them, once.
        log.info("robot %s %s%s", robot.name, summary, warned + " (above)" if warned else "")

    def _apply_links(self, robot: _Robot, description: RobotDescription) -> None:
        """(Re)wire the link lookups of a description: its links' TRANSFORMs stream from
        tf, those the frame policy refuses are withheld, links gone are forgotten."""
        prefix = robot.tf_prefix
        fixed = _fixed_frame(robot, description)
        if fixed != robot.fixed_frame:  # every lookup starts from the fixed frame: redo all
            self._forget_links(robot, set(robot.links))
        names = list(description.links)
        refusals = {name: robot.guard.frame_refusal(prefix + name) for name in names}
        robot.withheld = {name: why for name, why in refusals.items() if why is not None}
        wanted = set(names) - set(robot.withheld)
        self._forget_links(robot, set(robot.links) - wanted)
        robot.fixed_frame = fixed
        self._tf.open_pose_group(robot.poses_device, {
            **metadata_for(robot.poses_key, frame=fixed, units=UNITS_MM), KEY_PARENT: fixed})
        for name in names:
            if name in robot.withheld or name in robot.links:
                continue
            frame = prefix + name
            key = NameKey.robot_link(robot.name, name)
            device = self._names.register(key)  # an element of the poses' TDATA: no stream
            metadata = metadata_for(key, frame=fixed, units=UNITS_MM)
            metadata[KEY_PARENT] = fixed
            metadata[KEY_CHILD] = frame
            handle = self._tf.stream_lookup(fixed, frame, device=device, metadata=metadata,
                                            group=robot.poses_device)
            robot.links[name] = _Link(name, frame, key, device, handle)

    def _publish_visual(self, robot: _Robot, visual: VisualMesh) -> _VisualInfo:
        key = NameKey.robot_visual(robot.name, visual.link, visual.index)
        device = self._device(robot.request, key)
        metadata = metadata_for(key, units=UNITS_MM)
        metadata[KEY_PARENT_DEVICE] = robot.links[visual.link].device
        metadata[KEY_COLOR] = " ".join(f"{c:.6g}" for c in visual.rgba)
        from bridge.robots.model import to_polydata

        body: PolyData = to_polydata(visual)
        self._hub.publish_persistent(Message(device_name=device, body=body,
                                             metadata=metadata))
        return _VisualInfo(device, key, visual.link, visual.index, visual.name,
                           len(visual.vertices), len(visual.triangles),
                           tuple(float(c) for c in visual.rgba),  # type: ignore[arg-type]
                           visual.source)

    def _forget_links(self, robot: _Robot, names: set[str]) -> None:
        for name in names:
            link = robot.links.pop(name)
            self._tf.stop_lookup(link.handle)  # its element leaves the robot's TDATA
            self._names.release(link.key)

    # ------------------------------------------------------------------ plumbing

    def _device(self, request: CreateRobot, key: NameKey) -> str:
        """The device named `key`, one of the robot's: it goes to whom the robot's bridge
        goes (`Hub.bridge_device`). Every device of a robot is registered here."""
        device = self._names.register(key)
        self._hub.bridge_device(made_bridge(request), device)
        return device

    def _status(self, robot: _Robot, code: int, text: str,
                extra: Optional[dict[str, str]] = None) -> None:
        metadata = metadata_for(robot.description_key)
        metadata.update(extra or {})
        self._hub.stream(Message(device_name=robot.description_device,
                                 body=Status(code=code, error_name=_STATUS_NAME,
                                             text=text[:4000]),
                                 metadata=metadata))

    def _spawn(self, coroutine: Any) -> None:
        task = asyncio.ensure_future(coroutine)
        self._tasks.add(task)
        task.add_done_callback(self._task_done)

    def _task_done(self, task: asyncio.Task[None]) -> None:
        self._tasks.discard(task)
        if not task.cancelled() and task.exception() is not None:
            log.error("robot reload failed unexpectedly", exc_info=task.exception())

    def _devices_of(self, robot: _Robot) -> list[str]:
        devices = [link.device for link in robot.links.values()]
        devices += list(robot.visuals)
        devices += [robot.poses_device, robot.description_device]
        return devices

    def _drop(self, robot: _Robot) -> None:
        """Forget every device of the robot, stop its lookups and its description source."""
        robot.removed = True
        if self.robots.get(robot.name) is robot:
            del self.robots[robot.name]
            for listener in self.removed_listeners:
                listener(robot.name)
        self._forget_links(robot, set(robot.links))
        for device, info in {**robot.streamed, **robot.visuals}.items():
            self._hub.forget(device)
            self._names.release(info.key)
        robot.visuals, robot.streamed, robot.sent, robot.reading = {}, {}, {}, None
        self._tf.close_pose_group(robot.poses_device)
        for device, key in ((robot.poses_device, robot.poses_key),
                            (robot.description_device, robot.description_key)):
            self._hub.forget(device)
            self._names.release(key)

    # ------------------------------------------------------------------ capability

    def handlers(self) -> dict[type[Op], Handler]:
        return {
            CreateRobot: self.create_robot,
            RemoveRobot: lambda request, _: self.remove_robot(request),
            ListRobots: lambda request, _: self.list_robots(request),
            DescribeRobotJoints: lambda request, _: self.describe_robot_joints(request),
        }

    # ------------------------------------------------------------------ recording

    def recorded_topics(self) -> dict[str, str]:
        """What a bag needs to show each robot again (any thread): its joint states and,
        unless it came from a file, the description topic its state publisher latches
        (beside the node whose parameter holds it, as robot_state_publisher does)."""
        topics: dict[str, str] = {}
        for robot in tuple(self.robots.values()):
            topics[self._joint_states_topic(robot)] = JOINT_STATE_TYPE
            source = robot.source
            if source.kind == "topic":
                topics[source.topic] = _DESCRIPTION_TYPE
            elif source.kind == "parameter":
                topics[f"{_source_base(source)}/robot_description"] = _DESCRIPTION_TYPE
        return topics

    def mesh_files(self) -> dict[str, Path]:
        """The mesh files of the loaded robots, by their URI as the URDF writes it (any
        thread), resolved as their load did; those that did not resolve are left out."""
        files: dict[str, Path] = {}
        for robot in tuple(self.robots.values()):
            model = robot.model
            if model is None:
                continue
            try:
                base = (self._file_path(robot.source.path).parent
                        if robot.source.kind == "file" else None)
            except CommandFailedError:  # its URDF file is gone since it loaded
                continue
            resolver = PackageResolver(dict(self._package_paths), base_dir=base,
                                       allowed_roots=robot.mesh_roots)
            for link in model.description.links.values():
                for visual in link.visuals:
                    uri = visual.geometry.filename
                    if visual.geometry.kind != "mesh" or not uri or uri in files:
                        continue
                    try:
                        files[uri] = resolver.resolve(uri)
                    except RobotError:
                        continue
        return files

    # ------------------------------------------------------------------ joints

    def _loaded(self, name: str) -> tuple[_Robot, RobotModel]:
        robot = self.robots.get(name)
        if robot is None:
            raise CommandFailedError("name", "a robot created by create_robot", name,
                                     code=ErrorCode.NOT_FOUND)
        if robot.model is None:
            raise CommandFailedError("name", "a loaded robot", f"robot {name!r} "
                                     f"({robot.state}: {robot.reason or 'no URDF yet'})",
                                     code=ErrorCode.UNAVAILABLE)
        return robot, robot.model

    def loaded_model(self, name: str) -> tuple[RobotModel, str, str]:
        """A loaded robot's model, its joint-states topic and its root link's tf frame, for
        the capabilities that compute with it (motion); refused as `describe_robot_joints`
        refuses."""
        robot, model = self._loaded(name)
        return model, self._joint_states_topic(robot), robot.tf_prefix + model.root_link

    def describe_robot_joints(self, request: DescribeRobotJoints) -> DescribeRobotJointsResult:
        robot, model = self._loaded(request.name)
        return DescribeRobotJointsResult(robot.name, model.name,
                                         self._joint_states_topic(robot),
                                         tuple(describe_joints(model.joints)))

    def _unposed(self, robot: _Robot) -> Optional[dict[str, Any]]:
        """The links of a loaded robot tf cannot place in its fixed frame now, and why
        (None: all placed)."""
        return None

    def _summary(self, robot: _Robot) -> RobotSummary:
        return RobotSummary(
            "robot", robot.name, robot.state, robot.source, robot.fixed_frame or None,
            robot.tf_prefix, len(robot.links), len(robot.withheld), len(robot.visuals),
            robot.description_device, robot.loads, len(robot.warnings),
            namespace=robot.request.namespace or None, reason=robot.reason or None,
            unposed=self._unposed(robot))

    def _describe(self, robot: _Robot) -> CreatedRobot:
        model = robot.model
        return CreatedRobot(
            robot.name, robot.state, robot.source, robot.fixed_frame or None, robot.tf_prefix,
            model.name if model is not None else None,
            model.root_link if model is not None else None, robot.description_device,
            links=tuple({"link": link.link, "device": link.device, "frame": link.frame,
                         "visuals": list(link.visuals)} for link in robot.links.values()),
            visuals=tuple(info.to_dict() for info in robot.visuals.values()),
            withheld=tuple({"link": name, "frame": robot.tf_prefix + name, "reason": why}
                           for name, why in robot.withheld.items()),
            warnings=tuple(robot.warnings), reason=robot.reason or None,
            poses_device=robot.poses_device)

    def describe(self) -> list[dict[str, Any]]:
        return [self._summary(robot).to_dict() for robot in self.robots.values()]

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        for task in tuple(self._tasks):
            task.cancel()
        for robot in list(self.robots.values()):
            self._drop(robot)


class RobotBridges(RobotServing):
    """The daemon's robots: descriptions from a node's parameter, a latched topic or a
    file; `set_robot_joints` publishes joint states to ROS."""

    def __init__(self, ros: RosNode, hub: Hub, names: DeviceNameRegistry, *, tf: LookupStreams,
                 parameters: ParameterWatcher,
                 package_paths: Mapping[str, Path] | None = None,
                 topic_wait_s: float = _TOPIC_WAIT_S,
                 mesh_readers: Optional[MeshReaders] = None) -> None:
        super().__init__(hub, names, tf=tf, package_paths=package_paths,
                         mesh_readers=mesh_readers)
        self._ros = ros
        self._parameters = parameters
        self._topic_wait_s = topic_wait_s

    def handlers(self) -> dict[type[Op], Handler]:
        return {**super().handlers(),
                SetRobotJoints: lambda request, _: self.set_robot_joints(request)}

    # ------------------------------------------------------------------ sources

    async def _first_description(self, robot: _Robot) -> Optional[str]:
        """The URDF text now, or None (then ``robot.reason`` says what it waits for)."""
        source = robot.source
        if source.kind == "file":
            return None if robot.removed else "<file>"  # read by the loader (see _load)
        if source.kind == "parameter":
            robot.watch, value = await self._parameters.watch_parameter(
                source.node, source.parameter,
                lambda v: self._on_parameter(robot, v),
                ready_wait_s=None if robot.request.wait else _REFUSE_AFTER_S)
            if value is None:
                robot.reason = (f"parameter {source.parameter} of {source.node}: "
                                + (f"{robot.watch.unanswered}; asked again while the node is up"
                                   if robot.watch.unanswered else "node not available yet"))
                if not robot.watch.unanswered:  # a node that is there but slow still waits
                    _refuse_unless_waiting(robot, "source.node", f"a node on the ROS graph "
                                           f"holding parameter {source.parameter}",
                                           f"{source.node}: no such node (its parameter "
                                           f"services not found in {_REFUSE_AFTER_S:g} s)")
                return None
            return self._text_of(robot, value, initial=True)
        # topic
        from std_msgs.msg import String as StringMsg

        from bridge.ros.graph_types import refuse_other_type

        loop = asyncio.get_running_loop()
        robot.first_description = loop.create_future()
        refuse_other_type(self._ros, source.topic, _DESCRIPTION_TYPE, "source.topic")

        def on_message(msg: StringMsg) -> None:  # on an executor thread
            self._hub.call_soon(self._on_topic, robot, msg.data)

        robot.subscription = self._ros.node.create_subscription(
            StringMsg, source.topic, on_message, _description_qos())
        bound = self._topic_wait_s if robot.request.wait else _REFUSE_AFTER_S
        try:
            return await asyncio.wait_for(asyncio.shield(robot.first_description), bound)
        except asyncio.TimeoutError:
            robot.reason = f"topic {source.topic}: no description published yet"
            _refuse_unless_waiting(robot, "source.topic", "a URDF published (latched) on it",
                                   f"{source.topic}: nothing within {bound:g} s")
            return None

    def _text_of(self, robot: _Robot, value: ParameterValue, *, initial: bool,
                 ) -> Optional[str]:
        source = robot.source
        if value.type == "not_set":
            robot.reason = f"parameter {source.parameter} of {source.node}: not set yet"
            if initial:
                _refuse_unless_waiting(robot, "source.parameter", f"a parameter set on "
                                       f"{source.node}", f"{source.parameter}: not set")
            return None
        if value.type != "string":
            problem = CommandFailedError(
                "source.parameter", f"a string parameter holding URDF XML "
                f"({source.parameter} of {source.node})", f"a {value.type} parameter",
                code=ErrorCode.WRONG_TYPE)
            if initial:
                raise problem
            self._load_failed(robot, str(problem))
            return None
        return str(value.value)

    def _on_parameter(self, robot: _Robot, value: ParameterValue) -> None:
        """The watched parameter changed, or its node (re)appeared (loop thread)."""
        if robot.removed:
            return
        text = self._text_of(robot, value, initial=False)
        if text is not None:
            self._reload(robot, text)

    def _on_topic(self, robot: _Robot, text: str) -> None:
        """A description arrived on the robot's topic (loop thread)."""
        if robot.removed:
            return
        first = robot.first_description
        if first is not None and not first.done():
            first.set_result(text)  # create_robot is still waiting for it: it loads
            return
        self._reload(robot, text)

    def _drop(self, robot: _Robot) -> None:
        super()._drop(robot)
        if robot.watch is not None:
            self._parameters.unwatch_parameter(robot.watch)
            robot.watch = None
        if robot.subscription is not None:
            self._ros.destroy(robot.subscription)
            robot.subscription = None
        if robot.joint_publisher is not None:
            self._ros.destroy(robot.joint_publisher)
            robot.joint_publisher = None
        if robot.first_description is not None and not robot.first_description.done():
            robot.first_description.cancel()


    # ------------------------------------------------------------------ joints

    def _joint_states_topic(self, robot: _Robot) -> str:
        """Where this robot's state publisher listens: robot_state_publisher subscribes
        the relative ``joint_states``, so in the namespace of the node whose parameter
        holds the description (``/PSM1/robot_state_publisher`` -> ``/PSM1/joint_states``),
        of the description topic, or for a file the robot's namespace."""
        source = robot.source  # names already resolved (absolute)
        if source.kind == "parameter":
            base = source.node.rsplit("/", 1)[0]
        elif source.kind == "topic":
            base = source.topic.rsplit("/", 1)[0]
        else:
            namespace = robot.request.namespace.strip("/")
            return self._ros.resolve_name(f"{namespace}/joint_states" if namespace
                                          else "joint_states", "topic")
        return f"{base}/joint_states"

    def set_robot_joints(self, request: SetRobotJoints) -> SetRobotJointsResult:
        from sensor_msgs.msg import JointState

        from bridge.ros.graph_types import refuse_other_type

        robot, model = self._loaded(request.name)
        positions = joint_positions(model.joints, request.positions)
        topic = request.topic
        if robot.joint_publisher is None or robot.joint_topic != topic:
            if robot.joint_publisher is not None:
                self._ros.destroy(robot.joint_publisher)
                robot.joint_publisher = None
            refuse_other_type(self._ros, topic, _JOINT_STATES_TYPE, "topic")
            robot.joint_publisher = self._ros.node.create_publisher(
                JointState, topic, _joint_states_qos())
            robot.joint_topic = topic
        msg = JointState()
        msg.header.stamp = self._ros.node.get_clock().now().to_msg()
        msg.name = list(positions)
        msg.position = list(positions.values())
        robot.joint_publisher.publish(msg)
        return SetRobotJointsResult(robot.name, topic, positions,
                                    int(robot.joint_publisher.get_subscription_count()))

    def _unposed(self, robot: _Robot) -> Optional[dict[str, Any]]:
        """The links of a loaded robot tf cannot place in its fixed frame now, and why: a
        client whose wait for every link's transform timed out says the cause."""
        model = robot.model
        if model is None:
            return None
        missing = [name for name, link in robot.links.items()
                   if not self._tf.buffer.can_transform(robot.fixed_frame, link.frame)]
        if not missing:
            return None
        lacking = set(missing)
        # Where the tree breaks: the joints from a placed link to one that is not.
        moving = [joint.name for joint in model.joints.values()
                  if joint.child in lacking and joint.parent not in lacking and joint.moves]
        if moving:
            topic = self._joint_states_topic(robot)
            publishers = int(self._ros.node.count_publishers(topic))
            given = (f"nothing publishes joint states on {topic}" if not publishers else
                     f"{topic} has {publishers} publisher(s), which gave none of them yet")
            reason = (f"the links after moving joint(s) {', '.join(moving)} get tf from a "
                      f"state publisher only once it has those joints' states, and {given}")
        else:
            reason = (f"nothing placed them in tf from {robot.fixed_frame}: is a state "
                      f"publisher (robot_state_publisher) running for this URDF?")
        return {"links": missing, "reason": reason}


def _refuse_unless_waiting(robot: _Robot, field_name: str, expected: str,
                           got: str) -> None:
    """The description is not there (``got`` says what is missing): the robot waits for
    it, unless its request said not to (``"wait": false``)."""
    if not robot.request.wait:
        raise CommandFailedError(field_name, f"{expected} (or \"wait\": true to wait for "
                                 f"it)", got, code=ErrorCode.NOT_FOUND)


def _source_base(source: RobotSource) -> Optional[str]:
    """The namespace of the node or topic a description comes from (names resolved); None
    for a file."""
    if source.kind == "parameter":
        return source.node.rsplit("/", 1)[0]
    if source.kind == "topic":
        return source.topic.rsplit("/", 1)[0]
    return None


def _fixed_frame(robot: _Robot, model: RobotModel | RobotDescription) -> str:
    """The frame every link's pose is given in: the request's, else the prefixed root."""
    return (robot.request.fixed_frame or robot.tf_prefix + model.root_link).lstrip("/")


def _import_mesh_libraries() -> None:
    """trimesh and yourdfpy (0.1-0.2 s in a daemon, which leaves out trimesh's unused
    extras: `bridge.robots.mesh_extras`), imported off the loop while the first robot's
    description is fetched; `_read_robot` waits for them if they are not in yet."""
    try:
        import bridge.robots.model  # noqa: F401
    except Exception:  # noqa: BLE001 - the load itself imports again and says why
        log.debug("importing the mesh libraries failed", exc_info=True)


def _read_robot(text: str, **options: Any) -> RobotModel:
    """`load_robot` in a worker thread: the mesh libraries (trimesh, yourdfpy) are imported
    there, never on the loop, the first time."""
    from bridge.robots.model import load_robot

    return load_robot(text, **options)


def _read_robot_file(path: Path, **options: Any) -> RobotModel:
    """`load_robot_file` in a worker thread (see `_read_robot`)."""
    from bridge.robots.model import load_robot_file

    return load_robot_file(path, **options)


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()


def _source_text(source: RobotSource) -> str:
    if source.kind == "parameter":
        return f"parameter {source.parameter} of {source.node}"
    if source.kind == "topic":
        return f"topic {source.topic}"
    return f"file {source.path}"
