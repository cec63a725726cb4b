"""Publish a chain of frames: PREFIXworld -> PREFIXbase (static, /tf_static, transient local,
published once) and PREFIXbase -> PREFIXlink1 -> PREFIXtool (dynamic, /tf, one TFMessage
holding both links per tick).

usage: tf_chain_publisher.py PREFIX [--rate HZ] [--count N] [--no-static] [--static-only]
                             [--moving] [--then-step]
static  world -> base : translation (0.1, 0.2, 0.3) m, identity rotation
dynamic base -> link1 : translation (0.0, 0.0, 0.5) m, 90 degrees about z
dynamic link1 -> tool : translation (0.25 + n * 1e-4 if --moving else 0.25, 0.0, 0.0) m,
                        90 degrees about x   (n = 1, 2, ... the tick number)
--then-step: after the --count ticks, one more with link1 -> tool at x = 0.26 m (a 10 mm
step): a reader that sees it knows every tick before it was read (one writer, in order).
Stamps are the node clock's now. Waits (up to 20 s) for a /tf subscriber before the first
tick. Prints READY, SENT <n> every 100 ticks, then SENT <n> DONE after --count ticks, and
stays alive (quiet) until stopped.
"""

import argparse
import math
import time

import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

HALF = math.sqrt(0.5)


def transform(stamp, parent, child, xyz, quat_xyzw) -> TransformStamped:
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id, t.child_frame_id = parent, child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = xyz
    r = t.transform.rotation
    r.x, r.y, r.z, r.w = quat_xyzw
    return t


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("prefix")
    parser.add_argument("--rate", type=float, default=50.0)
    parser.add_argument("--count", type=int, default=0)
    parser.add_argument("--no-static", action="store_true")
    parser.add_argument("--static-only", action="store_true")
    parser.add_argument("--moving", action="store_true")
    parser.add_argument("--then-step", action="store_true")
    args = parser.parse_args()
    p = args.prefix
    rclpy.init()
    node = rclpy.create_node("test_tf_chain_publisher")
    if not args.no_static:
        static_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL)
        static_pub = node.create_publisher(TFMessage, "/tf_static", static_qos)
        # Published once, before anyone can have discovered us: only transient local
        # durability gets it to subscribers.
        static_pub.publish(TFMessage(transforms=[transform(
            node.get_clock().now().to_msg(), p + "world", p + "base", (0.1, 0.2, 0.3),
            (0.0, 0.0, 0.0, 1.0))]))
    print("READY", flush=True)
    try:
        if args.static_only:
            while rclpy.ok():
                time.sleep(0.1)
            return
        dynamic_pub = node.create_publisher(TFMessage, "/tf", 100)
        deadline = time.monotonic() + 20
        while dynamic_pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        period = 1.0 / args.rate
        next_time = time.monotonic()
        n = 0
        ticks = args.count + 1 if args.count and args.then_step else args.count
        while rclpy.ok() and (not ticks or n < ticks):
            n += 1
            stamp = node.get_clock().now().to_msg()
            x = 0.25 + (n * 1e-4 if args.moving else 0.0)
            if args.then_step and n > args.count:
                x = 0.26
            dynamic_pub.publish(TFMessage(transforms=[
                transform(stamp, p + "base", p + "link1", (0.0, 0.0, 0.5), (0.0, 0.0, HALF, HALF)),
                transform(stamp, p + "link1", p + "tool", (x, 0.0, 0.0), (HALF, 0.0, 0.0, HALF)),
            ]))
            if n % 100 == 0:
                print(f"SENT {n}", flush=True)
            next_time += period
            delay = next_time - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        print(f"SENT {n} DONE", flush=True)
        while rclpy.ok():
            time.sleep(0.1)
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
