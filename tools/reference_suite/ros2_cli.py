"""A stand-in for the `ros2` command, for running SlicerROS2's own unit tests unchanged.

Their Testing/Python/ROS2Tests.py runs, through a shell,
`unset PYTHONHOME ; unset PYTHONPATH ; . /opt/ros/$ROS_DISTRO/setup.sh ;
/usr/bin/python3 /opt/ros/$ROS_DISTRO/bin/ros2 <command>`; pointed here (and at setup.sh
beside it), these are the commands it uses, done with rclpy as the real ones do:

  ros2 run turtlesim turtlesim_node        tests/peers/turtlesim_node.py, in the foreground
  ros2 node list                           one fully qualified node name per line
  ros2 service list                        one service name per line
  ros2 param set NODE NAME VALUE           VALUE typed by YAML rules, as the real command

Started by any Python (Debian's /usr/bin/python3 has no ROS), it re-executes itself with
the project's venv Python, found from this file's place in the repository (or
$SLICER_ROS2_BRIDGE_REPO). Without a ros2 daemon, the listings wait for discovery to settle.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Mapping

if TYPE_CHECKING:  # imported when used: Debian's Python runs the top of this file
    from rcl_interfaces.msg import ParameterValue
    from rclpy.node import Node

REPO = Path(os.environ.get("SLICER_ROS2_BRIDGE_REPO") or Path(__file__).resolve().parents[2])
VENV = REPO / ".venv"
EXECUTABLES = {("turtlesim", "turtlesim_node"): REPO / "tests" / "peers" / "turtlesim_node.py"}
# Discovery without a daemon: listen at least this long, until nothing changed for QUIET_S.
# Measured here (2 cores, load 3): a running node is seen 0.05-2.5 s after our start. A
# participant that missed the first exchange is heard at its next announcement (Fast DDS:
# every 3 s), so the first wait is longer than that.
DISCOVERY_MIN_S = 4.0
DISCOVERY_QUIET_S = 1.0
DISCOVERY_MAX_S = 10.0
# How long `param set` waits for the node's parameter service, then for its answer.
PARAM_WAIT_S = 10.0
# Our own node: hidden (leading _), as the real command's, and never listed.
OWN_NAME = f"_ros2cli_{os.getpid()}"


def run_in_project_venv() -> None:
    """Re-execute this script with the venv's Python unless it is the one running."""
    if Path(sys.prefix).resolve() == VENV.resolve():
        return
    python = VENV / "bin" / "python"
    if not python.exists():
        sys.exit(f"ros2: expected the project's venv at {VENV}, got none: run `make setup` "
                 f"in {REPO}")
    env = dict(os.environ)
    env.pop("PYTHONHOME", None)
    # The venv's Python sets its own library path up (ROS wheels' bootstrap).
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
    os.execve(str(python), [str(python), str(Path(__file__).resolve()), *sys.argv[1:]], env)


def main(argv: list[str]) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog="ros2", description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    run = commands.add_parser("run", help="run a package's executable")
    run.add_argument("package")
    run.add_argument("executable")
    run.add_argument("arguments", nargs=argparse.REMAINDER)
    node = commands.add_parser("node").add_subparsers(dest="verb", required=True)
    node.add_parser("list", help="the running nodes")
    service = commands.add_parser("service").add_subparsers(dest="verb", required=True)
    service.add_parser("list", help="the services offered")
    param = commands.add_parser("param").add_subparsers(dest="verb", required=True)
    param_set = param.add_parser("set", help="set a node's parameter")
    param_set.add_argument("node_name")
    param_set.add_argument("parameter_name")
    param_set.add_argument("value")
    args = parser.parse_args(argv)
    if args.command == "run":
        return run_executable(args.package, args.executable, args.arguments)
    if args.command == "node":
        return print_lines(discovered(node_names))
    if args.command == "service":
        return print_lines(discovered(service_names))
    return set_parameter(args.node_name, args.parameter_name, args.value)


def run_executable(package: str, executable: str, arguments: list[str]) -> int:
    """Replace this process with the executable: the caller's signals reach it directly."""
    script = EXECUTABLES.get((package, executable))
    if script is None:
        known = {p for p, _ in EXECUTABLES}
        print(f"Package '{package}' not found" if package not in known
              else "No executable found", file=sys.stderr)
        return 1
    env = with_overlay_python_paths(os.environ)
    os.execve(sys.executable, [sys.executable, "-u", str(script), *arguments], env)
    return 1  # not reached


def with_overlay_python_paths(env: Mapping[str, str]) -> dict[str, str]:
    """`env` with the Python modules of every prefix on AMENT_PREFIX_PATH importable, as a
    ROS setup.sh arranges: the suite unsets PYTHONPATH, and packages built into a separate
    prefix (the tests' turtlesim interfaces) need it."""
    from bridge.interfaces import prefix_exports, with_exports

    merged = dict(env)
    for prefix in filter(None, reversed(env.get("AMENT_PREFIX_PATH", "").split(os.pathsep))):
        site = prefix_exports(Path(prefix))["PYTHONPATH"]
        if Path(site).is_dir():
            merged = with_exports(merged, {"PYTHONPATH": site})
    return merged


