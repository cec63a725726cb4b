"""`slicer-ros2-bridge topics | services | echo`: look at the ROS graph from a shell.

ROS 2 from PyPI wheels has no `ros2` command, so the checks SlicerROS2's documentation does
with `ros2 topic list -t` and `ros2 topic echo` are offered here, printing the same way
(one `/name [type]` line per topic; each message as YAML followed by `---`). They run a
short-lived node of their own, not the daemon, and see what the daemon would see.
"""

from __future__ import annotations

import argparse
import difflib
import os
import sys
import threading
import time
from typing import TYPE_CHECKING, Any, Callable, Optional, TextIO

if TYPE_CHECKING:  # rclpy is imported only when a subcommand runs: --help stays quick
    from bridge.ros.ros_node import RosNode

# Discovery is not instant, and on a busy machine it takes seconds. DDS never says it is
# done: a list is read once the graph has not changed for SETTLED_S (at most --wait), and
# echo waits for its topic until it appears (at most --wait).
DEFAULT_DISCOVERY_S = 10.0
SETTLED_S = 1.5
_POLL_S = 0.05
# The name of every inspector's node (this command's, or one that just ended and is still
# in the graph): their parameter services are not the user's graph.
INSPECTOR_PREFIX = "slicer_bridge_inspect_"


class GraphInspectError(Exception):
    """What the user asked for cannot be shown; the text says why and what to do."""


def add_parsers(commands: Any) -> None:
    """Add the `topics`, `services` and `echo` subcommands to the CLI's subparsers."""
    for name, what in (("topics", "topic"), ("services", "service")):
        listing = commands.add_parser(
            name, help=f"list the ROS graph's {what}s with their types (as `ros2 {what} list "
                       f"-t`)", description=f"List the {what}s the ROS graph has, with types.")
        listing.add_argument("--wait", type=float, default=DEFAULT_DISCOVERY_S, metavar="S",
                             help=f"at most this long for discovery: the list is printed "
                                  f"once the graph is unchanged for {SETTLED_S:g} s "
                                  f"(default %(default)s)")
    echo = commands.add_parser(
        "echo", help="print a topic's messages as YAML (as `ros2 topic echo`)",
        description="Print the messages of a topic as YAML, each followed by `---`.")
    echo.add_argument("topic", help="the topic, e.g. /tool_pose")
    echo.add_argument("type", nargs="?",
                      help="its type, e.g. geometry_msgs/msg/PoseStamped (default: the type "
                           "the graph knows)")
    echo.add_argument("--once", action="store_true", help="print one message and exit")
    echo.add_argument("--count", type=int, metavar="N", help="print N messages and exit")
    echo.add_argument("--timeout", type=float, metavar="S",
                      help="give up after S seconds without a message (default: wait)")
    echo.add_argument("--wait", type=float, default=DEFAULT_DISCOVERY_S, metavar="S",
                      help="at most this long for a publisher of the topic to appear in the "
                           "graph (default %(default)s)")


