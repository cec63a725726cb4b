"""Fill a tf buffer with one /tf message, then publish a new frame a few times.

usage: tf_flood_publisher.py PREFIX [--frames N] [--sec S] [--new-count K] [--rate HZ]
flood: one TFMessage of N transforms PREFIXworld -> PREFIXjunkNNNN (N = 9999 by default),
       translation (0, 0, 1) m, identity rotation, stamped sec = S, nanosec = 0 (default:
       the node clock's now)
new:   then K TFMessages (2 by default) at HZ (20 by default), each one transform
       PREFIXworld -> PREFIXnew, translation (1, 0, 0) m, stamped with the clock's now
Waits (up to 20 s) for a /tf subscriber before the flood. Prints READY, FLOOD SENT, NEW <n>
after each new message, NEW DONE after the last, and stays alive (quiet) until stopped.
"""

import argparse
import time

import rclpy
from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage

from peer_teardown import spin_until_stopped


def transform(sec: int, nanosec: int, parent: str, child: str, x: float, z: float):
    t = TransformStamped()
    t.header.stamp.sec, t.header.stamp.nanosec = sec, nanosec
    t.header.frame_id, t.child_frame_id = parent, child
    t.transform.translation.x, t.transform.translation.z = x, z
    t.transform.rotation.w = 1.0
    return t


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("prefix")
    parser.add_argument("--frames", type=int, default=9999)
    parser.add_argument("--sec", type=int, default=None)
    parser.add_argument("--new-count", type=int, default=2)
    parser.add_argument("--rate", type=float, default=20.0)
    args = parser.parse_args()
    p = args.prefix
    rclpy.init()
    node = rclpy.create_node("test_tf_flood_publisher")
    pub = node.create_publisher(TFMessage, "/tf", 100)  # reliable, as tf2's
    print("READY", flush=True)
    deadline = time.monotonic() + 20
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    now = node.get_clock().now().to_msg()
    sec, nanosec = (now.sec, now.nanosec) if args.sec is None else (args.sec, 0)
    pub.publish(TFMessage(transforms=[
        transform(sec, nanosec, p + "world", f"{p}junk{i:04}", 0.0, 1.0)
        for i in range(args.frames)]))
    print("FLOOD SENT", flush=True)
    for n in range(1, args.new_count + 1):
        time.sleep(1.0 / args.rate)
        now = node.get_clock().now().to_msg()
        pub.publish(TFMessage(transforms=[
            transform(now.sec, now.nanosec, p + "world", p + "new", 1.0, 0.0)]))
        print(f"NEW {n}", flush=True)
    print("NEW DONE", flush=True)
    spin_until_stopped(node)


if __name__ == "__main__":
    main()
