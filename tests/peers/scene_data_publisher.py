"""Publish one of each kind of data a Slicer scene shows, at 5 Hz, until stopped.

usage: scene_data_publisher.py

- /tf_static world -> base: (0.1, 0.2, 0.3) m, identity;
  /tf base -> tool: (0.01, 0.02, 0.03) m, 90 degrees about z;
- /scene_image: sensor_msgs/Image mono8, 4 wide, 3 high, pixel (row r, column c) = 10 r + c;
- /scene_cloud: sensor_msgs/PointCloud2, organised 2 x 2, x y z float32 + rgb (packed in a
  float32), point i at (i, 2 i, 3 i) cm, colour (40 i, 80, 120);
- /scene_markers: visualization_msgs/MarkerArray in base: a CUBE (ns "scene", id 1,
  0.02 m, red, at (0, 0, 0.05) m), a TEXT_VIEW_FACING (id 2, "hello", green, at
  (0.03, 0, 0) m) and POINTS (id 3, blue, at (0, 0, 0), (0.01, 0, 0), (0, 0.01, 0) m);
- /scene_text: std_msgs/String "note <n>".
Prints READY once its publishers exist.
"""

import math
import struct

import rclpy
from geometry_msgs.msg import Point, TransformStamped
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import Image, PointCloud2, PointField
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker, MarkerArray

from peer_teardown import spin_until_stopped


def transform(node, parent, child, xyz, yaw):
    t = TransformStamped()
    t.header.stamp = node.get_clock().now().to_msg()
    t.header.frame_id, t.child_frame_id = parent, child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = xyz
    t.transform.rotation.z, t.transform.rotation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return t


def cloud(node):
    msg = PointCloud2(height=2, width=2, is_bigendian=False, is_dense=True, point_step=16)
    msg.header.frame_id = "base"
    msg.header.stamp = node.get_clock().now().to_msg()
    msg.fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                  for i, n in enumerate(("x", "y", "z", "rgb"))]
    msg.row_step = 32
    data = b""
    for i in range(4):
        rgb = struct.unpack("<f", struct.pack("<I", (40 * i) << 16 | 80 << 8 | 120))[0]
        data += struct.pack("<ffff", 0.01 * i, 0.02 * i, 0.03 * i, rgb)
    msg.data = data
    return msg


def markers(node):
    cube = Marker(ns="scene", id=1, type=Marker.CUBE, action=Marker.ADD)
    cube.header.frame_id = "base"
    cube.pose.position.z, cube.pose.orientation.w = 0.05, 1.0
    cube.scale.x = cube.scale.y = cube.scale.z = 0.02
    cube.color.r, cube.color.a = 1.0, 1.0
    text = Marker(ns="scene", id=2, type=Marker.TEXT_VIEW_FACING, action=Marker.ADD,
                  text="hello")
    text.header.frame_id = "base"
    text.pose.position.x, text.pose.orientation.w = 0.03, 1.0
    text.scale.z = 0.01
    text.color.g, text.color.a = 1.0, 1.0
    dots = Marker(ns="scene", id=3, type=Marker.POINTS, action=Marker.ADD,
                  points=[Point(x=0.01 * (i == 1), y=0.01 * (i == 2)) for i in range(3)])
    dots.header.frame_id = "base"
    dots.pose.orientation.w = 1.0
    dots.scale.x = dots.scale.y = 0.005
    dots.color.b, dots.color.a = 1.0, 1.0
    return MarkerArray(markers=[cube, text, dots])


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("scene_data_publisher")
    static = node.create_publisher(TFMessage, "/tf_static", QoSProfile(
        depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    tf = node.create_publisher(TFMessage, "/tf", 10)
    image = node.create_publisher(Image, "/scene_image", 10)
    points = node.create_publisher(PointCloud2, "/scene_cloud", 10)
    marks = node.create_publisher(MarkerArray, "/scene_markers", 10)
    text = node.create_publisher(String, "/scene_text", 10)
    static.publish(TFMessage(transforms=[transform(node, "world", "base", (0.1, 0.2, 0.3), 0)]))
    count = [0]

    def tick() -> None:
        count[0] += 1
        tf.publish(TFMessage(transforms=[transform(node, "base", "tool", (0.01, 0.02, 0.03),
                                                   math.pi / 2)]))
        img = Image(height=3, width=4, encoding="mono8", step=4,
                    data=bytes(10 * r + c for r in range(3) for c in range(4)))
        img.header.frame_id = "base"
        img.header.stamp = node.get_clock().now().to_msg()
        image.publish(img)
        points.publish(cloud(node))
        marks.publish(markers(node))
        text.publish(String(data=f"note {count[0]}"))
    node.create_timer(0.2, tick)
    print("READY", flush=True)
    spin_until_stopped(node)


if __name__ == "__main__":
    main()
