"""Publish hostile-but-legal ROS messages on the topics a daemon subscribes to.

usage: bad_topic_publisher.py PREFIX [--rounds N] [--rate HZ]
Per round: PREFIXpose PoseStamped with NaN position and an infinite orientation;
PREFIXarray Float64MultiArray with 2,000,000 doubles (16 MB) containing NaN and inf;
PREFIXimage sensor_msgs/Image whose width x height x step disagree with its data (10x10
rgb8, 7 bytes of data); PREFIXtext String of 1 MB of invalid-looking text and an empty one;
PREFIXpose with empty frame_id. Waits (up to 20 s) for subscribers on every topic first.
Prints READY, ROUND <n> after each round, DONE at the end, and stays alive until stopped.
"""

import argparse
import time

import rclpy
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import Image
from std_msgs.msg import Float64MultiArray, String


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("prefix")
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--rate", type=float, default=20.0)
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("test_bad_topic_publisher")
    p = args.prefix
    pose = node.create_publisher(PoseStamped, p + "pose", 10)
    array = node.create_publisher(Float64MultiArray, p + "array", 10)
    image = node.create_publisher(Image, p + "image", 10)
    text = node.create_publisher(String, p + "text", 10)
    publishers = (pose, array, image, text)
    deadline = time.monotonic() + 20
    while any(pub.get_subscription_count() == 0 for pub in publishers) \
            and time.monotonic() < deadline:
        time.sleep(0.02)
    print("READY", flush=True)
    nan, inf = float("nan"), float("inf")
    huge = [0.0] * 2_000_000
    huge[0], huge[1] = nan, inf
    try:
        for n in range(1, args.rounds + 1):
            bad = PoseStamped()
            bad.header.frame_id = "map"
            bad.pose.position.x = nan
            bad.pose.orientation.w = inf
            pose.publish(bad)
            empty = PoseStamped()  # empty frame_id, zero quaternion
            pose.publish(empty)
            array.publish(Float64MultiArray(data=huge))
            picture = Image(height=10, width=10, encoding="rgb8", step=30, data=bytes(7))
            image.publish(picture)
            text.publish(String(data="\u0000\ufffd" * 500_000))
            text.publish(String(data=""))
            print(f"ROUND {n}", flush=True)
            time.sleep(1.0 / args.rate)
        print("DONE", flush=True)
        while True:
            time.sleep(1)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
