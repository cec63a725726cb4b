"""`slicer-ros2-bridge demo`: the daemon, the built-in demo robot moving, and a banner.

What runs (all stopped by one Ctrl-C):

- the daemon (`bridge.daemon.run_daemon`), with the demo package on its package path;
- ``python -m bridge.robots.state_publisher <demo urdf>`` (``/robot_state_publisher``:
  robot_description, /tf from joint_states, /tf_static);
- ``python -m bridge.robots.demo.joint_motion`` (joint_states, every joint swinging, and a
  control_msgs/action/FollowJointTrajectory server on
  ``/joint_trajectory_controller/follow_joint_trajectory`` that moves the joints, pausing
  the swinging while a goal runs: `bridge.robots.demo.trajectory`);
- the robot ``demo``, created in the daemon from ``/robot_state_publisher``'s
  ``robot_description`` parameter, as a user would with ``create_robot``.

The children run in their own process groups: a terminal's Ctrl-C (or hang-up) reaches the
daemon only, which then stops them itself (SIGINT, then SIGKILL after a grace period), so a
child's exit during shutdown is never mistaken for a crash. Whatever ends the demo, its
children end with it: SIGINT, SIGTERM and SIGHUP stop them as above, and if the demo
process is killed outright each child notices its parent is gone (`bridge.robots._spin`:
PR_SET_PDEATHSIG on Linux, a parent-pid check everywhere) and stops. A child that dies
while the demo runs is logged at ERROR with its exit code and last output lines; the
daemon keeps serving.
"""

from __future__ import annotations

import asyncio
import collections
import dataclasses
import logging
import os
import signal
import sys
from pathlib import Path
from typing import Optional

from bridge.config import DaemonConfig
from bridge.daemon import Daemon, run_daemon
from bridge.robots._spin import PARENT_PID_ENV
from bridge.ros.ros_args import domain_id_from_environment

__all__ = ["DemoChildren", "run_demo"]

log = logging.getLogger("bridge.demo")

_READY_TIMEOUT_S = 30.0
_STOP_GRACE_S = 5.0
_TAIL_LINES = 20


@dataclasses.dataclass(eq=False)
class _Child:
    name: str
    argv: list[str]
    ready_text: str
    process: Optional[asyncio.subprocess.Process] = None
    tail: collections.deque[str] = dataclasses.field(
        default_factory=lambda: collections.deque(maxlen=_TAIL_LINES))
    ready: Optional[asyncio.Future[None]] = None
    watcher: Optional[asyncio.Task[None]] = None


