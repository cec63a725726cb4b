"""``slicer-ros2-bridge play BAG.mcap [--rate R] [--loop] [--start S] [--port P]``: serve a
bag to 3D Slicer (bridge/playback/player.py). No ROS is imported on this path."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from pathlib import Path
from typing import Optional

from protocol.commands import MAX_PLAYBACK_RATE

__all__ = ["build_parser", "main"]

DEFAULT_PORT = 18944


def _rate(text: str) -> float:
    try:
        rate = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0 < rate <= MAX_PLAYBACK_RATE:
        raise argparse.ArgumentTypeError(f"expected a rate in (0, {MAX_PLAYBACK_RATE:g}], "
                                         f"got {text}")
    return rate


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"expected seconds >= 0, got {text}")
    return value


def _package_path(text: str) -> tuple[str, str]:
    from bridge.robots.errors import RobotError
    from bridge.robots.resources import parse_package_path_option

    try:
        name, folder = parse_package_path_option(text)
    except RobotError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    return name, str(folder)


def build_parser(prog: str = "slicer-ros2-bridge play") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog, description="Serve a ROS 2 bag (MCAP: ros2msg schemas, cdr encoding) to "
        "3D Slicer over OpenIGTLink as the daemon serves ROS: the same devices, names and "
        "metadata, robots from the bag's robot_description, tf lookups, images, point "
        "clouds, text. Needs no ROS. Clients pause, resume, seek and set the rate.")
    parser.add_argument("bag", type=Path, metavar="BAG.mcap",
                        help="an MCAP file, or a rosbag2 folder holding one")
    parser.add_argument("--rate", type=_rate, default=1.0,
                        help="play at RATE times the bag's speed (default 1)")
    parser.add_argument("--loop", action="store_true", help="start again at the end")
    parser.add_argument("--start", type=_seconds, default=0.0, metavar="S",
                        help="start S seconds into the bag")
    parser.add_argument("--paused", action="store_true",
                        help="start paused (a client resumes it)")
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT,
                        help=f"OpenIGTLink port (default {DEFAULT_PORT}; 0: any free one)")
    parser.add_argument("--package-path", type=_package_path, action="append", default=[],
                        metavar="NAME=DIR",
                        help="where package://NAME/ meshes are, for a bag that does not "
                             "carry them as attachments (repeatable)")
    parser.add_argument("--log-level", default="INFO",
                        choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    return parser


def main(argv: Optional[list[str]] = None) -> int:
    args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
    logging.basicConfig(level=getattr(logging, args.log_level), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        from bridge.playback.bag import BagError
        from bridge.playback.player import PlayOptions, run_player
    except ImportError as error:  # the play extra not installed
        print(f"slicer-ros2-bridge play: {error.name} is not installed (pip install "
              "'slicer-ros2-bridge[play]')", file=sys.stderr)
        return 2
    from bridge.core.server import PortInUseError

    options = PlayOptions(bag=args.bag, host=args.host, port=args.port, rate=args.rate,
                          loop=args.loop, start_s=args.start, paused=args.paused,
                          package_paths=tuple(args.package_path))
    try:
        asyncio.run(run_player(options))
    except (BagError, PortInUseError) as error:  # the start's own error: one line
        print(f"slicer-ros2-bridge play: {error}", file=sys.stderr)
        return 2
    return 0
