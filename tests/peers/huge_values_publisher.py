"""Publish poses and transforms whose lengths are finite in metres but not once in
millimetres as float32 (what a TRANSFORM carries), between good ones, until stopped.

usage: huge_values_publisher.py TOPIC
TOPIC: geometry_msgs/PoseStamped at 50 Hz, frame "world", identity rotation, x cycling
through 1e306, 0.25, 1e36, 0.5 m (y = z = 0).
/tf at 50 Hz, one TFMessage each: world -> huge (x 1e306 m), world -> big (x 1e36 m),
world -> a and a -> b (x 3e35 m each: each fits, world -> b does not), world -> ok (x 0.1 m).
Prints READY once the publishers exist.
"""

import sys

import rclpy
from geometry_msgs.msg import PoseStamped, TransformStamped
from tf2_msgs.msg import TFMessage

from peer_teardown import spin_until_stopped

POSE_X = (1e306, 0.25, 1e36, 0.5)
LINKS = (("world", "huge", 1e306), ("world", "big", 1e36), ("world", "a", 3e35),
         ("a", "b", 3e35), ("world", "ok", 0.1))


def main() -> None:
    topic = sys.argv[1]
    rclpy.init()
    node = rclpy.create_node("test_huge_values_publisher")
    poses = node.create_publisher(PoseStamped, topic, 10)
    tf = node.create_publisher(TFMessage, "/tf", 100)
    sent = [0]

    def tick() -> None:
        now = node.get_clock().now().to_msg()
        pose = PoseStamped()
        pose.header.stamp = now
        pose.header.frame_id = "world"
        pose.pose.position.x = POSE_X[sent[0] % len(POSE_X)]
        pose.pose.orientation.w = 1.0
        poses.publish(pose)
        transforms = []
        for parent, child, x in LINKS:
            t = TransformStamped()
            t.header.stamp = now
            t.header.frame_id, t.child_frame_id = parent, child
            t.transform.translation.x = x
            t.transform.rotation.w = 1.0
            transforms.append(t)
        tf.publish(TFMessage(transforms=transforms))
        sent[0] += 1

    node.create_timer(0.02, tick)
    print("READY", flush=True)
    spin_until_stopped(node)


if __name__ == "__main__":
    main()
