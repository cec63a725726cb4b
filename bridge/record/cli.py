"""`slicer-ros2-bridge record OUT.mcap [TOPIC ...]`: record the ROS graph into a bag.

A node of its own (as `topics` and `echo`), recording the topics given, or every topic of
the graph (those that appear later too) when none is given, until Ctrl-C, SIGTERM or
``--duration``. The bag is a standard ROS 2 MCAP (`bridge.record.bag`). A running daemon
records what it bridges instead: the ``start_recording`` op (``ros.record(...)``).
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from pathlib import Path
from types import FrameType
from typing import Any, Optional, TextIO

from bridge.record.bag import COMPRESSIONS, DEFAULT_QUEUE_BYTES, BagPathError, BagStats

__all__ = ["add_parser", "run", "summary"]

_PROGRAM = "slicer-ros2-bridge record"


def add_parser(commands: Any) -> None:
    record = commands.add_parser(
        "record", help="record ROS topics into a standard ROS 2 bag (MCAP)",
        description="Record ROS topics into OUT.mcap, a ROS 2 bag (MCAP: ros2msg schemas, "
                    "CDR messages) that ros2 bag, Foxglove and rosbags read, until Ctrl-C. "
                    "Without TOPIC: every topic of the graph, those that appear later too. "
                    "Exit code 2: bad OUT; 1: the recording stopped early (a full disk: "
                    "the bag is closed and readable).")
    record.add_argument("out", type=Path, metavar="OUT.mcap", help="the bag to write")
    record.add_argument("topics", nargs="*", metavar="TOPIC",
                        help="a topic to record (repeatable); recorded from when the graph "
                             "has it")
    record.add_argument("--overwrite", action="store_true", help="replace an existing OUT")
    record.add_argument("--compression", choices=sorted(COMPRESSIONS), default="none",
                        help="chunk compression (default none: the least CPU)")
    record.add_argument("--duration", type=float, metavar="S",
                        help="stop after S seconds (default: at Ctrl-C or SIGTERM)")
    record.add_argument("--queue-mb", type=float, default=DEFAULT_QUEUE_BYTES / 2**20,
                        metavar="MB", help="memory for messages waiting to be written; past "
                                           "it they are dropped and counted (default "
                                           "%(default)g)")


def summary(stats: BagStats, pending: Optional[dict[str, str]] = None) -> str:
    """One line per topic (and per wanted topic not recorded, saying why), then the
    totals."""
    lines = [f"  {t.topic} [{t.ros_type}]: {t.messages} messages"
             + (f", {t.dropped} dropped" if t.dropped else "") for t in stats.topics]
    lines += [f"  {topic}: not recorded: {why}" for topic, why in (pending or {}).items()]
    lines.append(f"{stats.path}: {stats.messages} messages, {stats.bytes / 1e6:.1f} MB, "
                 f"{stats.elapsed_s:.1f} s, {stats.dropped} dropped")
    return "\n".join(lines)


def run(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    from bridge.graph_inspect import INSPECTOR_PREFIX
    from bridge.record.bag import BagWriter, check_bag_path
    from bridge.record.recorder import Recorder
    from bridge.ros.ros_node import RosNode, RosOptions
    from protocol.commands import OutOfRangeError

    stop = threading.Event()

    def on_signal(signum: int, frame: Optional[FrameType]) -> None:
        stop.set()

    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, on_signal)
    try:
        path = check_bag_path(args.out, absolute=False)
    except BagPathError as error:
        print(f"{_PROGRAM}: {error}", file=sys.stderr)
        return 2
    ros = RosNode(RosOptions(node_name=f"{INSPECTOR_PREFIX}record_{time.time_ns() % 10**9}"))
    try:
        try:
            topics = [ros.resolve_name(t, "topic") for t in args.topics]
        except OutOfRangeError as error:
            print(f"{_PROGRAM}: {error}", file=sys.stderr)
            return 2
        try:
            bag = BagWriter(path, overwrite=args.overwrite, compression=args.compression,
                            queue_bytes=int(args.queue_mb * 2**20),
                            on_error=lambda text: stop.set())
        except BagPathError as error:
            print(f"{_PROGRAM}: {error}", file=sys.stderr)
            return 2
        ros.start()

        def wanted() -> dict[str, Optional[str]]:
            if topics:
                return dict.fromkeys(topics)
            return {name: None for name, _ in ros.node.get_topic_names_and_types()
                    if not name.startswith("/_")}

        def said(topic: str, ros_type: str) -> None:
            print(f"recording {topic} [{ros_type}]", file=out, flush=True)

        recorder = Recorder(ros, bag, wanted, on_topic=said)
        recorder.start()
        print(f"recording into {path} (Ctrl-C stops)", file=out, flush=True)
        stop.wait(args.duration)
        pending = {p["topic"]: p["why"] for p in recorder.status().pending}
        stats = recorder.stop()
    finally:
        ros.stop()
    print(summary(stats, pending), file=out, flush=True)
    if stats.error:
        print(f"{_PROGRAM}: {stats.error}", file=sys.stderr)
        return 1
    return 0
