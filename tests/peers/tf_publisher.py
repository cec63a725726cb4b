"""Publish tf2_msgs/TFMessage: one static transform on /tf_static (transient local, once)
and one dynamic transform on /tf at 20 Hz, until stopped.

usage: tf_publisher.py
static: world -> base, translation (0.1, 0.2, 0.3) m, identity rotation
dynamic: base -> tool, translation (0.0, 0.0, 0.5) m, 90 degrees about z
"""

import math

import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage


def transform(node, parent, child, xyz, quat_xyzw) -> TransformStamped:
    t = TransformStamped()
    t.header.stamp = node.get_clock().now().to_msg()
    t.header.frame_id, t.child_frame_id = parent, child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = xyz
    r = t.transform.rotation
    r.x, r.y, r.z, r.w = quat_xyzw
    return t


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("test_tf_publisher")
    static_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)
    static_pub = node.create_publisher(TFMessage, "/tf_static", static_qos)
    dynamic_pub = node.create_publisher(TFMessage, "/tf", 100)
    static_pub.publish(TFMessage(transforms=[
        transform(node, "world", "base", (0.1, 0.2, 0.3), (0.0, 0.0, 0.0, 1.0))]))
    half = math.sqrt(0.5)

    def tick() -> None:
        dynamic_pub.publish(TFMessage(transforms=[
            transform(node, "base", "tool", (0.0, 0.0, 0.5), (0.0, 0.0, half, half))]))

    node.create_timer(0.05, tick)
    print("READY", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass


if __name__ == "__main__":
    main()
