"""Publish sensor_msgs/JointState at 20 Hz with fixed names, positions and stamp, until stopped.

usage: robot_joint_state_publisher.py [--topic joint_states] [--stamp SEC NANOSEC]
                                      NAME=POSITION [NAME=POSITION ...]
Reliable QoS, depth 10. Prints READY once the publisher exists.
"""

import argparse

import rclpy
from rclpy.executors import ExternalShutdownException
from sensor_msgs.msg import JointState


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--topic", default="joint_states")
    parser.add_argument("--stamp", nargs=2, type=int, default=None)
    parser.add_argument("joints", nargs="+")
    args = parser.parse_args()
    names, positions = [], []
    for item in args.joints:
        name, _, value = item.partition("=")
        names.append(name)
        positions.append(float(value))
    rclpy.init()
    node = rclpy.create_node("test_robot_joint_state_publisher")
    publisher = node.create_publisher(JointState, args.topic, 10)

    def tick() -> None:
        msg = JointState()
        if args.stamp:
            msg.header.stamp.sec, msg.header.stamp.nanosec = args.stamp
        else:
            msg.header.stamp = node.get_clock().now().to_msg()
        msg.name = names
        msg.position = positions
        publisher.publish(msg)

    node.create_timer(0.05, tick)
    print("READY", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass


if __name__ == "__main__":
    main()
