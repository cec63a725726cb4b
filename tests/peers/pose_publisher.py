"""Publish a geometry_msgs/PoseStamped at 20 Hz until stopped.

usage: pose_publisher.py TOPIC X Y Z QX QY QZ QW [FRAME]
"""

import sys

import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.executors import ExternalShutdownException


def main() -> None:
    topic = sys.argv[1]
    x, y, z, qx, qy, qz, qw = (float(v) for v in sys.argv[2:9])
    frame = sys.argv[9] if len(sys.argv) > 9 else "world"
    rclpy.init()
    node = rclpy.create_node("test_pose_publisher")
    publisher = node.create_publisher(PoseStamped, topic, 10)

    def tick() -> None:
        msg = PoseStamped()
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.header.frame_id = frame
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x, y, z
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = qx, qy, qz, qw
        publisher.publish(msg)

    node.create_timer(0.05, tick)
    print("READY", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass


if __name__ == "__main__":
    main()
