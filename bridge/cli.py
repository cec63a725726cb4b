"""The `slicer-ros2-bridge` command line: `run`, `demo`, `record`, `play`, `state-publisher`."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import logging
import os
import sys
from pathlib import Path
from typing import Any, Callable, Coroutine, TypeVar

from bridge import graph_inspect
from bridge.config import (DEFAULT_HOST, DEFAULT_PORT, DEFAULT_TLS_PORT, ConfigError,
                           WORKAROUNDS, DaemonConfig, FastPaths, TlsListener)
from bridge.config import ConfigFile, build_security, load_config_file
from bridge.platform.allocator import keep_large_buffers_returnable
from bridge.interfaces import missing_runtime_line
from bridge.record import cli as record_cli
from protocol.auth import new_key_text
from bridge.core.security import (DEFAULT_MAX_BRIDGES, DEFAULT_MAX_BRIDGES_PER_CLIENT,
                                  DEFAULT_MAX_CLIENTS)
from bridge.platform.receive_priority import MAX_PRIORITY, MIN_PRIORITY
from bridge.ros.ros_args import RosArgsError, apply_parameters, split_ros_args
from bridge.platform.shm_locks import (MAX_STUCK_AFTER_S, MIN_STUCK_AFTER_S, STUCK_AFTER_S,
                                  release_stuck, remove_dead_segments, remove_unfinished)

LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")

T = TypeVar("T", int, float)


def _package_path(text: str) -> tuple[str, str]:
    name, sep, folder = text.partition("=")
    if not sep or not name or not folder:
        raise argparse.ArgumentTypeError(f"expected NAME=DIR, got {text!r}")
    return name, folder


def _lock_wait(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not MIN_STUCK_AFTER_S <= value <= MAX_STUCK_AFTER_S:
        raise argparse.ArgumentTypeError(
            f"expected seconds from {MIN_STUCK_AFTER_S:g} to {MAX_STUCK_AFTER_S:g} (a lock "
            f"taken for less may only be busy), got {text!r}")
    return value


def _positive(kind: Callable[[str], T]) -> Callable[[str], T]:
    def parse(text: str) -> T:
        try:
            value = kind(text)
        except ValueError:
            value = None
        if value is None or not value > 0:
            raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
        return value
    parse.__name__ = kind.__name__  # argparse names the type in its own errors
    return parse


def _add_daemon_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", default=DEFAULT_HOST,
                        help=f"address to listen on (default {DEFAULT_HOST}: this machine only)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT,
                        help=f"OpenIGTLink TCP port (default {DEFAULT_PORT}, Slicer's default)")
    parser.add_argument("--config", type=Path, metavar="FILE",
                        help="YAML file of bridges to create at start-up (see README)")
    parser.add_argument("--node-name", default="slicer_bridge",
                        help="name of the daemon's ROS node (default slicer_bridge)")
    parser.add_argument("--namespace", default="", help="ROS namespace of the daemon's node")
    parser.add_argument("--log-level", default="INFO", type=str.upper, choices=LOG_LEVELS)
    parser.add_argument("--package-path", type=_package_path, action="append", default=[],
                        metavar="NAME=DIR",
                        help="where package://NAME/... URIs of robot meshes point (repeatable)")
    parser.add_argument("--robot-dir", action="append", default=[], metavar="DIR",
                        help="a folder whose URDF files clients may load by path "
                             "(create_robot from a file; repeatable). --package-path folders "
                             "count too; nothing else on this machine can be read")
    parser.add_argument("--record-dir", action="append", default=[], metavar="DIR",
                        help="a folder clients' recordings (start_recording, ros.record) may "
                             "write bags in (repeatable; default: the system's temporary "
                             "folder). Nowhere else on this machine can be written")
    parser.add_argument("--frame-prefix", default="", metavar="PREFIX",
                        help="tf prefix of the robot instance this daemon serves, trailing / "
                             "included (PSM1/): a client's relative frame id 'base' means "
                             "'PSM1/base'; a leading / opts out ('/world' is 'world', "
                             "'/PSM1/base' is 'PSM1/base'). One daemon per instance (PSM1/, "
                             "PSM2/) lets the same client code serve each. Applies to tf "
                             "lookups and broadcasters (and what --allow-frame judges), not "
                             "to robot models: give create_robot a tf_prefix")
    security = parser.add_argument_group(
        "security", "Who may connect and who may change ROS (docs/deployment.md): lock the "
                    "daemon down with these (also "
                    "a `security:` section in --config; lists add up, limits given here win). "
                    "See docs/security.md.")
    security.add_argument("--allow", action="append", default=[], metavar="CIDR",
                          help="accept clients only from this IPv4/IPv6 address or block "
                               "(repeatable; others are closed at once and logged)")
    security.add_argument("--key-file", metavar="FILE",
                          help="writers' key (make it with `slicer-ros2-bridge keygen FILE`): "
                               "a connection may change ROS only once it presents this key "
                               "(slicer_client: connect(key_file=...)), or if it comes from a "
                               "--trust network. Without a key, a daemon listening beyond "
                               "loopback lets only this machine's connections write")
    security.add_argument("--trust", action="append", default=[], metavar="CIDR",
                          help="plain connections (3D Slicer's OpenIGTLinkIF cannot present a "
                               "key) from this address or block may write (repeatable)")
    security.add_argument("--tls-cert", metavar="PEM",
                          help="certificate chain for a TLS listener on --tls-port (the "
                               "project's own clients: connect(tls=True)); with --tls-key")
    security.add_argument("--tls-key", metavar="PEM", help="the private key of --tls-cert")
    security.add_argument("--tls-port", type=int, default=DEFAULT_TLS_PORT, metavar="PORT",
                          help=f"port of the TLS listener (default {DEFAULT_TLS_PORT})")
    security.add_argument("--read-only", action="store_true", default=False,
                          help="clients can only receive: publishing, tf broadcasts, "
                               "parameter changes, service calls and action goals are refused "
                               "(FORBIDDEN)")
    for kind in ("topic", "service", "action", "parameter", "frame"):
        what = {"parameter": "NODE.PARAM", "frame": "PSM1/"}.get(kind, f"/{kind}")
        # Frames: both ends of tf lookups and broadcasters, without a leading / and with
        # --frame-prefix applied.
        label = "tf frame" if kind == "frame" else kind
        security.add_argument(f"--allow-{kind}", action="append", default=[], metavar="GLOB",
                              help=f"allow only {label}s matching a glob like {what}* "
                                   f"(repeatable)")
        security.add_argument(f"--deny-{kind}", action="append", default=[], metavar="GLOB",
                              help=f"refuse {label}s matching this glob; deny wins over allow "
                                   f"(repeatable)")
    security.add_argument("--max-clients", type=int, metavar="N",
                          help=f"extra clients get a STATUS and are closed "
                               f"(default {DEFAULT_MAX_CLIENTS})")
    security.add_argument("--max-bridges-per-client", type=int, metavar="N",
                          help=f"bridges one client may create (default "
                               f"{DEFAULT_MAX_BRIDGES_PER_CLIENT}); more get LIMIT_REACHED")
    security.add_argument("--max-bridges", type=int, metavar="N",
                          help=f"bridges all clients together may have made and not removed "
                               f"(default {DEFAULT_MAX_BRIDGES}; they outlive their client, "
                               f"so reconnecting does not reset it); more get LIMIT_REACHED")
    security.add_argument("--max-message-bytes", type=int, metavar="BYTES",
                          help="largest message body a client may send (default 64 MiB); a "
                               "larger BODY_SIZE closes the connection")
    security.add_argument("--max-send-buffer-bytes", type=int, metavar="BYTES",
                          help="unsent one-shot bytes (meshes, replies) a client may let pile "
                               "up before it is closed as too slow (default 256 MiB)")
    security.add_argument("--max-marker-bytes", type=int, metavar="BYTES",
                          help="bytes of marker models the daemon keeps, all marker topics "
                               "together (default 256 MiB; one topic may hold half); a "
                               "marker whose model would not fit is refused before it is "
                               "made")
    security.add_argument("--max-receive-buffer-bytes", type=_positive(int), metavar="BYTES",
                          help="bytes of partly received message bodies all clients together "
                               "may hold (default twice --max-message-bytes); a body that "
                               "does not fit gets a STATUS and its connection is closed")
    security.add_argument("--frame-deadline", type=_positive(float), metavar="SECONDS",
                          help="a message whose first byte has arrived must be complete this "
                               "long after (plus 1 s per 8 MiB of its body), or the "
                               "connection is closed (default 5); clients that only receive "
                               "are not affected")
    parser.add_argument("--stop-timeout", type=_positive(float), metavar="SECONDS",
                        default=DaemonConfig.stop_timeout_s,
                        help="on SIGTERM/SIGINT/SIGHUP, exit after this long even if ROS's "
                             "teardown has not finished (logged); a second signal exits at "
                             f"once (default {DaemonConfig.stop_timeout_s:g})")
    parser.add_argument("--receive-priority", type=_receive_priority, metavar="1-99",
                        help="run the DDS receive threads under SCHED_FIFO at this priority: "
                             "a message larger than the publisher's shared-memory segment "
                             "(a VGA image with Fast DDS's defaults) then reaches the daemon "
                             "without a resend's 10 ms, whatever else runs. Needs "
                             "CAP_SYS_NICE or `ulimit -r` at least this high")
    parser.add_argument("--without", action="append", choices=WORKAROUNDS, default=[],
                        metavar="WORKAROUND",
                        help="leave out a host workaround, to weigh it (repeatable; "
                             "bridge/platform/README.md says what each wins): receive-slice "
                             "(the DDS receive threads' short scheduler slice), gil-switch "
                             "(a 0.5 ms GIL switch interval), collector (start-up frozen, "
                             "rarer collections), mmap-threshold (glibc's fixed at 4 MiB)")
    paths = parser.add_argument_group(
        "fast paths", "each compiled path has a slower twin with the same results: turn one "
                      "off to compare them, or to rule it out (bridge/platform/README.md)")
    paths.add_argument("--tf-store", choices=("compiled", "python"), default="compiled",
                       help="where the tf buffer keeps its samples: the compiled store "
                            "(default, where built) or the pure-Python one")
    paths.add_argument("--ros-take", choices=("rcl", "rclpy"), default="rcl",
                       help="how subscriptions are taken: by rcl in reader threads, without "
                            "the interpreter's lock, poses written to clients from there "
                            "(default, where built), or through rclpy's executor")
    paths.add_argument("--send-batch", choices=("on", "off"), default="on",
                       help="a streamed message to every client in one io_uring call "
                            "(default, where the system allows) or one sendmsg per client")


def _receive_priority(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not MIN_PRIORITY <= value <= MAX_PRIORITY:
        raise argparse.ArgumentTypeError(
            f"expected a SCHED_FIFO priority from {MIN_PRIORITY} to {MAX_PRIORITY}, got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="slicer-ros2-bridge",
        description="Bridge ROS 2 (topics, parameters, tf2, services, robots) and 3D Slicer "
                    "over OpenIGTLink. Connect 3D Slicer's OpenIGTLinkIF (client mode) to "
                    "the daemon's host and port.",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    run = commands.add_parser("run", help="run the bridge daemon",
                              description="Run the bridge daemon: one ROS node, an "
                                          "OpenIGTLink server for any number of clients.")
    _add_daemon_options(run)
    demo = commands.add_parser("demo", help="run the daemon with the built-in demo robot",
                               description="Run the daemon with the built-in demo robot "
                                           "moving (state publisher and joint motion included).")
    _add_daemon_options(demo)
    graph_inspect.add_parsers(commands)
    record_cli.add_parser(commands)
    _add_build_interfaces_parser(commands)
    keygen = commands.add_parser("keygen", help="make a writers' key file (--key-file)",
                                 description="Write a new random key (32 bytes, hex) to FILE, "
                                             "readable by its owner only. Give the daemon "
                                             "--key-file FILE and each writer's machine a "
                                             "copy (docs/deployment.md).")
    keygen.add_argument("file", type=Path, metavar="FILE")
    keygen.add_argument("--force", action="store_true", help="replace an existing FILE")
    unlock = commands.add_parser(
        "shm-unlock", help="release Fast DDS shared-memory port locks a killed ROS process "
                           "left taken (ROS processes then hang at start-up)",
        description="Release the Fast DDS shared-memory port locks that stay taken for "
                    "--wait seconds, and remove the port segments never finished that "
                    "are older: a ROS process killed while opening or making a port "
                    "(kill -9, a crash) leaves them, and every later ROS process that "
                    "opens that port, the bridge too, hangs at start-up or on its first "
                    "message to a peer. Also remove the segments of killed ROS processes, "
                    "which Fast DDS leaves in /dev/shm (RAM) for good.")
    unlock.add_argument("--wait", type=_lock_wait, default=STUCK_AFTER_S, metavar="SECONDS",
                        help="how long a lock must stay taken to be released "
                             f"(default {STUCK_AFTER_S:g}; Fast DDS holds one at most "
                             "about a second)")
    # Parsed by its own module (it runs on its own too); listed here for --help.
    commands.add_parser("state-publisher", add_help=False,
                        help="a robot state publisher for any URDF (robot_description, /tf "
                             "from joint_states, /tf_static); see state-publisher --help")
    commands.add_parser("play", add_help=False,
                        help="serve a ROS 2 bag (MCAP) to 3D Slicer, without ROS; see "
                             "play --help")
    return parser


def _config_from(args: argparse.Namespace) -> DaemonConfig:
    file = load_config_file(args.config) if args.config else ConfigFile()
    # The command line in the keys of the config's `security:` section: one parser for both.
    cli = {"read_only": args.read_only, "allow": args.allow,
           "allow_topics": args.allow_topic, "deny_topics": args.deny_topic,
           "allow_services": args.allow_service, "deny_services": args.deny_service,
           "allow_actions": args.allow_action, "deny_actions": args.deny_action,
           "allow_parameters": args.allow_parameter, "deny_parameters": args.deny_parameter,
           "allow_frames": args.allow_frame, "deny_frames": args.deny_frame,
           "max_clients": args.max_clients, "max_bridges_per_client": args.max_bridges_per_client,
           "max_bridges": args.max_bridges,
           "max_message_bytes": args.max_message_bytes,
           "max_send_buffer_bytes": args.max_send_buffer_bytes,
           "max_marker_bytes": args.max_marker_bytes, "robot_dirs": args.robot_dir,
           "record_dirs": args.record_dir,
           "key_file": args.key_file, "trust": args.trust}
    where = f"{file.name}: security (or its command-line option)" if file.name else "option"
    security, limits = build_security(file.security, cli, where)
    if args.max_receive_buffer_bytes is not None:
        if args.max_receive_buffer_bytes < limits.max_message_bytes:
            raise ConfigError(f"--max-receive-buffer-bytes: expected at least "
                              f"--max-message-bytes ({limits.max_message_bytes}), got "
                              f"{args.max_receive_buffer_bytes}")
        limits = dataclasses.replace(limits, receive_budget_bytes=args.max_receive_buffer_bytes)
    if args.frame_deadline is not None:
        limits = dataclasses.replace(limits, frame_deadline_s=args.frame_deadline)
    tls = None
    if args.tls_cert or args.tls_key:
        if not (args.tls_cert and args.tls_key):
            raise ConfigError("--tls-cert and --tls-key: expected both, got one")
        tls = TlsListener(args.tls_cert, args.tls_key, args.tls_port)
        tls.context()  # a bad file stops the start here, in one line
    return DaemonConfig(host=args.host, port=args.port, node_name=args.node_name,
                        namespace=args.namespace, log_level=args.log_level, startup=file.startup,
                        package_paths=tuple(args.package_path), security=security,
                        limits=limits, frame_prefix=args.frame_prefix,
                        ros_args=tuple(getattr(args, "ros_args", ())),
                        stop_timeout_s=args.stop_timeout, tls=tls,
                        receive_priority=args.receive_priority,
                        fast_paths=FastPaths(compiled_tf=args.tf_store == "compiled",
                                             rcl_take=args.ros_take == "rcl",
                                             send_batch=args.send_batch == "on"),
                        without=frozenset(args.without))


def _configure_logging(level: str) -> None:
    logging.basicConfig(level=getattr(logging, level), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def run_with_config(args: argparse.Namespace,
                    main: Callable[[DaemonConfig], Coroutine[Any, Any, None]]) -> int:
    """Build the config from the options, set up logging, run `main(config)`; what stops
    the start (bad config, port in use, a bad start-up bridge) is one line and exit 2."""
    from bridge.core.server import PortInUseError
    from bridge.daemon import StartupError, ThreadFailedError
    from bridge.ros.ros_node import RosArgumentsError

    try:
        config = _config_from(args)
    except ConfigError as error:
        print(f"slicer-ros2-bridge: {error}", file=sys.stderr)
        return 2
    _configure_logging(config.log_level)
    if "mmap-threshold" not in config.without:
        keep_large_buffers_returnable()  # before ROS starts its threads
    try:
        asyncio.run(main(config))
    except PortInUseError as error:
        print(f"slicer-ros2-bridge: {error.strerror}", file=sys.stderr)
        return 2
    except (StartupError, RosArgumentsError) as error:
        print(f"slicer-ros2-bridge: {error}", file=sys.stderr)
        return 2
    except ThreadFailedError as error:
        print(f"slicer-ros2-bridge: stopped: {error}", file=sys.stderr)
        return 1
    return 0


def _subparser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    for action in parser._actions:  # noqa: SLF001 - argparse keeps subparsers there
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
            return action.choices[command]  # type: ignore[no-any-return]
    raise LookupError(command)


def _add_build_interfaces_parser(
        commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    build = commands.add_parser(
        "build-interfaces", help="build ROS 2 interface packages (msg/srv/action) into this "
                                 "environment; without PATH, the ones the daemon ships",
        description="Build ROS 2 interface packages (a folder with package.xml and a "
                    "CMakeLists.txt calling rosidl_generate_interfaces, with msg/, srv/, "
                    "action/) into this Python environment, so that Python and the daemon "
                    "can use their types: the ROS 2 wheels from PyPI cannot build them "
                    "themselves. Dependencies are built first (package.xml <depend>, "
                    "<build_depend>, <exec_depend>); each must be given or installed. A "
                    "package this environment can import already is skipped. Without PATH: "
                    "the interfaces the daemon ships (tf2_msgs, control_msgs) that are "
                    "missing. Needs the 'interfaces' extra, cmake >= 3.20, a C/C++ compiler "
                    "and make. Exit code 2: bad input, nothing built; 1: a build failed.")
    build.add_argument("paths", nargs="*", type=Path, metavar="PATH",
                       help="an interface package's folder, or a folder holding several "
                            "(a workspace's src/)")
    build.add_argument("--force", action="store_true",
                       help="rebuild packages that are importable already")
    build.add_argument("--prefix", type=Path, metavar="DIR",
                       help="install into DIR instead of this environment (then prints what "
                            "to export to use them: PYTHONPATH, LD_LIBRARY_PATH, "
                            "AMENT_PREFIX_PATH)")
    build.add_argument("--build-dir", type=Path, metavar="DIR",
                       help="where to build (default: a temporary folder, removed after a "
                            "success, kept after a failure for its logs)")
    build.add_argument("--parallel", type=_positive(int), metavar="N",
                       default=min(2, os.cpu_count() or 1),
                       help="build up to N independent packages at once (default: 2, or 1 on "
                            "a single core)")


def _build_interfaces(args: argparse.Namespace) -> int:
    import shutil
    import tempfile
    import time

    from bridge.interfaces import (InputError, InterfaceBuildError, build_interfaces,
                                   describe_exports, find_packages, shipped_packages,
                                   this_environment)

    def say(line: str) -> None:
        print(line, flush=True)

    started = time.monotonic()
    target = this_environment(args.prefix)
    try:
        packages = find_packages(args.paths, note=say) if args.paths else shipped_packages()
    except InputError as error:
        print(f"slicer-ros2-bridge build-interfaces: {error}", file=sys.stderr)
        return 2
    build_root = args.build_dir or Path(tempfile.mkdtemp(prefix="slicer-ros2-bridge-build-"))
    say(f"building {len(packages)} interface package(s) into {target.install_prefix}: "
        f"{', '.join(p.name for p in packages)}")
    try:
        built = build_interfaces(packages, target, force=args.force, build_root=build_root,
                                 say=say, parallel=args.parallel)
    except InputError as error:  # found before anything was built
        print(f"slicer-ros2-bridge build-interfaces: {error}", file=sys.stderr)
        if args.build_dir is None:
            shutil.rmtree(build_root, ignore_errors=True)
        return 2
    except InterfaceBuildError as error:
        print(f"slicer-ros2-bridge build-interfaces: {error}", file=sys.stderr)
        if args.build_dir is None:
            print(f"slicer-ros2-bridge build-interfaces: the build folder is kept for its "
                  f"logs: {build_root}", file=sys.stderr)
        return 1
    if args.build_dir is None:
        shutil.rmtree(build_root, ignore_errors=True)
    took = f"{time.monotonic() - started:.0f} s"
    skipped = len(packages) - len(built)
    rebuild = f"; {skipped} importable already (--force rebuilds them)" if skipped else ""
    if not built:
        say(f"done in {took}: nothing to build{rebuild}")
        return 0
    say(f"done in {took}: built {', '.join(built)} into {target.install_prefix}{rebuild}")
    if target.exports:
        say(f"to use them, export:\n{describe_exports(target.exports)}")
    return 0


def _keygen(path: Path, *, force: bool) -> int:
    """Write a new key, owner-only from its first byte (never world-readable for a moment)."""
    flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if force else os.O_EXCL)
    try:
        fd = os.open(path, flags, 0o600)
    except FileExistsError:
        print(f"slicer-ros2-bridge keygen: {path} exists; expected a new file (--force "
              f"replaces it, and every writer then needs the new key)", file=sys.stderr)
        return 2
    except OSError as error:
        print(f"slicer-ros2-bridge keygen: cannot write {path}: {error.strerror}",
              file=sys.stderr)
        return 2
    with os.fdopen(fd, "w", encoding="ascii") as file:
        os.fchmod(file.fileno(), 0o600)
        file.write(new_key_text())
    print(f"wrote a new key to {path} (owner-only). Start the daemon with --key-file {path}; "
          f"copy it to each machine that writes (slicer_client.connect(key_file=...)).")
    return 0


def _shm_unlock(wait_s: float) -> int:
    removed = remove_unfinished(wait_s)
    for path in removed:
        print(f"removed {path} (a port segment never finished: every process opening it "
              f"hung)")
    released = release_stuck(wait_s)
    for name in released:
        print(f"released {name} (left taken by a ROS process that was killed)")
    dead = remove_dead_segments(wait_s)
    if dead:
        print(f"removed {len(dead)} shared-memory segment(s) of killed ROS processes "
              f"({sum(size for _, size in dead) / 1e6:.1f} MB of RAM)")
    if not released and not removed and not dead:
        print("no Fast DDS port lock is left taken, no port segment unfinished, and no "
              "segment of a killed process left")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["play"]:  # no ROS: a bag plays where ROS is not installed
        from bridge.playback import cli as play

        return play.main(argv[1:])
    if argv[:1] == ["state-publisher"]:
        lacking = missing_runtime_line()
        if lacking is not None:
            print(f"slicer-ros2-bridge: {lacking}", file=sys.stderr)
            return 2
        from bridge.robots import state_publisher

        return state_publisher.main(argv[1:])
    parser = build_parser()
    try:
        ours, ros_args = split_ros_args(argv)
    except RosArgsError as error:
        print(f"slicer-ros2-bridge: --ros-args: {error}", file=sys.stderr)
        return 2
    args = parser.parse_args(ours)
    if args.command in ("run", "demo"):
        try:
            node = ros_args.node_name(args.node_name, args.namespace)
            apply_parameters(_subparser(parser, args.command), args, ours,
                             ros_args.parameters_for(node))
        except RosArgsError as error:
            print(f"slicer-ros2-bridge: --ros-args: {error}", file=sys.stderr)
            return 2
        args.ros_args = tuple(ros_args.argv)
    elif ros_args.argv:
        parser.error(f"--ros-args: expected only with run or demo, got {args.command}")
    if args.command is None:
        parser.print_help()
        return 2
    if args.command == "build-interfaces":
        return _build_interfaces(args)
    if args.command == "keygen":
        return _keygen(args.file, force=args.force)
    if args.command == "shm-unlock":
        return _shm_unlock(args.wait)
    # A wheel installed without ROS or tf2_msgs says so in one line, not with a traceback.
    lacking = missing_runtime_line()
    if lacking is not None:
        print(f"slicer-ros2-bridge: {lacking}", file=sys.stderr)
        return 2
    if args.command == "demo":  # the daemon plus the demo robot's processes
        from bridge.robots.demo_runner import run_demo

        return run_with_config(args, run_demo)
    if args.command == "run":
        from bridge.daemon import run_daemon

        return run_with_config(args, run_daemon)
    if args.command in ("topics", "services", "echo"):
        return graph_inspect.run(args)
    if args.command == "record":
        return record_cli.run(args)
    parser.error(f"unknown command {args.command}")
    return 2


if __name__ == "__main__":
    sys.exit(main())
