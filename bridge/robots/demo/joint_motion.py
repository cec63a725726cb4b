"""Move every joint of a robot smoothly within its limits: a sensor_msgs/JointState
publisher (50 Hz by default) for the demo robot, or any URDF.

Each actuated joint (moving, not a mimic) follows ``centre + amplitude * sin(2 pi t / T_i +
phase_i)``: the centre is the middle of its limits, the amplitude ``fraction`` of half the
range (continuous joints and joints without limits swing +-pi/2 or +-0.05 m), and every joint
gets its own period and phase so the arm does not move in lockstep. Mimic joints are left
to the state publisher. `JointMotion.positions_at` is pure, for tests.

The motion yields (`MotionHold`): it stops publishing while another publisher drives
``joint_states`` (a client's sliders through ``set_robot_joints``: for ``--yield-s`` seconds
after the last foreign joint state, 3 s by default) and while something holds it by name
(`MotionHold.pause` / `resume`, for an in-process user such as an action server).

Command line::

    python -m bridge.robots.demo.joint_motion [URDF] [--rate HZ] [--period S]
        [--namespace NS] [--node-name NAME] [--package-path NAME=DIR ...] [--yield-s S]

Without URDF the built-in demo robot is used.
"""

from __future__ import annotations

import argparse
import math
import sys
import threading
from collections import deque
from dataclasses import dataclass
from typing import Any, Optional

from bridge.robots.description import RobotDescription, parse_urdf

__all__ = ["DEFAULT_YIELD_S", "JointMotion", "MotionHold", "create_joint_motion_node", "main"]

DEFAULT_YIELD_S = 3.0


@dataclass(frozen=True)
class _Wave:
    name: str
    centre: float
    amplitude: float
    period: float
    phase: float


class JointMotion:
    """Sinusoidal positions for the actuated joints of ``description``."""

    def __init__(self, description: RobotDescription, *, period_s: float = 8.0,
                 fraction: float = 0.8) -> None:
        if period_s <= 0 or not 0 < fraction <= 1:
            raise ValueError(f"period_s > 0 and 0 < fraction <= 1 expected, got "
                             f"{period_s}, {fraction}")
        waves = []
        for i, name in enumerate(description.actuated_joints):
            joint = description.joints[name]
            limits = joint.limits
            if joint.type != "continuous" and limits is not None and limits.upper > limits.lower:
                centre = 0.5 * (limits.lower + limits.upper)
                amplitude = fraction * 0.5 * (limits.upper - limits.lower)
            else:
                centre = 0.0
                amplitude = 0.05 if joint.type == "prismatic" else math.pi / 2
            # Periods 1, 1.13, 1.26... x period_s and spread phases: a non-repeating look.
            waves.append(_Wave(name, centre, amplitude, period_s * (1.0 + 0.13 * i),
                               0.7 * i))
        self._waves = tuple(waves)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(w.name for w in self._waves)

    def positions_at(self, t: float) -> dict[str, float]:
        return {w.name: w.centre + w.amplitude * math.sin(2 * math.pi * t / w.period + w.phase)
                for w in self._waves}

    def velocities_at(self, t: float) -> dict[str, float]:
        return {w.name: w.amplitude * 2 * math.pi / w.period
                * math.cos(2 * math.pi * t / w.period + w.phase) for w in self._waves}


class MotionHold:
    """Whether the idle motion yields at time ``now`` (seconds, any monotonic clock):
    while any owner holds it (`pause` / `resume`, counted per owner name) or for
    ``yield_s`` after `foreign_state` (someone else published a joint state). Thread-safe:
    a subscription callback and a timer may run in different threads."""

    def __init__(self, yield_s: float = DEFAULT_YIELD_S) -> None:
        if not yield_s >= 0:
            raise ValueError(f"yield_s >= 0 expected, got {yield_s}")
        self.yield_s = yield_s
        self._owners: set[str] = set()
        self._until = -math.inf
        self._lock = threading.Lock()

    def pause(self, owner: str) -> None:
        with self._lock:
            self._owners.add(owner)

    def resume(self, owner: str) -> None:
        with self._lock:
            self._owners.discard(owner)

    def foreign_state(self, now: float) -> None:
        with self._lock:
            self._until = max(self._until, now + self.yield_s)

    def holds(self, now: float) -> bool:
        with self._lock:
            return bool(self._owners) or now < self._until


