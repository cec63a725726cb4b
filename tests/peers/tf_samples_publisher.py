"""Publish two samples of PARENT -> CHILD with explicit stamps, every 100 ms until stopped.

usage: tf_samples_publisher.py PARENT CHILD SEC
sample 1, stamp SEC     : translation (0, 0, 0) m, identity rotation
sample 2, stamp SEC + 1 : translation (1, 2, 0) m, 90 degrees about z
Both samples go in one TFMessage; re-publishing the same stamps changes nothing for a tf
buffer, and covers the time discovery takes. Prints READY.
"""

import math
import sys
import time

import rclpy
from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage


def transform(sec, parent, child, xyz, quat_xyzw) -> TransformStamped:
    t = TransformStamped()
    t.header.stamp.sec = sec
    t.header.frame_id, t.child_frame_id = parent, child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = xyz
    r = t.transform.rotation
    r.x, r.y, r.z, r.w = quat_xyzw
    return t


def main() -> None:
    parent, child, sec = sys.argv[1], sys.argv[2], int(sys.argv[3])
    rclpy.init()
    node = rclpy.create_node("test_tf_samples_publisher")
    publisher = node.create_publisher(TFMessage, "/tf", 100)
    half = math.sqrt(0.5)
    message = TFMessage(transforms=[
        transform(sec, parent, child, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
        transform(sec + 1, parent, child, (1.0, 2.0, 0.0), (0.0, 0.0, half, half)),
    ])
    print("READY", flush=True)
    try:
        while rclpy.ok():
            publisher.publish(message)
            time.sleep(0.1)
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
