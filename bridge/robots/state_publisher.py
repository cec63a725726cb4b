"""A robot state publisher in Python, for any URDF (robot_state_publisher is not on PyPI).

What it does, like the C++ ``robot_state_publisher``:

- parameter ``robot_description`` (string) holds the URDF; setting it to another valid
  URDF swaps the robot (an invalid one is refused with the parse error as the reason);
- topic ``robot_description`` (std_msgs/String, reliable, transient local, depth 1): the URDF;
- ``/tf_static`` (tf2_msgs/TFMessage, transient local): fixed joints (and floating/planar
  ones, held at their origin), sent at start and when the URDF or the prefix changes;
- subscribes ``joint_states`` (sensor_msgs/JointState, best effort so any publisher
  matches) and publishes ``/tf`` for the moving joints the message names plus the mimic
  joints that follow them, stamped with the joint state's stamp (now if it is zero);
- parameter / option ``frame_prefix`` is prepended to every frame id ("robot1/").

Topic names ``robot_description`` and ``joint_states`` are relative (they follow the
namespace); ``/tf`` and ``/tf_static`` are absolute, as in ROS.

Command line (the ``slicer-ros2-bridge state-publisher`` subcommand calls `main`)::

    state-publisher URDF [--package-path NAME=DIR ...] [--namespace NS]
                         [--frame-prefix PREFIX] [--node-name NAME]

URDF is a file path or a ``package://`` / ``file://`` URI (resolved with the package paths).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np
from geometry_msgs.msg import TransformStamped
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from bridge.robots._spin import inherited_parent_pid, ros_session, spin_until_signal
from bridge.robots.description import RobotDescription, parse_urdf
from bridge.robots.errors import RobotError
from bridge.robots.joint_states import JointStateTracker, joint_frames
from bridge.robots.resources import PackageResolver, parse_package_path_option
from bridge.ros.qos import LATCHED_QOS, TF_QOS

__all__ = ["DEFAULT_NODE_NAME", "StatePublisherNode", "transforms_message", "main"]

DEFAULT_NODE_NAME = "robot_state_publisher"

# Best effort accepts reliable and best-effort publishers alike (as robot_state_publisher).
JOINT_STATES_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE)


def transforms_message(description: RobotDescription, transforms: Mapping[str, np.ndarray],
                       stamp: object, frame_prefix: str = "") -> TFMessage:
    """A TFMessage with one TransformStamped per joint of ``transforms`` (4x4, metres):
    parent link -> child link, frame ids prefixed."""
    message = TFMessage()
    out = []
    for frame in joint_frames(description, transforms, frame_prefix):
        t = TransformStamped()
        t.header.stamp = stamp
        t.header.frame_id = frame.parent
        t.child_frame_id = frame.child
        tr = t.transform.translation
        tr.x, tr.y, tr.z = frame.translation
        r = t.transform.rotation
        r.x, r.y, r.z, r.w = frame.rotation
        out.append(t)
    message.transforms = out
    return message


class StatePublisherNode(Node):
    """The robot state publisher node (see the module doc)."""

    def __init__(self, urdf: str, *, node_name: str = DEFAULT_NODE_NAME, namespace: str = "",
                 frame_prefix: str = "", **node_kwargs: object) -> None:
        super().__init__(node_name, namespace=namespace, **node_kwargs)  # type: ignore[arg-type]
        self._description = parse_urdf(urdf)  # raises UrdfError before any ROS entity exists
        self._warned: set[str] = set()
        self._state = JointStateTracker(self._description, self._warn_once)
        self.declare_parameter("robot_description", urdf,
                               ParameterDescriptor(description="The robot's URDF (XML)."))
        self.declare_parameter("frame_prefix", frame_prefix,
                               ParameterDescriptor(description="Prefix of every tf frame id."))
        self._frame_prefix = frame_prefix
        self._description_pub = self.create_publisher(String, "robot_description", LATCHED_QOS)
        self._static_pub = self.create_publisher(TFMessage, "/tf_static", LATCHED_QOS)
        self._tf_pub = self.create_publisher(TFMessage, "/tf", TF_QOS)
        self.create_subscription(JointState, "joint_states", self._on_joint_state,
                                 JOINT_STATES_QOS)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        for warning in self._description.warnings:
            self.get_logger().warning(warning)  # type: ignore[no-untyped-call]
        self._publish_description()

    @property
    def description(self) -> RobotDescription:
        return self._description

    # ------------------------------------------------------------------ publishing

    def _publish_description(self) -> None:
        self._description_pub.publish(String(data=self._description.xml))
        static = self._state.kinematics.fixed_joint_transforms()
        self._static_pub.publish(transforms_message(
            self._description, static, self.get_clock().now().to_msg(), self._frame_prefix))
        self.get_logger().info(  # type: ignore[no-untyped-call]  # rclpy: unannotated
            f"robot {self._description.name!r}: {len(self._description.links)} links, "
            f"{len(self._state.kinematics.moving_joints)} moving joints, {len(static)} static "
            f"transforms on /tf_static")

    def _on_joint_state(self, msg: JointState) -> None:
        transforms = self._state.update(list(msg.name), list(msg.position))
        if not transforms:
            return
        stamp = msg.header.stamp
        if stamp.sec == 0 and stamp.nanosec == 0:
            stamp = self.get_clock().now().to_msg()
        self._tf_pub.publish(transforms_message(self._description, transforms, stamp,
                                                self._frame_prefix))

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self.get_logger().warning(text)  # type: ignore[no-untyped-call]

    # ------------------------------------------------------------------ parameters

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        new_description: Optional[RobotDescription] = None
        new_prefix: Optional[str] = None
        for p in params:
            if p.name == "robot_description":
                if p.type_ != Parameter.Type.STRING:
                    return SetParametersResult(successful=False,
                                               reason="robot_description must be a string")
                try:
                    new_description = parse_urdf(p.value)
                except RobotError as exc:
                    return SetParametersResult(successful=False, reason=str(exc))
            elif p.name == "frame_prefix":
                if p.type_ != Parameter.Type.STRING:
                    return SetParametersResult(successful=False,
                                               reason="frame_prefix must be a string")
                new_prefix = str(p.value)
        if new_prefix is not None:
            self._frame_prefix = new_prefix
        if new_description is not None:
            self._description = new_description
            self._state = JointStateTracker(new_description, self._warn_once)
        if new_description is not None or new_prefix is not None:
            self._publish_description()
        return SetParametersResult(successful=True)


# ---------------------------------------------------------------------------- command line


def build_parser(prog: str = "slicer-ros2-bridge state-publisher") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog, description="Publish a robot's URDF, /tf_static and /tf (from joint_states "
                               "by forward kinematics), like ROS's robot_state_publisher.")
    parser.add_argument("urdf", metavar="URDF",
                        help="URDF file, or a package:// or file:// URI to one")
    parser.add_argument("--package-path", action="append", default=[], metavar="NAME=DIR",
                        help="folder of package NAME for package:// URIs (repeatable)")
    parser.add_argument("--namespace", default="", help="ROS namespace of the node")
    parser.add_argument("--frame-prefix", default="", help="prefix of every tf frame id")
    parser.add_argument("--node-name", default=DEFAULT_NODE_NAME, help="ROS node name")
    return parser


def read_urdf(spec: str, package_options: Sequence[str]) -> tuple[str, dict[str, Path]]:
    """The URDF text named by ``spec`` (path or URI) and the parsed ``--package-path``s."""
    packages = dict(parse_package_path_option(o) for o in package_options)
    path = PackageResolver(packages).resolve(spec)
    try:
        return path.read_text(encoding="utf-8"), packages
    except (OSError, UnicodeDecodeError) as exc:
        raise RobotError(str(path), "a readable UTF-8 URDF file", str(exc)) from None


def main(argv: Optional[list[str]] = None) -> int:
    """Run the state publisher until SIGINT/SIGTERM; 0 on a clean stop, 2 on bad input."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        urdf, _ = read_urdf(args.urdf, args.package_path)
        parse_urdf(urdf)  # fail before ROS starts
    except RobotError as exc:
        print(f"state-publisher: {exc}", file=sys.stderr)
        return 2
    with ros_session(parent_pid=inherited_parent_pid()) as session:
        node = StatePublisherNode(urdf, node_name=args.node_name, namespace=args.namespace,
                                  frame_prefix=args.frame_prefix)
        name = node.get_fully_qualified_name()
        spin_until_signal(session, [node],
                          on_ready=lambda: print(f"state publisher {name} ready", flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