def create_joint_motion_node(motion: JointMotion, *, rate_hz: float = 50.0,
                             node_name: str = "demo_joint_motion", namespace: str = "",
                             context: Any = None, hold: Optional[MotionHold] = None) -> Any:
    """An rclpy node publishing ``motion`` on ``joint_states`` at ``rate_hz`` (for any
    executor, e.g. inside the daemon); rclpy must be initialised. It also listens on
    ``joint_states``: a message it did not publish (told by its stamp, unique per tick)
    makes it yield per ``hold`` (default `MotionHold()`; its ``pause``/``resume`` too)."""
    import rclpy
    from sensor_msgs.msg import JointState

    hold = hold if hold is not None else MotionHold()
    node = rclpy.create_node(node_name, namespace=namespace, context=context)
    publisher = node.create_publisher(JointState, "joint_states", 10)
    start = node.get_clock().now()
    own: deque[tuple[int, int]] = deque(maxlen=256)  # stamps of our recent messages

    def seconds() -> float:
        return float(node.get_clock().now().nanoseconds) * 1e-9

    def on_state(msg: Any) -> None:  # does almost nothing: notes a foreign publisher
        if (msg.header.stamp.sec, msg.header.stamp.nanosec) not in own:
            hold.foreign_state(seconds())

    def tick() -> None:
        now = node.get_clock().now()
        if hold.holds(now.nanoseconds * 1e-9):
            return
        t = (now - start).nanoseconds * 1e-9
        msg = JointState()
        msg.header.stamp = now.to_msg()
        own.append((msg.header.stamp.sec, msg.header.stamp.nanosec))
        msg.name = list(motion.joint_names)
        msg.position = list(motion.positions_at(t).values())
        msg.velocity = list(motion.velocities_at(t).values())
        publisher.publish(msg)

    node.create_subscription(JointState, "joint_states", on_state, 10)
    node.create_timer(1.0 / rate_hz, tick)
    return node


def main(argv: Optional[list[str]] = None) -> int:
    """Publish joint_states until SIGINT/SIGTERM; exit 0 on a clean stop."""
    parser = argparse.ArgumentParser(prog="joint_motion", description=__doc__.split("\n\n")[0])
    parser.add_argument("urdf", nargs="?", metavar="URDF", help="URDF file or URI "
                        "(default: the built-in demo robot)")
    parser.add_argument("--package-path", action="append", default=[], metavar="NAME=DIR")
    parser.add_argument("--rate", type=float, default=50.0, help="messages per second")
    parser.add_argument("--period", type=float, default=8.0, help="slowest joint period (s)")
    parser.add_argument("--namespace", default="")
    parser.add_argument("--node-name", default="demo_joint_motion")
    parser.add_argument("--yield-s", type=float, default=DEFAULT_YIELD_S,
                        help="stop moving for this long after another publisher's joint "
                        "state (a client's sliders); 0: never yield")
    args = parser.parse_args(argv)
    if args.rate <= 0:
        parser.error("--rate must be positive")
    if not args.yield_s >= 0:
        parser.error("--yield-s must be >= 0")

    # ROS imports here: JointMotion itself is usable (and testable) without ROS.
    from bridge.robots._spin import inherited_parent_pid, ros_session, spin_until_signal
    from bridge.robots.errors import RobotError
    from bridge.robots.state_publisher import read_urdf

    try:
        if args.urdf is None:
            from bridge.robots.demo import demo_urdf_path
            path, _ = demo_urdf_path()
            text = path.read_text(encoding="utf-8")
        else:
            text, _ = read_urdf(args.urdf, args.package_path)
        motion = JointMotion(parse_urdf(text), period_s=args.period)
    except (RobotError, ValueError) as exc:
        print(f"joint_motion: {exc}", file=sys.stderr)
        return 2

    with ros_session(parent_pid=inherited_parent_pid()) as session:
        node = create_joint_motion_node(motion, rate_hz=args.rate, node_name=args.node_name,
                                        namespace=args.namespace,
                                        hold=MotionHold(args.yield_s))
        spin_until_signal(session, [node], on_ready=lambda: print(
            f"joint motion ready: {len(motion.joint_names)} joints at {args.rate:g} Hz",
            flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
