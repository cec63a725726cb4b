"""Move every joint of a robot smoothly within its limits: a sensor_msgs/JointState
publisher (50 Hz by default) for the demo robot, or any URDF.

Each actuated joint (moving, not a mimic) follows ``centre + amplitude * sin(2 pi t / T_i +
phase_i)``: the centre is the middle of its limits, the amplitude ``fraction`` of half the
range (continuous joints and joints without limits swing +-pi/2 or +-0.05 m), and every joint
gets its own period and phase so the arm does not move in lockstep. Mimic joints are left
to the state publisher. `JointMotion.positions_at` is pure, for tests.

`MotionHold` (`bridge.robots.demo.motion_hold`) holds it: anything that moves the joints
itself (the demo's FollowJointTrajectory controller, `bridge.robots.demo.trajectory`) holds
them and releases them to blend back into the idle motion; and it yields to another
publisher of ``joint_states`` (a client's sliders through ``set_robot_joints``): nothing for
``--yield-s`` seconds after the last foreign joint state, 3 s by default. Meanwhile it goes
on publishing, at its rate, the pose it saw last (as a robot's driver reports an arm that
stands still: a silent topic would be judged stale): on each foreign state it publishes its
own positions with the foreign ones laid over them at once, then that pose on every tick. A
motion message sent just before the foreign one may reach the state publisher after it (more
likely on a busy machine); the motion's own messages arrive in order, so the one that
follows wins and the arm stays where it was put.

Command line::

    python -m bridge.robots.demo.joint_motion [URDF] [--rate HZ] [--period S]
        [--namespace NS] [--node-name NAME] [--package-path NAME=DIR ...]
        [--trajectory-action NAME | --no-trajectory-action] [--yield-s S]

Without URDF the built-in demo robot is used.
"""

from __future__ import annotations

import argparse
import math
import sys
import threading
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Optional

from bridge.robots.description import RobotDescription, parse_urdf

from bridge.robots.demo.motion_hold import DEFAULT_YIELD_S, MotionHold

__all__ = ["JointMotion", "MotionHold", "create_joint_motion_node", "main"]


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


def create_joint_motion_node(motion: JointMotion, *, rate_hz: float = 50.0,
                             node_name: str = "demo_joint_motion", namespace: str = "",
                             context: Any = None,
                             trajectory_action: Optional[str] = None,
                             hold: Optional[MotionHold] = None,
                             on_yield: Optional[Callable[[float], None]] = None) -> Any:
    """An rclpy node publishing ``motion`` on ``joint_states`` at ``rate_hz`` (for any
    executor, e.g. inside the daemon); rclpy must be initialised. With
    ``trajectory_action``, it also serves FollowJointTrajectory there (see
    `bridge.robots.demo.trajectory`), pausing the idle motion while a goal runs. It also
    listens on ``joint_states``: a message it did not publish (told by its stamp, unique
    per tick) makes it yield per `hold` (made if not given; see `MotionHold`);
    ``on_yield(t)`` is told when such a message starts a yield (t: when it came, seconds
    on the node's clock, the clock of the stamps)."""
    import rclpy
    from sensor_msgs.msg import JointState

    node = rclpy.create_node(node_name, namespace=namespace, context=context)
    publisher = node.create_publisher(JointState, "joint_states", 10)
    start = node.get_clock().now()
    hold = hold if hold is not None else MotionHold()
    last = motion.positions_at(0.0)
    controller = None
    if trajectory_action:
        from bridge.robots.demo.trajectory import create_trajectory_server
        controller = create_trajectory_server(node, hold, motion.joint_names,
                                              lambda: dict(last), action=trajectory_action)

    own: deque[tuple[int, int]] = deque(maxlen=256)  # stamps of our recent messages
    # A tick's yield check and publish, and a foreign state's last word, never interleave
    # (an executor may run the timer and the subscription in two threads).
    publishing = threading.Lock()

    def publish(now: Any, positions: dict[str, float], velocities: list[float]) -> None:
        msg = JointState()
        msg.header.stamp = now.to_msg()
        own.append((msg.header.stamp.sec, msg.header.stamp.nanosec))
        msg.name = list(positions)
        msg.position = list(positions.values())
        msg.velocity = velocities
        publisher.publish(msg)
        last.update(positions)

    def on_state(msg: Any) -> None:  # a foreign publisher: yield, ending on what it set
        if (msg.header.stamp.sec, msg.header.stamp.nanosec) in own:
            return
        now = node.get_clock().now()
        now_s = now.nanoseconds * 1e-9
        starts = hold.foreign_state(now_s)
        with publishing:
            publish(now, {**last, **foreign_positions(msg, last)}, [])
        if starts and on_yield is not None:
            on_yield(now_s)

    def tick() -> None:
        now = node.get_clock().now()
        now_s = now.nanoseconds * 1e-9
        with publishing:
            if hold.yields(now_s):
                # Still at its rate, the pose it was put in: a driver reports a still arm,
                # and a silent joint_states would be judged stale by whoever follows it.
                publish(now, dict(last), [])
                return
            t = (now - start).nanoseconds * 1e-9
            if controller is not None:
                controller.advance(now_s)
            idle = hold.idle
            positions = hold.apply(now_s, motion.positions_at(t))
            # The idle motion's velocities are known; held or blending ones are not given.
            publish(now, positions, list(motion.velocities_at(t).values()) if idle else [])
        if controller is not None:
            controller.report(now_s, positions)

    node.create_subscription(JointState, "joint_states", on_state, 10)
    node.create_timer(1.0 / rate_hz, tick)
    return node


def foreign_positions(msg: Any, joints: dict[str, float]) -> dict[str, float]:
    """The finite positions a foreign JointState sets for the motion's ``joints``."""
    return {name: float(value) for name, value in zip(msg.name, msg.position)
            if name in joints and math.isfinite(value)}


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
    parser.add_argument("--trajectory-action", default=None, metavar="NAME",
                        help="serve control_msgs/action/FollowJointTrajectory there (default "
                             "/joint_trajectory_controller/follow_joint_trajectory)")
    parser.add_argument("--no-trajectory-action", action="store_true",
                        help="only the idle motion, no trajectory action")
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

    action = None
    if not args.no_trajectory_action:
        import importlib.util

        from bridge.robots.demo.trajectory import DEFAULT_ACTION
        action = args.trajectory_action or DEFAULT_ACTION
        if importlib.util.find_spec("control_msgs") is None:
            print("joint_motion: control_msgs is not installed (slicer-ros2-bridge "
                  "build-interfaces builds it): no FollowJointTrajectory action", flush=True)
            action = None
    with ros_session(parent_pid=inherited_parent_pid()) as session:
        node = create_joint_motion_node(motion, rate_hz=args.rate, node_name=args.node_name,
                                        namespace=args.namespace, trajectory_action=action,
                                        hold=MotionHold(args.yield_s),
                                        on_yield=lambda t: print(
                                            f"joint motion yields for {args.yield_s:g} s to "
                                            f"another publisher's joint state (at {t:.6f})",
                                            flush=True))
        served = f", FollowJointTrajectory on {action}" if action else ""
        spin_until_signal(session, [node], on_ready=lambda: print(
            f"joint motion ready: {len(motion.joint_names)} joints at {args.rate:g} Hz"
            f"{served}", flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