def run(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """Run one of the subcommands; returns the exit code."""
    try:
        with _Inspector() as ros:
            if args.command == "topics":
                return _list(out, ros, ros.node.get_topic_names_and_types, args.wait)
            if args.command == "services":
                return _list(out, ros, ros.node.get_service_names_and_types, args.wait)
            count = 1 if args.once else args.count
            return _echo(out, ros, args.topic, args.type, count, args.timeout, args.wait)
    except GraphInspectError as error:
        print(f"slicer-ros2-bridge {args.command}: {error}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # the reader left (`| head -3`): its node is stopped already
        return _reader_gone(out)
    except KeyboardInterrupt:
        return 0


# Python's exit status when a write meets EPIPE (the `signal` module's note on SIGPIPE).
READER_GONE_STATUS = 1


def _reader_gone(out: TextIO) -> int:
    """End quietly: what is still buffered for ``out`` goes to /dev/null, so the flush at
    interpreter exit does not print an "Exception ignored ... BrokenPipeError" either."""
    try:
        fd = out.fileno()
    except (OSError, ValueError):  # not a file (a test's StringIO): nothing is flushed
        return READER_GONE_STATUS
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, fd)
    os.close(devnull)
    return READER_GONE_STATUS


class _Inspector:
    """A node of its own, spinning in its thread, stopped on exit."""

    def __enter__(self) -> RosNode:
        from bridge.ros.ros_node import RosNode, RosOptions

        name = f"{INSPECTOR_PREFIX}{time.time_ns() % 10**9}"
        self._ros = RosNode(RosOptions(node_name=name))
        self._ros.start()
        return self._ros

    def __exit__(self, *exc: object) -> None:
        self._ros.stop()


NamesAndTypes = list[tuple[str, list[str]]]


def _list(out: TextIO, ros: RosNode, names_and_types: Callable[[], NamesAndTypes],
          wait: float) -> int:
    for name, types in sorted(settled_graph(names_and_types, wait)):
        if not name.startswith("/" + INSPECTOR_PREFIX):  # inspectors' parameter services
            print(f"{name} [{', '.join(types)}]", file=out)
    return 0


def settled_graph(read: Callable[[], NamesAndTypes], wait: float, *,
                  settled_s: float = SETTLED_S) -> NamesAndTypes:
    """``read()`` once it has returned the same for ``settled_s``, or after ``wait``."""
    start = changed = time.monotonic()
    seen = sorted(read())
    while True:
        now = time.monotonic()
        if now - changed >= settled_s or now - start >= wait:
            return seen
        time.sleep(_POLL_S)  # graph changes come by polling: rclpy has no graph callback
        current = sorted(read())
        if current != seen:
            seen, changed = current, time.monotonic()


def _echo(out: TextIO, ros: RosNode, topic: str, type_name: Optional[str],
          count: Optional[int], timeout: Optional[float], wait: float) -> int:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from bridge.codecs import CodecError, message_to_yaml
    from bridge.codecs.registry import message_class

    from protocol.commands import OutOfRangeError

    try:
        full = ros.resolve_name(topic, "topic")
    except OutOfRangeError as error:
        raise GraphInspectError(str(error)) from None

    def installed(ros_type: str) -> Any:
        try:
            return message_class(ros_type)
        except CodecError as error:
            raise GraphInspectError(f"expected a message type installed here, got "
                                    f"{ros_type!r} ({error})") from None
    if type_name:
        installed(type_name)  # before any wait
    publishers = _wait_for_publishers(ros, full, wait)
    cls = installed(type_name or _graph_type(ros, full, wait, publishers))
    printed = 0
    done = threading.Event()
    lock = threading.Lock()
    reader_gone = False

    def on_message(msg: Any) -> None:  # executor thread
        nonlocal printed, reader_gone
        with lock:
            if done.is_set():
                return
            try:
                out.write(message_to_yaml(msg))
                out.write("---\n")
                out.flush()
            except BrokenPipeError:  # raised here, it would only kill this callback
                reader_gone = True
                done.set()
                return
            printed += 1
            if count is not None and printed >= count:
                done.set()

    # As `ros2 topic echo`: match what the discovered publishers offer (latched ones too).
    # With none discovered, BEST_AVAILABLE would ask for the most (reliable, transient
    # local) and never match a volatile publisher found later: ask for the least then.
    if publishers:
        qos = QoSProfile(
            depth=10, reliability=ReliabilityPolicy.BEST_AVAILABLE,
            durability=DurabilityPolicy.BEST_AVAILABLE)
    else:
        qos = QoSProfile(
            depth=10, reliability=ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.VOLATILE)
    ros.node.create_subscription(cls, full, on_message, qos)
    finished = done.wait(timeout)
    with lock:
        if reader_gone:
            raise BrokenPipeError(f"the reader of {full}'s messages closed its end")
    if not finished:
        if timeout is not None and printed == 0:
            raise GraphInspectError(f"no message on {full} within {timeout:g} s")
    return 0


def _wait_for_publishers(ros: RosNode, topic: str, wait: float) -> int:
    """The publishers of ``topic`` discovered within ``wait`` (at once when there are)."""
    deadline = time.monotonic() + max(wait, 0.0)
    while True:
        found = ros.node.count_publishers(topic)
        if found or time.monotonic() >= deadline:
            return int(found)
        time.sleep(_POLL_S)


def _graph_type(ros: RosNode, topic: str, wait: float, publishers: int) -> str:
    types = ros.topic_types(topic)
    if len(types) > 1:
        raise GraphInspectError(f"{topic} has several types ({', '.join(types)}): "
                                f"name one, e.g. `echo {topic} {types[0]}`")
    if types and publishers:
        return types[0]
    seen = [name for name, _ in ros.node.get_topic_names_and_types()]
    where = "has no publisher" if types else f"is not among the {seen_topics(topic, seen)}"
    raise GraphInspectError(
        f"expected a topic the ROS graph knows, got {topic}: it {where} seen in {wait:g} s. "
        f"Is its publisher running, with the same ROS_DOMAIN_ID? Name the type to wait for "
        f"it anyway: `echo {topic} pkg/msg/Type`")


def seen_topics(wanted: str, seen: list[str], shown: int = 12) -> str:
    """What the graph had, for an error: the count, then the names closest to ``wanted``
    first (a typo shows at once), at most ``shown`` of them."""
    if not seen:
        return "0 topics"
    closest = difflib.get_close_matches(wanted, seen, n=shown, cutoff=0.6)
    names = closest + [name for name in sorted(seen) if name not in closest]
    more = f", and {len(names) - shown} more" if len(names) > shown else ""
    return (f"{len(seen)} topic{'s' if len(seen) != 1 else ''} "
            f"({', '.join(names[:shown])}{more})")
