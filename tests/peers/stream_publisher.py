"""Publish numbered messages as fast as asked, until stopped or --count is reached.

usage: stream_publisher.py TOPIC RATE_HZ [--image WIDTHxHEIGHT] [--count N] [--stamp-in-y]
PoseStamped (default): position.x = n * 1e-6 m, so a client sees n / 1000 mm;
--stamp-in-y: also position.y = the header stamp's seconds modulo 1000, in m (a client sees
the stamp in mm = ms, for one whose transform node keeps no header time: Slicer's).
--image: sensor_msgs/Image rgb8 of that size, header.frame_id = "seq:n".
Waits (up to 20 s) for a subscriber before the first message.
Prints READY, then SENT <n> every 100 messages and at the end.
"""

import argparse
import time

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import Image


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("topic")
    parser.add_argument("rate", type=float)
    parser.add_argument("--image")
    parser.add_argument("--count", type=int, default=0)
    parser.add_argument("--stamp-in-y", action="store_true")
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("test_stream_publisher")
    if args.image:
        width, height = (int(v) for v in args.image.split("x"))
        publisher = node.create_publisher(Image, args.topic, 10)
        template = Image(height=height, width=width, encoding="rgb8", step=width * 3)
        template.data = np.random.default_rng(1).integers(
            0, 255, size=width * height * 3, dtype=np.uint8).tobytes()
    else:
        publisher = node.create_publisher(PoseStamped, args.topic, 1000)
    print("READY", flush=True)
    # Messages published before discovery matches a subscriber are lost (volatile QoS).
    deadline = time.monotonic() + 20
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    period = 1.0 / args.rate
    next_time = time.monotonic()
    n = 0
    try:
        while rclpy.ok() and (not args.count or n < args.count):
            n += 1
            if args.image:
                msg = template
                msg.header.frame_id = f"seq:{n}"
            else:
                msg = PoseStamped()
                msg.header.frame_id = "world"
                msg.pose.position.x = n * 1e-6
                msg.pose.orientation.w = 1.0
            msg.header.stamp = node.get_clock().now().to_msg()
            if args.stamp_in_y and not args.image:
                msg.pose.position.y = (msg.header.stamp.sec % 1000
                                       + msg.header.stamp.nanosec * 1e-9)
            publisher.publish(msg)
            if n % 100 == 0:
                print(f"SENT {n}", flush=True)
            next_time += period
            delay = next_time - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        print(f"SENT {n} DONE", flush=True)
        while rclpy.ok():  # stay alive (late joiners, transient local) until stopped
            time.sleep(0.1)
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
