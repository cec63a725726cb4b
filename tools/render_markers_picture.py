"""Render both directions of issue 15 into one picture -> docs/markers-and-models.png.

    .venv/bin/pip install vtk          # for this script only; not a project dependency
    .venv/bin/python tools/render_markers_picture.py [--out docs/markers-and-models.png]

Everything goes through the real path, in separate processes, in a ROS domain of its own:

* left, ROS -> Slicer: an rclpy node (this file, ``--marker-publisher``) publishes a
  ``visualization_msgs/MarkerArray`` in frame ``tool`` (cube, sphere, cylinder, arrow, line
  strip, points with per-point colours, a text) and ``world -> tool`` on /tf_static. A
  client subscribes with ``create_marker_subscriber`` (fixed frame ``world``); the panel
  shows the models as the client received them (POLYDATA in mm, each placed by the
  TRANSFORM of its frame), as the ROS2Bridge module places them in Slicer;
* right, Slicer -> ROS: the client sends a model made in Slicer (an ellipsoid "organ" and
  a needle path, POLYDATA in mm) with ``publish_model`` as ``visualization_msgs/Marker``
  TRIANGLE_LIST in frame ``world``; an rclpy subscriber in another process (this file,
  ``--marker-listener``) receives it, and the panel shows the triangles it got, in metres,
  as RViz draws them.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import select
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tools.offscreen_png import write_png  # noqa: E402

MARKER_TOPIC = "/picture/markers"
MODEL_TOPIC = "/picture/slicer_model"


# ------------------------------------------------------------------ ROS peers (children)


def marker_publisher() -> int:
    import rclpy
    from geometry_msgs.msg import Point, TransformStamped
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import ColorRGBA
    from tf2_msgs.msg import TFMessage
    from visualization_msgs.msg import Marker, MarkerArray

    rclpy.init()
    node = rclpy.create_node("picture_marker_publisher")
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    tf_static = node.create_publisher(TFMessage, "/tf_static", latched)
    world_tool = TransformStamped()
    world_tool.header.frame_id, world_tool.child_frame_id = "world", "tool"
    world_tool.transform.translation.z = 0.05
    world_tool.transform.rotation.z = math.sin(math.radians(20) / 2)
    world_tool.transform.rotation.w = math.cos(math.radians(20) / 2)
    tf_static.publish(TFMessage(transforms=[world_tool]))
    publisher = node.create_publisher(MarkerArray, MARKER_TOPIC, 10)

    def marker(kind: int, mid: int, xyz: tuple[float, float, float],
               scale: tuple[float, float, float], rgba: tuple[float, float, float, float],
               ) -> Marker:
        m = Marker()
        m.header.frame_id = "tool"
        m.ns, m.id, m.type, m.action = "picture", mid, kind, Marker.ADD
        m.pose.position.x, m.pose.position.y, m.pose.position.z = xyz
        m.pose.orientation.w = 1.0
        m.scale.x, m.scale.y, m.scale.z = scale
        # floats: rclpy serializes an int given to a float32 field as 0.0
        m.color = ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]),
                            a=float(rgba[3]))
        return m

    markers = [
        marker(Marker.CUBE, 1, (0.0, 0.0, 0.03), (0.06, 0.06, 0.06), (0.85, 0.33, 0.2, 1)),
        marker(Marker.SPHERE, 2, (0.12, 0.0, 0.04), (0.08, 0.08, 0.08), (0.2, 0.55, 0.85, 1)),
        marker(Marker.CYLINDER, 3, (-0.12, 0.0, 0.05), (0.05, 0.05, 0.1), (0.3, 0.7, 0.35, 1)),
    ]
    arrow = marker(Marker.ARROW, 4, (0.0, 0.0, 0.0), (0.008, 0.016, 0.02), (0.95, 0.8, 0.2, 1))
    arrow.points = [Point(x=-0.1, y=-0.12, z=0.0), Point(x=0.05, y=-0.12, z=0.1)]
    strip = marker(Marker.LINE_STRIP, 5, (0.0, 0.1, 0.0), (0.004, 0.0, 0.0),
                   (0.55, 0.3, 0.75, 1))
    strip.points = [Point(x=0.1 * math.cos(a), y=0.04 * math.sin(a), z=0.02 + 0.03 * a / 6)
                    for a in np.linspace(0.0, 4 * math.pi, 120)]
    ring = marker(Marker.POINTS, 6, (0.0, 0.0, 0.0), (0.008, 0.008, 0.0), (1, 1, 1, 1))
    for a in np.linspace(0.0, 2 * math.pi, 36, endpoint=False):
        ring.points.append(Point(x=0.2 * math.cos(a), y=0.2 * math.sin(a), z=0.0))
        ring.colors.append(ColorRGBA(r=0.5 + 0.5 * math.cos(a), g=0.5 + 0.5 * math.sin(a),
                                     b=0.6, a=1.0))
    text = marker(Marker.TEXT_VIEW_FACING, 7, (0.0, 0.0, 0.16), (0.0, 0.0, 0.025),
                  (0.1, 0.1, 0.1, 1))
    text.text = "MarkerArray from ROS"
    array = MarkerArray(markers=[*markers, arrow, strip, ring, text])
    print("READY", flush=True)
    try:
        while rclpy.ok():
            publisher.publish(array)
            rclpy.spin_once(node, timeout_sec=0.5)  # sleeps: one array every half second
    except KeyboardInterrupt:
        pass
    return 0


def marker_listener() -> int:
    import rclpy
    from visualization_msgs.msg import Marker

    rclpy.init()
    node = rclpy.create_node("picture_marker_listener")
    got: list[Any] = []
    node.create_subscription(Marker, MODEL_TOPIC, got.append, 10)
    print("READY", flush=True)
    deadline = time.monotonic() + 60
    while not got and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.2)
    if not got:
        return 1
    m = got[-1]
    print(json.dumps({"frame": m.header.frame_id, "type": int(m.type),
                      "points": [[p.x, p.y, p.z] for p in m.points],
                      "color": [m.color.r, m.color.g, m.color.b, m.color.a]}), flush=True)
    return 0


# ------------------------------------------------------------------ the client's side


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _child(args: list[str], env: dict[str, str], log: Path) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-u", *args], env=env, cwd=str(REPO),
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=log.open("w"), text=True, start_new_session=True)


def _ready(child: subprocess.Popen[str], what: str) -> None:
    assert child.stdout is not None
    line = child.stdout.readline()
    if "READY" not in line:
        raise SystemExit(f"{what} did not start: {line!r}")


def organ_model() -> tuple[np.ndarray, np.ndarray]:
    """An ellipsoid (mm) with a dent, as a segmentation would give: points, triangles."""
    rings, sectors = 24, 36
    points = []
    for i in range(rings + 1):
        theta = math.pi * i / rings
        for j in range(sectors):
            phi = 2 * math.pi * j / sectors
            dent = 1.0 - 0.18 * math.exp(-((phi - math.pi) ** 2) * 2)
            points.append((60 * dent * math.sin(theta) * math.cos(phi),
                           38 * dent * math.sin(theta) * math.sin(phi),
                           30 * math.cos(theta) + 80))
    triangles = []
    for i in range(rings):
        for j in range(sectors):
            a, b = i * sectors + j, i * sectors + (j + 1) % sectors
            c, d = a + sectors, b + sectors
            triangles += [(a, c, b), (b, c, d)]
    return np.array(points), np.array(triangles)


def collect(port: int, env: dict[str, str], logs: Path) -> tuple[Any, dict[str, Any], int]:
    from slicer_client import connect

    publisher = _child([__file__, "--marker-publisher"], env, logs / "publisher.log")
    listener = _child([__file__, "--marker-listener"], env, logs / "listener.log")
    try:
        _ready(publisher, "the marker publisher")
        _ready(listener, "the marker listener")
        with connect("127.0.0.1", port) as ros:
            markers = ros.markers(MARKER_TOPIC, "MarkerArray", "world")
            markers.wait_for_markers(lambda m: len(m) >= 7, timeout=60)
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline and any(
                    markers.points_in_fixed_frame(i) is None for i in markers.markers.values()):
                time.sleep(0.05)  # polling the client's state, not synchronising
            received = [(item, markers.points_in_fixed_frame(item))
                        for item in markers.markers.values()]
            points, triangles = organ_model()
            assert listener.stdout is not None
            # Volatile, as RViz's markers are: sent again until the listener has matched.
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                ros.publish_model(MODEL_TOPIC, (points, triangles), frame="world",
                                  type="visualization_msgs/msg/Marker", ns="slicer",
                                  color=(0.85, 0.45, 0.45, 1.0))
                if select.select([listener.stdout], [], [], 1.0)[0]:
                    break
            line = listener.stdout.readline()
            if not line:
                raise SystemExit("the listener got no Marker")
            seen = json.loads(line)
        return received, seen, len(triangles)
    finally:
        for child in (publisher, listener):
            if child.poll() is None:
                os.killpg(child.pid, signal.SIGINT)
            child.wait(30)


# ------------------------------------------------------------------ rendering


def render(received: list[Any], seen: dict[str, Any], out: Path,
           size: tuple[int, int]) -> None:
    try:
        import vtk
        from vtk.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    except ImportError:
        raise SystemExit("VTK is needed: .venv/bin/pip install vtk (not a project "
                         "dependency)") from None
    from protocol.messages import PolyData

    def cells(flat: Any) -> Any:
        array = vtk.vtkCellArray()
        flat = np.asarray(flat, dtype=np.int64)
        if len(flat):
            array.ImportLegacyFormat(numpy_to_vtkIdTypeArray(flat.copy(), deep=True))
        return array

    def panel(viewport: tuple[float, float, float, float], title: str) -> Any:
        renderer = vtk.vtkRenderer()
        renderer.SetViewport(*viewport)
        renderer.GradientBackgroundOn()
        renderer.SetBackground(0.93, 0.94, 0.96)
        renderer.SetBackground2(0.62, 0.68, 0.78)
        caption = vtk.vtkTextActor()
        caption.SetInput(title)
        caption.GetTextProperty().SetFontSize(18)
        caption.GetTextProperty().SetColor(0.15, 0.17, 0.2)
        caption.SetPosition(14, size[1] - 36)
        renderer.AddViewProp(caption)
        return renderer

    left = panel((0.0, 0.0, 0.5, 1.0), "ROS -> Slicer: a MarkerArray as the client's models")
    for item, world_mm in received:
        if world_mm is None:
            continue
        if not isinstance(item.body, PolyData):  # a text marker: a label at its position
            label = vtk.vtkBillboardTextActor3D()
            label.SetInput(str(getattr(item.body, "text", "")))
            label.SetPosition(*world_mm[0])
            label.GetTextProperty().SetFontSize(18)
            label.GetTextProperty().SetColor(0.1, 0.1, 0.1)
            left.AddActor(label)
            continue
        poly = vtk.vtkPolyData()
        points = vtk.vtkPoints()
        points.SetData(numpy_to_vtk(np.ascontiguousarray(world_mm, dtype=np.float32),
                                    deep=True))
        poly.SetPoints(points)
        poly.SetVerts(cells(item.body.vertices))
        poly.SetLines(cells(item.body.lines))
        poly.SetPolys(cells(item.body.polygons))
        rgba = next((a.data for a in item.body.attributes if a.name == "RGBA"), None)
        if rgba is not None:
            colours = numpy_to_vtk((np.asarray(rgba) * 255).astype(np.uint8), deep=True)
            colours.SetName("RGBA")
            poly.GetPointData().SetScalars(colours)
        mapper = vtk.vtkPolyDataMapper()
        mapper.SetInputData(poly)
        mapper.SetColorModeToDirectScalars()
        actor = vtk.vtkActor()
        actor.SetMapper(mapper)
        actor.GetProperty().SetPointSize(7)
        actor.GetProperty().SetLineWidth(3)
        actor.GetProperty().SetRenderPointsAsSpheres(True)
        left.AddActor(actor)

    right = panel((0.5, 0.0, 1.0, 1.0), "Slicer -> ROS: a Slicer model as a ROS node "
                                        "receives it (Marker, m)")
    tri = np.asarray(seen["points"], dtype=np.float64)
    poly = vtk.vtkPolyData()
    points = vtk.vtkPoints()
    points.SetData(numpy_to_vtk(np.ascontiguousarray(tri, dtype=np.float32), deep=True))
    poly.SetPoints(points)
    n = len(tri) // 3
    flat = np.column_stack([np.full(n, 3), np.arange(3 * n).reshape(n, 3)]).ravel()
    poly.SetPolys(cells(flat))
    normals = vtk.vtkPolyDataNormals()
    normals.SetInputData(poly)
    mapper = vtk.vtkPolyDataMapper()
    mapper.SetInputConnection(normals.GetOutputPort())
    actor = vtk.vtkActor()
    actor.SetMapper(mapper)
    actor.GetProperty().SetColor(*seen["color"][:3])
    actor.GetProperty().SetSpecular(0.3)
    right.AddActor(actor)
    axes = vtk.vtkAxesActor()  # the ROS side's world frame, 2 cm axes
    axes.SetTotalLength(0.02, 0.02, 0.02)
    axes.AxisLabelsOff()
    right.AddActor(axes)

    for renderer, distance in ((left, 600.0), (right, 0.3)):
        camera = renderer.GetActiveCamera()
        camera.SetViewUp(0, 0, 1)
        camera.SetPosition(distance, -1.3 * distance, 0.9 * distance)
        camera.SetFocalPoint(0, 0, 0)
        renderer.ResetCamera()
        camera.Zoom(1.2)
    write_png([left, right], size, out)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--marker-publisher"]:
        return marker_publisher()
    if argv[:1] == ["--marker-listener"]:
        return marker_listener()
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "markers-and-models.png")
    parser.add_argument("--size", type=int, nargs=2, default=(1400, 640))
    args = parser.parse_args(argv)
    logs = Path(tempfile.mkdtemp(prefix="render-markers-"))
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(1, 100)),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_LOG_DIR=str(logs / "roslog"))
    port = _free_port()
    daemon = subprocess.Popen([sys.executable, "-u", "-m", "bridge.cli", "run", "--port",
                               str(port)], env=env, cwd=str(REPO), stdin=subprocess.DEVNULL,
                              stdout=(logs / "daemon.log").open("wb"),
                              stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while "listening on" not in (logs / "daemon.log").read_text(errors="replace"):
            if daemon.poll() is not None or time.monotonic() > deadline:
                raise SystemExit(f"the daemon did not start; see {logs / 'daemon.log'}")
            time.sleep(0.1)
        received, seen, triangles = collect(port, env, logs)
    finally:
        os.killpg(daemon.pid, signal.SIGINT)
        daemon.wait(30)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    render(received, seen, args.out, tuple(args.size))  # type: ignore[arg-type]
    print(f"wrote {args.out}: {len(received)} markers received by the client; a {triangles}-"
          f"triangle Slicer model received by ROS as {len(seen['points']) // 3} triangles in "
          f"frame {seen['frame']!r}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
