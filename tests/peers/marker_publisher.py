"""Publish RViz markers, a Path, a polygon and a point as a test's control file says.

usage: marker_publisher.py CONTROL_FILE

tf: /tf_static world -> base (0.1, 0.2, 0.3) m, identity; /tf world -> moving at 20 Hz,
translation from the control file's "moving" (default 0, 0, 0), identity rotation.

CONTROL_FILE is JSON {"seq": N, "markers": [...], "marker": {...}, "path": {...},
"polygon": {...}, "point": {...}, "moving": [x, y, z], "statics": [[parent, child, x, y,
z], ...]}, rewritten whole by the test
(rename). Each time its seq changes the peer publishes, ONCE, what it holds: "markers" as
one MarkerArray on /test_markers, "marker" as a Marker on /test_marker, the others on
/test_path, /test_polygon, /test_point, "statics" (with world -> base) on /tf_static;
then prints "APPLIED N". Nothing is published
before the daemon's subscriptions have matched (reliable QoS: then nothing is lost), so
a marker's lifetime is not renewed by repeats.

A marker: {"ns", "id", "type" (int), "action" (int, default ADD), "frame",
"pos": [x, y, z], "quat": [x, y, z, w], "scale": [x, y, z], "color": [r, g, b, a],
"points": [[x, y, z], ...], "colors": [[r, g, b, a], ...], "text", "mesh",
"lifetime" (s), "embedded" (bool), "locked" (bool: frame_locked)}.
Path/polygon: {"frame", "points"}; point: {"frame", "point"}.
"""

import json
import os
import sys

import rclpy
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import (Point, Point32, PointStamped, PolygonStamped, PoseStamped,
                               TransformStamped)
from nav_msgs.msg import Path
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import ColorRGBA
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker, MarkerArray


def marker(spec: dict) -> Marker:
    m = Marker()
    m.header.frame_id = spec.get("frame", "base")
    m.ns = spec.get("ns", "")
    m.id = int(spec.get("id", 0))
    m.type = int(spec.get("type", Marker.CUBE))
    m.action = int(spec.get("action", Marker.ADD))
    p = spec.get("pos", [0.0, 0.0, 0.0])
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in p)
    q = spec.get("quat", [0.0, 0.0, 0.0, 1.0])
    o = m.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in q)
    s = spec.get("scale", [1.0, 1.0, 1.0])
    m.scale.x, m.scale.y, m.scale.z = (float(v) for v in s)
    c = spec.get("color", [1.0, 1.0, 1.0, 1.0])
    m.color = ColorRGBA(r=float(c[0]), g=float(c[1]), b=float(c[2]), a=float(c[3]))
    m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in spec.get("points", [])]
    m.colors = [ColorRGBA(r=float(r), g=float(g), b=float(b), a=float(a))
                for r, g, b, a in spec.get("colors", [])]
    m.text = spec.get("text", "")
    m.mesh_resource = spec.get("mesh", "")
    m.mesh_use_embedded_materials = bool(spec.get("embedded", False))
    m.frame_locked = bool(spec.get("locked", False))
    life = float(spec.get("lifetime", 0.0))
    m.lifetime = Duration(sec=int(life), nanosec=int(round((life - int(life)) * 1e9)))
    return m


def transform(node, parent: str, child: str, xyz) -> TransformStamped:
    t = TransformStamped()
    t.header.stamp = node.get_clock().now().to_msg()
    t.header.frame_id, t.child_frame_id = parent, child
    tr = t.transform.translation
    tr.x, tr.y, tr.z = (float(v) for v in xyz)
    t.transform.rotation.w = 1.0
    return t


def main() -> None:
    control = sys.argv[1]
    rclpy.init()
    node = rclpy.create_node("test_marker_publisher")
    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    static_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)
    pubs = {
        "markers": node.create_publisher(MarkerArray, "/test_markers", reliable),
        "marker": node.create_publisher(Marker, "/test_marker", reliable),
        "path": node.create_publisher(Path, "/test_path", reliable),
        "polygon": node.create_publisher(PolygonStamped, "/test_polygon", reliable),
        "point": node.create_publisher(PointStamped, "/test_point", reliable),
    }
    static_pub = node.create_publisher(TFMessage, "/tf_static", static_qos)
    tf_pub = node.create_publisher(TFMessage, "/tf", 100)
    static_pub.publish(TFMessage(transforms=[transform(node, "world", "base",
                                                       (0.1, 0.2, 0.3))]))
    state = {"seq": None, "moving": [0.0, 0.0, 0.0], "mtime": None}

    def publish(doc: dict) -> None:
        for key, pub in pubs.items():
            if key not in doc:
                continue
            if pub.get_subscription_count() < 1:
                return  # not matched yet: try again on the next tick
        if "statics" in doc:
            static_pub.publish(TFMessage(transforms=[
                transform(node, "world", "base", (0.1, 0.2, 0.3))] + [
                transform(node, parent, child, xyz) for parent, child, *xyz in doc["statics"]]))
        if "markers" in doc:
            pubs["markers"].publish(MarkerArray(markers=[marker(m) for m in doc["markers"]]))
        if "marker" in doc:
            pubs["marker"].publish(marker(doc["marker"]))
        if "path" in doc:
            msg = Path()
            msg.header.frame_id = doc["path"].get("frame", "base")
            for x, y, z in doc["path"]["points"]:
                pose = PoseStamped()
                pose.header.frame_id = msg.header.frame_id
                pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (
                    float(x), float(y), float(z))
                pose.pose.orientation.w = 1.0
                msg.poses.append(pose)
            pubs["path"].publish(msg)
        if "polygon" in doc:
            msg = PolygonStamped()
            msg.header.frame_id = doc["polygon"].get("frame", "base")
            msg.polygon.points = [Point32(x=float(x), y=float(y), z=float(z))
                                  for x, y, z in doc["polygon"]["points"]]
            pubs["polygon"].publish(msg)
        if "point" in doc:
            msg = PointStamped()
            msg.header.frame_id = doc["point"].get("frame", "base")
            msg.point.x, msg.point.y, msg.point.z = (float(v) for v in doc["point"]["point"])
            pubs["point"].publish(msg)
        state["seq"] = doc["seq"]
        state["moving"] = doc.get("moving", state["moving"])
        print(f"APPLIED {doc['seq']}", flush=True)

    def tick() -> None:
        tf_pub.publish(TFMessage(transforms=[transform(node, "world", "moving",
                                                       state["moving"])]))
        try:
            mtime = os.stat(control).st_mtime_ns
        except OSError:
            return
        with open(control) as f:
            doc = json.load(f)
        if doc.get("seq") != state["seq"]:
            publish(doc)
        state["mtime"] = mtime

    node.create_timer(0.05, tick)
    print("READY", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass


if __name__ == "__main__":
    main()