class DemoChildren:
    """The demo's child processes: started, supervised, stopped."""

    def __init__(self, urdf: Path, packages: dict[str, Path]) -> None:
        package_args = [f"--package-path={name}={folder}" for name, folder in packages.items()]
        self.children = [
            _Child("state publisher", [sys.executable, "-u", "-m",
                                       "bridge.robots.state_publisher", str(urdf),
                                       *package_args], "ready"),
            _Child("joint motion", [sys.executable, "-u", "-m",
                                    "bridge.robots.demo.joint_motion", str(urdf),
                                    *package_args], "joint motion ready"),
        ]
        self._stopping = False

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        for child in self.children:
            child.ready = loop.create_future()
            child.process = await asyncio.create_subprocess_exec(
                *child.argv, stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.STDOUT, start_new_session=True,
                env={**os.environ, PARENT_PID_ENV: str(os.getpid())})
            child.watcher = asyncio.ensure_future(self._watch(child))
            log.debug("demo: started %s (pid %d)", child.name, child.process.pid)
        for child in self.children:
            assert child.ready is not None
            try:
                await asyncio.wait_for(asyncio.shield(child.ready), _READY_TIMEOUT_S)
            except asyncio.TimeoutError:
                log.error("demo: the %s did not report ready within %g s; its output:\n%s",
                          child.name, _READY_TIMEOUT_S, "\n".join(child.tail))

    async def _watch(self, child: _Child) -> None:
        """Read the child's output (kept for error reports), notice ready, report a death."""
        process = child.process
        assert process is not None and process.stdout is not None
        async for raw in process.stdout:
            line = raw.decode(errors="replace").rstrip()
            child.tail.append(line)
            log.debug("%s: %s", child.name, line)
            if child.ready is not None and not child.ready.done() and \
                    child.ready_text in line:
                child.ready.set_result(None)
        code = await process.wait()
        if child.ready is not None and not child.ready.done():
            child.ready.set_result(None)  # stop waiting: it is gone
        if not self._stopping:
            log.error("demo: the %s (pid %d) exited with code %s; the robot stops moving. "
                      "Its last output:\n%s", child.name, process.pid, code,
                      "\n".join(child.tail) or "(none)")

    def request_stop(self) -> None:
        """Ask every child to stop (SIGINT to its group) without waiting. Idempotent."""
        if self._stopping:
            return
        self._stopping = True
        for child in self.children:
            if child.process is not None and child.process.returncode is None:
                try:
                    os.killpg(child.process.pid, signal.SIGINT)
                except ProcessLookupError:
                    pass

    async def stop(self) -> None:
        self.request_stop()
        for child in self.children:
            process = child.process
            if process is None:
                continue
            try:
                await asyncio.wait_for(process.wait(), _STOP_GRACE_S)
            except asyncio.TimeoutError:
                log.warning("demo: the %s did not stop within %g s: killed", child.name,
                            _STOP_GRACE_S)
                try:
                    os.killpg(process.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                await process.wait()
            if child.watcher is not None:
                await child.watcher


def _banner(daemon: Daemon, robot: dict[str, object]) -> str:
    host, port = daemon.config.host, daemon.server.port
    state = robot.get("state")
    links = robot.get("links")
    visuals = robot.get("visuals")
    if state == "loaded" and isinstance(links, list) and isinstance(visuals, list):
        robot_line = (f"robot 'demo': {len(links)} links, {len(visuals)} meshes, "
                      f"moving (devices demo:<link> and demo:<link>:<n>)")
    else:
        robot_line = f"robot 'demo': {state} ({robot.get('reason', '')})"
    domain = domain_id_from_environment()
    return "\n".join([
        "",
        "slicer-ros2-bridge demo is running",
        f"  OpenIGTLink server  {host}:{port} (any number of clients)",
        f"  ROS 2               node {daemon.ros.fully_qualified_name}, ROS_DOMAIN_ID={domain};",
        "                      /robot_state_publisher and a joint motion node; move the arm",
        "                      with FollowJointTrajectory goals on",
        "                      /joint_trajectory_controller/follow_joint_trajectory",
        f"  {robot_line}",
        "",
        "Connect 3D Slicer: module OpenIGTLinkIF > '+' (new connector) > Type: Client,",
        f"  Hostname {host}, Port {port} > Active. Each link mesh arrives as a model, each",
        "  link pose as a transform (the ROS2Bridge module of slicer_client parents them).",
        "Or from Python:",
        f"  import slicer_client; ros = slicer_client.connect('{host}', {port})",
        "  robot = ros.robot('demo'); print(sorted(robot.links))",
        "  robot.set_joints({'joint_2': 0.8})  # the motion yields for 3 s to set joints",
        "",
        "Stop with Ctrl-C.",
        "",
    ])


async def run_demo(config: DaemonConfig) -> None:
    """The `demo` subcommand's main (`bridge.cli` runs it with the parsed configuration)."""
    from bridge.robots.demo import demo_urdf_path

    urdf, packages = demo_urdf_path()
    config = dataclasses.replace(config, package_paths=tuple(config.package_paths) + tuple(
        (name, str(folder)) for name, folder in packages.items()))
    children = DemoChildren(urdf, packages)

    async def started(daemon: Daemon) -> None:
        await children.start()
        robot = await daemon.dispatcher.execute(
            "create_robot", {"name": "demo", "source": {"kind": "parameter"}})
        if robot.get("state") != "loaded":  # the node's services are still being discovered
            robot = await daemon.robots.wait_loaded("demo", _READY_TIMEOUT_S)
        print(_banner(daemon, dict(robot)), flush=True)

    try:
        # The children stop alongside the daemon's own teardown, not after it.
        await run_daemon(config, started=started, stopping=children.request_stop)
    finally:
        await children.stop()
