"""Publish a 7-link chain on /tf, all 7 transforms in one TFMessage per tick, at RATE Hz.

usage: tf_robot_publisher.py RATE_HZ [--links 7] [--prefix P] [--seconds S] [--count N]
                             [--bad]
Frames: Pbase -> Plink1 -> ... -> Plink7. Each link: translation (n * 1e-5, 0, 0.1) m,
identity rotation, n = the tick number (so a lookup base->linkK reads K * n / 100 mm in x;
10 um a tick is well above the daemon's 1 um change tolerance).
Ticks are paced against a monotonic schedule (catching up if late, never bursting more
than 10 ticks). --bad: every 10th tick also sends a message with NaN translations, one with
empty frame ids, one with a non-unit quaternion and one with 10,000 transforms.
Prints READY, then SENT <n> every 1000 ticks, SENT <n> DONE at the end, and stays alive
(quiet) until stopped. Waits (up to 20 s) for a /tf subscriber first.
"""

import argparse
import math
import time

import rclpy
from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage


def transform(stamp, parent: str, child: str, x: float, y: float = 0.0, z: float = 0.1,
              q=(0.0, 0.0, 0.0, 1.0)) -> TransformStamped:
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id, t.child_frame_id = parent, child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = x, y, z
    r = t.transform.rotation
    r.x, r.y, r.z, r.w = q
    return t


def bad_messages(stamp, prefix: str) -> list:
    nan = float("nan")
    return [
        TFMessage(transforms=[transform(stamp, prefix + "base", prefix + "nan_link", nan, nan,
                                        nan)]),
        TFMessage(transforms=[transform(stamp, "", "", 0.0)]),
        TFMessage(transforms=[transform(stamp, prefix + "base", prefix + "skew", 0.0,
                                        q=(3.0, 0.0, 0.0, 0.0))]),
        TFMessage(transforms=[transform(stamp, prefix + "base", f"{prefix}many{i}", 0.0)
                              for i in range(10_000)]),
    ]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("rate", type=float)
    parser.add_argument("--links", type=int, default=7)
    parser.add_argument("--prefix", default="")
    parser.add_argument("--seconds", type=float, default=0.0)
    parser.add_argument("--count", type=int, default=0)
    parser.add_argument("--bad", action="store_true")
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("test_tf_robot_publisher")
    publisher = node.create_publisher(TFMessage, "/tf", 100)
    deadline = time.monotonic() + 20
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.02)
    print("READY", flush=True)
    names = [args.prefix + "base"] + [f"{args.prefix}link{i}" for i in range(1, args.links + 1)]
    period = 1.0 / args.rate
    start = time.monotonic()
    end = start + args.seconds if args.seconds else math.inf
    n = 0
    try:
        while (not args.count or n < args.count) and time.monotonic() < end:
            n += 1
            due = start + n * period
            now = time.monotonic()
            if due > now:
                time.sleep(due - now)
            elif now - due > 10 * period:  # far behind: skip ahead, never burst
                start = now - n * period
            stamp = node.get_clock().now().to_msg()
            x = n * 1e-5
            publisher.publish(TFMessage(transforms=[
                transform(stamp, names[i], names[i + 1], x) for i in range(args.links)]))
            if args.bad and n % 10 == 0:
                for message in bad_messages(stamp, args.prefix):
                    publisher.publish(message)
            if n % 1000 == 0:
                print(f"SENT {n}", flush=True)
        print(f"SENT {n} DONE", flush=True)
        while True:
            time.sleep(1)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
