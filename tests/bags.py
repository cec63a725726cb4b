"""Bags for the player's tests and bench, written by rosbags (its writer and its typestore
serialize CDR without ROS): an independent writer, as a bag recorded elsewhere is.

`write_robot_bag`: the demo robot (its URDF on /robot_description; meshes by package path)
with /tf_static world -> base_link, /tf moving base_link's parent ``world`` -> ``base``
... see below, /joint_states and a sensor_msgs/Image, each state known to the test."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

NS = 1_000_000_000
# The bag's clock starts here (an arbitrary epoch time, as a recording's would be).
T0 = 1_700_000_000 * NS
JOINTS = ("joint_1", "joint_2", "joint_3", "joint_4", "joint_5", "joint_6")
IMAGE_SHAPE = (48, 64, 3)  # rgb8


def typestore() -> Any:
    return get_typestore(Stores.ROS2_JAZZY)


@dataclass
class RobotBag:
    """What a robot bag holds, for the test to check what it is shown against."""

    path: Path  # the rosbag2 folder
    mcap: Path  # its .mcap file
    urdf: str
    times: list[int] = field(default_factory=list)  # log times of the states, ns
    joints: list[dict[str, float]] = field(default_factory=list)  # at each time
    base: list[tuple[float, float, float]] = field(default_factory=list)  # world->base_link
    image_times: list[int] = field(default_factory=list)
    images: list[bytes] = field(default_factory=list)

    def state_at(self, t_ns: int) -> int:
        """The index of the last state at or before ``t_ns``."""
        index = max(i for i, t in enumerate(self.times) if t <= t_ns)
        return index

    def image_at(self, t_ns: int) -> bytes:
        return self.images[max(i for i, t in enumerate(self.image_times) if t <= t_ns)]


def joint_values(k: int) -> dict[str, float]:
    """Joint positions of state ``k``, inside the demo robot's limits (the right finger
    mimics the left: not in the message, as a gripper's driver leaves it out)."""
    values = {name: 0.6 * math.sin(0.05 * k + i) for i, name in enumerate(JOINTS)}
    values["finger_left_joint"] = 0.0125 + 0.01 * math.sin(0.07 * k)
    return values


def base_translation(k: int) -> tuple[float, float, float]:
    return (0.001 * k, 0.02, 0.5 * math.cos(0.01 * k))


def image_pixels(k: int) -> bytes:
    rng = np.random.default_rng(k)
    return rng.integers(0, 256, size=IMAGE_SHAPE, dtype=np.uint8).tobytes()


def _stamp(ts: Any, t_ns: int) -> Any:
    sec, nanosec = divmod(t_ns, NS)
    return ts.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _header(ts: Any, t_ns: int, frame: str) -> Any:
    return ts.types["std_msgs/msg/Header"](stamp=_stamp(ts, t_ns), frame_id=frame)


def tf_message(ts: Any, t_ns: int, parent: str, child: str,
               xyz: tuple[float, float, float],
               xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)) -> Any:
    T = ts.types
    transform = T["geometry_msgs/msg/Transform"](
        translation=T["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2]),
        rotation=T["geometry_msgs/msg/Quaternion"](x=xyzw[0], y=xyzw[1], z=xyzw[2],
                                                   w=xyzw[3]))
    return T["tf2_msgs/msg/TFMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](
        header=_header(ts, t_ns, parent), child_frame_id=child, transform=transform)])


def write_robot_bag(folder: Path, urdf: str, *, states: int = 200, period_ns: int = NS // 100,
                    image_every: int = 10) -> RobotBag:
    """``states`` joint states and /tf (world -> base_link) every ``period_ns``, an image
    every ``image_every`` states; the description at the start (latched, as
    robot_state_publisher's)."""
    ts = typestore()
    T = ts.types
    bag = RobotBag(folder, folder / f"{folder.name}.mcap", urdf)
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        description = writer.add_connection("/robot_description", "std_msgs/msg/String",
                                            typestore=ts)
        tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
        joints = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState",
                                       typestore=ts)
        image = writer.add_connection("/camera/image", "sensor_msgs/msg/Image", typestore=ts)
        writer.write(description, T0, ts.serialize_cdr(T["std_msgs/msg/String"](data=urdf),
                                                       "std_msgs/msg/String"))
        for k in range(states):
            t = T0 + (k + 1) * period_ns
            values = joint_values(k)
            xyz = base_translation(k)
            writer.write(tf, t, ts.serialize_cdr(tf_message(ts, t, "world", "base_link", xyz),
                                                 "tf2_msgs/msg/TFMessage"))
            state = T["sensor_msgs/msg/JointState"](
                header=_header(ts, t, ""), name=list(values),
                position=np.array(list(values.values()), dtype=np.float64),
                velocity=np.zeros(0), effort=np.zeros(0))
            writer.write(joints, t, ts.serialize_cdr(state, "sensor_msgs/msg/JointState"))
            bag.times.append(t)
            bag.joints.append(values)
            bag.base.append(xyz)
            if k % image_every == 0:
                pixels = image_pixels(k)
                h, w, ch = IMAGE_SHAPE
                msg = T["sensor_msgs/msg/Image"](
                    header=_header(ts, t, "camera"), height=h, width=w, encoding="rgb8",
                    is_bigendian=0, step=w * ch, data=np.frombuffer(pixels, dtype=np.uint8))
                writer.write(image, t, ts.serialize_cdr(msg, "sensor_msgs/msg/Image"))
                bag.image_times.append(t)
                bag.images.append(pixels)
    return bag


def write_tf_bag(folder: Path, *, seconds: float, hz: float) -> Iterator[int]:
    """A bag of /tf alone (world -> base_link moving) at ``hz`` for ``seconds``: the bench's
    long bag. Yields each message's log time as written (for progress)."""
    ts = typestore()
    period = int(NS / hz)
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
        for k in range(int(seconds * hz)):
            t = T0 + k * period
            writer.write(tf, t, ts.serialize_cdr(tf_message(ts, t, "world", "base_link",
                                                            base_translation(k)),
                                                 "tf2_msgs/msg/TFMessage"))
            yield t