def print_lines(lines: list[str]) -> int:
    for line in lines:
        print(line)
    return 0


def discovered(read: Callable[[Node], list[str]]) -> list[str]:
    """What `read(node)` returns once discovery has settled: at least DISCOVERY_MIN_S, and
    DISCOVERY_QUIET_S without a change (at most DISCOVERY_MAX_S)."""
    import time

    import rclpy

    rclpy.init()
    node = rclpy.create_node(OWN_NAME, start_parameter_services=False, enable_rosout=False)
    try:
        started = changed = time.monotonic()
        seen = read(node)
        while True:
            rclpy.spin_once(node, timeout_sec=0.05)
            now = time.monotonic()
            current = read(node)  # the graph is kept by DDS's threads; spinning is a pause
            if current != seen:
                seen, changed = current, now
            settled = now - started >= DISCOVERY_MIN_S and now - changed >= DISCOVERY_QUIET_S
            if settled or now - started >= DISCOVERY_MAX_S:
                return seen
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def _hidden(name: str) -> bool:
    return any(part.startswith("_") for part in name.split("/"))


def node_names(node: Node) -> list[str]:
    """Fully qualified names of the visible nodes, sorted (hidden ones and ours left out)."""
    names = {f"{namespace.rstrip('/')}/{name}"
             for name, namespace in node.get_node_names_and_namespaces()}
    return sorted(n for n in names if not _hidden(n))


def service_names(node: Node) -> list[str]:
    """Names of the visible services, sorted (hidden ones, like actions' parts, left out)."""
    return sorted(name for name, _ in node.get_service_names_and_types() if not _hidden(name))


def parameter_value(text: str) -> ParameterValue:
    """A ParameterValue typed by YAML rules, as `ros2 param set` does: 150 is an integer,
    1.5 a double, true a bool, [1, 2] an integer array, anything else the text itself."""
    import yaml
    from rcl_interfaces.msg import ParameterType, ParameterValue

    try:
        parsed = yaml.safe_load(text)
    except yaml.YAMLError:
        parsed = text
    value = ParameterValue()
    scalar = {bool: (ParameterType.PARAMETER_BOOL, "bool_value"),
              int: (ParameterType.PARAMETER_INTEGER, "integer_value"),
              float: (ParameterType.PARAMETER_DOUBLE, "double_value"),
              str: (ParameterType.PARAMETER_STRING, "string_value")}
    array = {bool: (ParameterType.PARAMETER_BOOL_ARRAY, "bool_array_value"),
             int: (ParameterType.PARAMETER_INTEGER_ARRAY, "integer_array_value"),
             float: (ParameterType.PARAMETER_DOUBLE_ARRAY, "double_array_value"),
             str: (ParameterType.PARAMETER_STRING_ARRAY, "string_array_value")}
    kinds = {type(item) for item in parsed} if isinstance(parsed, list) else set()
    integers = [parsed] if type(parsed) is int else parsed if kinds == {int} else []
    too_large = [n for n in integers if not -2**63 <= n < 2**63]
    if too_large:
        raise ValueError(f"expected 64-bit integers, got {too_large[0]}")
    if type(parsed) in scalar:
        value.type, field = scalar[type(parsed)]
        setattr(value, field, parsed)
    elif parsed and len(kinds) == 1 and next(iter(kinds)) in array:
        value.type, field = array[next(iter(kinds))]
        setattr(value, field, parsed)
    else:  # empty, a mapping, a mixed list: the text as written
        value.type, value.string_value = ParameterType.PARAMETER_STRING, text
    return value


def set_parameter(node_name: str, name: str, text: str) -> int:
    import rclpy
    from rcl_interfaces.msg import Parameter
    from rcl_interfaces.srv import SetParameters

    try:
        value = parameter_value(text)
    except ValueError as error:
        print(f"Set parameter failed: {error}", file=sys.stderr)
        return 1
    target = node_name if node_name.startswith("/") else f"/{node_name}"
    rclpy.init()
    node = rclpy.create_node(OWN_NAME, start_parameter_services=False, enable_rosout=False)
    try:
        client = node.create_client(SetParameters, f"{target}/set_parameters")
        if not client.wait_for_service(timeout_sec=PARAM_WAIT_S):
            print("Node not found", file=sys.stderr)
            return 1
        future = client.call_async(SetParameters.Request(
            parameters=[Parameter(name=name, value=value)]))
        rclpy.spin_until_future_complete(node, future, timeout_sec=PARAM_WAIT_S)
        if not future.done() or future.result() is None:
            print(f"Set parameter failed: {target} did not answer within {PARAM_WAIT_S:g} s",
                  file=sys.stderr)
            return 1
        result = future.result().results[0]
        reason = f": {result.reason}" if result.reason else ""
        if not result.successful:
            print(f"Set parameter failed{reason}", file=sys.stderr)
            return 1
        print(f"Set parameter successful{reason}")
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    run_in_project_venv()
    sys.exit(main(sys.argv[1:]))
