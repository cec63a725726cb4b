"""Wires the daemon together and runs it until SIGINT, SIGTERM or SIGHUP (then it exits
within ``--stop-timeout`` whatever ROS's teardown does: see `bridge.core.shutdown`).

    ROS executor thread                     asyncio loop (main thread)
    ───────────────────                     ──────────────────────────
    subscription callbacks ──convert──►  Hub ──► ClientSession ×N ──► TCP clients
                                          ▲
    publishers ◄── PublisherBridge ◄──────┴── Dispatcher ◄── COMMAND / data messages
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import tempfile
from pathlib import Path
from typing import Awaitable, Callable, Optional

from bridge.actions import ActionBridges
from bridge.config import DaemonConfig
from bridge.core.client_replies import ClientReplies
from bridge.core.dispatch import Dispatcher
from bridge.core.heavy import HeavyWork
from bridge.core.hub import Hub
from bridge.core.security import is_loopback_host, open_permissions
from bridge.core.server import BridgeServer
from bridge.core.shutdown import StopSignals
from bridge.core.threads import fatal_failure
from bridge.core.stream_health import StreamHealth
from bridge.markers.capability import MarkerBridges
from bridge.motion.capability import MotionBridges
from bridge.parameters.capability import ParameterBridges
from bridge.playback.refusals import LiveRefusals
from bridge.record.capability import RecordBridges
from bridge.robots.capability import RobotBridges
from bridge.robots.mesh_extras import leave_out_mesh_extras
from bridge.robots.mesh_readers import MeshReaders
from bridge.types import InterfaceTypes
from bridge.platform.receive_priority import (RECEIVE_SLICE_NS, ReceivePriorityError,
                                         raise_receive_threads, shorten_receive_slices)
from bridge.ros.ros_args import domain_id_from_environment
from bridge.ros.ros_node import RosNode, RosOptions
from bridge.platform.interpreter import settle_the_collector, shorten_gil_switches
from bridge.platform.shm_locks import ports_of_domains
from bridge.platform.shm_ports import ShmPortWatch
from bridge.services.capability import ServiceBridges
from bridge.tf.capability import TfBridges
from bridge.topics.capability import TopicBridges
from protocol.naming import DeviceNameRegistry
from protocol.errors import ProtocolError

log = logging.getLogger("bridge")

# How long after start the graph is watched for another node of the daemon's name (a
# second daemon on the same domain): discovery takes seconds on a busy machine.
NAMESAKE_WATCH_S = 10.0
_NAMESAKE_POLL_S = 0.25


class StartupError(Exception):
    """The daemon cannot start as configured (a bad start-up bridge, for example)."""


class ThreadFailedError(Exception):
    """A thread the daemon cannot do without failed (bridge/core/threads.py): it stopped."""


class Daemon:
    def __init__(self, config: DaemonConfig, loop: asyncio.AbstractEventLoop) -> None:
        self.config = config
        fast = config.fast_paths
        self.hub = Hub(loop, send_batch=fast.send_batch)
        # Decoding, conversions and listings too heavy for the loop: one lane per client.
        self.heavy = HeavyWork()
        self.ros = RosNode(RosOptions(node_name=config.node_name, namespace=config.namespace,
                                      ros_args=config.ros_args, rcl_take=fast.rcl_take))
        self._namesake: Optional[asyncio.Future[None]] = None
        names = DeviceNameRegistry()
        # Clients' robots may read files (URDF, meshes) from the --package-path folders too.
        # Who may write depends on where the daemon listens (see SecurityPolicy.grant_at_accept).
        # Clients' recordings write only in --record-dir folders (default: the temp folder).
        policy = dataclasses.replace(config.security, robot_dirs=config.security.robot_dirs
                                     + tuple(folder for _, folder in config.package_paths),
                                     record_dirs=(config.security.record_dirs
                                                  or (tempfile.gettempdir(),)),
                                     beyond_loopback=not is_loopback_host(config.host))
        self.policy = policy
        # Streams that go stale (publisher gone, silent past their period) are said so.
        self.health = StreamHealth(self.hub, loop)
        # ROS data Fast DDS loses in a replaced shared-memory port is said so in the log.
        self.shm_ports = ShmPortWatch(
            lock_ports=ports_of_domains([domain_id_from_environment()]))
        # No capability gets the policy: the dispatcher judges each request and hands a
        # handler the guard for the content its op declares (bridge.core.content_guards).
        self.topics = TopicBridges(self.ros, self.hub, names, health=self.health)
        self.tf = TfBridges(self.ros, self.hub, names, frame_prefix=config.frame_prefix,
                            compiled_store=None if fast.compiled_tf else False)
        self.parameters = ParameterBridges(self.ros, self.hub, names)
        # One correlator for the COMMANDs sent to clients: its command ids never collide.
        replies = ClientReplies(self.hub)
        self.services = ServiceBridges(self.ros, self.hub, names, replies=replies)
        self.actions = ActionBridges(self.ros, self.hub, names, replies=replies)
        # An action's hidden cancel service obeys cancel_goal's ownership rule.
        self.services.add_call_guard(self.actions.sender.judge_service_call)
        # The daemon node's own parameters obey server_set_parameter's rule there too.
        self.services.add_call_guard(self.parameters.judge_service_call)
        package_paths = {name: Path(folder) for name, folder in config.package_paths}
        # Robots' mesh files parsed in processes of their own, from the first robot on.
        self.mesh_readers = MeshReaders()
        self.robots = RobotBridges(self.ros, self.hub, names, tf=self.tf,
                                   parameters=self.parameters,
                                   package_paths=package_paths,
                                   mesh_readers=self.mesh_readers)
        self.markers = MarkerBridges(self.ros, self.hub, names, tf=self.tf,
                                     package_paths=package_paths,
                                     max_model_bytes=policy.max_marker_bytes)
        self.recordings = RecordBridges(
            self.ros, sources=[self.tf, self.topics, self.markers, self.robots],
            meshes=self.robots)
        # Motion computes with the robots' models: handed the robots' public lookup only.
        self.motion = MotionBridges(self.ros, robots=self.robots.loaded_model,
                                    frames=self.tf.buffer.lookup,
                                    send_goal=self.actions.sender.send_goal)
        self.robots.removed_listeners.append(self.motion.robot_removed)
        self.robots.loaded_listeners.append(self.motion.robot_loaded)
        self.dispatcher = Dispatcher(self.ros, self.hub, [self.topics, self.tf, self.parameters,
                                                          self.services, self.actions,
                                                          self.robots, self.markers,
                                                          self.motion, InterfaceTypes(),
                                                          self.recordings, LiveRefusals()],
                                     policy=policy, resolve_frame=self.tf.resolve_client_frame,
                                     resolve_file=self.robots.file_path, heavy=self.heavy)
        self.server = BridgeServer(self.hub, self.dispatcher.handle, host=config.host,
                                   port=config.port, limits=config.limits,
                                   policy=policy, heavy=self.heavy, tls=config.tls)

    @staticmethod
    def _schedule_receive_threads(priority: Optional[int], *, short_slice: bool) -> str:
        """SCHED_FIFO at ``priority``, else a short slice (unless not ``short_slice``); what
        to log once the daemon is up (a start that fails says its error alone)."""
        if priority is None and not short_slice:
            return "DDS receive threads on the kernel's usual slice (--without receive-slice)"
        if priority is None:
            names = shorten_receive_slices()
            if not names:
                return ("DDS receive threads on the kernel's usual slice (a shorter one needs "
                        "Linux 6.12 or later)")
            return (f"DDS receive threads on a {RECEIVE_SLICE_NS / 1e6:.1f} ms scheduler "
                    f"slice: {', '.join(names)}")
        try:
            names = raise_receive_threads(priority)
        except ReceivePriorityError as error:
            raise StartupError(str(error)) from None
        return f"DDS receive threads under SCHED_FIFO at priority {priority}: {', '.join(names)}"

    async def start(self) -> None:
        try:
            # The port is bound first (one in use is the first error), but no client is
            # accepted before the operator's bridges exist: a client could otherwise race
            # them (own one, remove one, make one fail with another type).
            await self.server.start(serving=False)
            self.ros.start()
            scheduling = self._schedule_receive_threads(
                self.config.receive_priority, short_slice="receive-slice" not in
                self.config.without)
            self.shm_ports.start()
            for command in self.config.startup:
                try:
                    await self.dispatcher.execute(command.op, command.arguments)
                except ProtocolError as error:
                    raise StartupError(f"{command.where}: {error}") from None
            await self.server.serve()
        except BaseException:
            await self.stop()
            raise
        log.info("%s", scheduling)
        if self.config.without:
            log.info("host workarounds left out (--without): %s",
                     ", ".join(sorted(self.config.without)))
        log.info("listening on %s:%d (OpenIGTLink); ROS node %s", self.config.host,
                 self.server.port, self.ros.fully_qualified_name)
        if self.config.tls is not None:
            log.info("listening on %s:%d (OpenIGTLink over TLS)", self.config.host,
                     self.server.tls_port)
        log.info("security: %s", self.policy.describe())
        secrets = [("--key-file", self.policy.key_path),
                   ("--tls-key", self.config.tls.key_file if self.config.tls else None)]
        for what, path in secrets:
            warning = open_permissions(path, what) if path else None
            if warning is not None:
                log.warning("%s", warning)
        log.info("tf buffer on the %s", self.tf.store_in_use())
        log.info("streams written to clients %s", self.hub.send_mode())
        self._namesake = asyncio.ensure_future(self._warn_of_a_namesake())

    async def _warn_of_a_namesake(self) -> None:
        """One warning if another node of this daemon's name is on the graph: two daemons
        on one ROS domain are both /slicer_bridge, and a peer cannot tell them apart."""
        node = self.ros.node
        own = (node.get_name(), node.get_namespace())
        deadline = asyncio.get_running_loop().time() + NAMESAKE_WATCH_S
        while asyncio.get_running_loop().time() < deadline:
            if node.get_node_names_and_namespaces().count(own) > 1:
                log.warning("another node named %s is on the ROS graph (ROS_DOMAIN_ID %s): "
                            "a second daemon? Peers cannot tell the two apart; start this "
                            "one with --node-name, or on another ROS_DOMAIN_ID",
                            self.ros.fully_qualified_name,
                            domain_id_from_environment())
                return
            await asyncio.sleep(_NAMESAKE_POLL_S)

    async def stop(self) -> None:
        if self._namesake is not None:
            self._namesake.cancel()
        await self.server.close()
        self.health.close()
        self.shm_ports.close()
        self.dispatcher.close()
        self.heavy.close()
        self.mesh_readers.close()
        self.ros.stop()


async def run_daemon(config: DaemonConfig,
                     started: Optional[Callable[[Daemon], Awaitable[None]]] = None, *,
                     stopping: Optional[Callable[[], None]] = None) -> None:
    """Run until SIGINT/SIGTERM/SIGHUP; `started` runs once the daemon serves and
    `stopping` when the stop begins (used by `demo`). After the signal the process ends
    within ``config.stop_timeout_s``."""
    if "gil-switch" not in config.without:
        shorten_gil_switches()
    leave_out_mesh_extras()  # before any thread imports trimesh (a first robot, a mesh marker)
    loop = asyncio.get_running_loop()
    signals = StopSignals(loop, timeout_s=config.stop_timeout_s)
    signals.install()
    daemon = Daemon(config, loop)
    await daemon.start()
    if "collector" not in config.without:
        settle_the_collector()
    try:
        if started is not None:
            await started(daemon)
        await signals.requested.wait()
        log.info("shutting down (%s)", signals.signal_name)
    finally:
        signals.watchdog.start()  # an error ends the run too: its teardown is bounded alike
        if stopping is not None:
            stopping()
        await daemon.stop()
    failure = fatal_failure()
    if failure is not None:
        raise ThreadFailedError(failure)
