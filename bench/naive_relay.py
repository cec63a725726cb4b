"""The baseline: the ROS -> OpenIGTLink relay a Python user would write with pyigtl's own
server and rclpy (subscription callback -> pyigtl message -> server.send_message).

usage: naive_relay.py PORT POSE_TOPIC IMAGE_TOPIC [POSE_DEPTH [CLOUD_TOPIC]]
Prints READY once the server listens. Used by bench_daemon.py and bench_pointcloud.py; not
part of the product.

A PointCloud2 (CLOUD_TOPIC) goes as pyigtl 0.3.4 can send it: its PolyDataMessage takes
points and cells but no attributes (it raises NotImplementedError for them), so the relay
sends the finite points in mm and one polyvertex cell of them, without the colours: a
third of the bytes the daemon sends for the same cloud, whose POLYDATA carries each
point's colour as 4 float32. The points are read the way a numpy user would, as rows of
float32 (x, y, z, rgb): PCL's layout, point_step 16, and nothing else. (pyigtl writes the
cell's ids in the host's byte order where the spec says big-endian, a defect of its own:
the size on the wire is the same.)
"""

import sys
import threading

import numpy as np
import pyigtl
import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.executors import ExternalShutdownException
from sensor_msgs.msg import Image, PointCloud2


def quaternion_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def main() -> None:
    port, pose_topic, image_topic = int(sys.argv[1]), sys.argv[2], sys.argv[3]
    pose_depth = int(sys.argv[4]) if len(sys.argv) > 4 else 1000
    cloud_topic = sys.argv[5] if len(sys.argv) > 5 else None
    # pyigtl's server installs signal handlers: it must live in the main thread.
    server = pyigtl.OpenIGTLinkServer(port=port, local_server=True)
    rclpy.init()
    node = rclpy.create_node("naive_relay")

    def stamp_of(msg) -> float:
        return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9

    def on_pose(msg: PoseStamped) -> None:
        matrix = np.eye(4)
        o, p = msg.pose.orientation, msg.pose.position
        matrix[:3, :3] = quaternion_matrix(o.x, o.y, o.z, o.w)
        matrix[:3, 3] = (p.x * 1000.0, p.y * 1000.0, p.z * 1000.0)
        server.send_message(pyigtl.TransformMessage(matrix, timestamp=stamp_of(msg),
                                                    device_name="pose"), wait=False)

    def on_image(msg: Image) -> None:
        pixels = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(
            1, msg.height, msg.width, 3)
        server.send_message(pyigtl.ImageMessage(pixels, timestamp=stamp_of(msg),
                                                device_name="camera"), wait=False)

    def on_cloud(msg: PointCloud2) -> None:
        rows = np.frombuffer(msg.data, dtype=np.float32).reshape(-1, 4)
        points = rows[:, :3][np.isfinite(rows[:, :3]).all(axis=1)] * 1000.0
        n = len(points)
        vertices = np.concatenate(([n], np.arange(n)))  # one polyvertex cell
        server.send_message(pyigtl.PolyDataMessage(points=points, vertices=vertices,
                                                   timestamp=stamp_of(msg),
                                                   device_name="cloud"), wait=False)

    node.create_subscription(PoseStamped, pose_topic, on_pose, pose_depth)
    if cloud_topic is not None:
        node.create_subscription(PointCloud2, cloud_topic, on_cloud, 10)
    node.create_subscription(Image, image_topic, on_image, 10)
    spinner = threading.Thread(target=rclpy.spin, args=(node,), daemon=True)
    spinner.start()
    print("READY", flush=True)
    try:
        threading.Event().wait()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass


if __name__ == "__main__":
    main()
