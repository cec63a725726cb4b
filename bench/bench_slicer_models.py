"""Time to turn Slicer models and markups into ROS messages (Slicer -> ROS), in process.

Rows per model (an icosphere, as a segmented organ's surface; median of --repeat runs, ms):
- decode: the POLYDATA body's bytes -> `PolyData` (what the daemon's reader does first);
- Mesh raw / Marker raw: `PolyData` -> the serialized shape_msgs/Mesh, visualization_msgs/
  Marker TRIANGLE_LIST (mm -> m, fan triangulation, CDR built with numpy): what the daemon
  does, in a worker thread, before `publish(bytes)`;
- Mesh obj / Marker obj: the same as rclpy message objects (`from_igtl`), the way a plain
  rclpy node would build them;
- baseline, serialize: rclpy's `serialize_message` of that Mesh / Marker object, the cost
  any rclpy publisher of the object pays in `publish()` on top of building it.
Then markups: POINT -> PoseArray for 10 and 10,000 points, beside serializing the result.

usage: python bench/bench_slicer_models.py [--repeat N]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

import numpy as np  # noqa: E402
import trimesh  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402

from bench_robot_load import median_ms  # noqa: E402
from bridge.codecs import codec_for  # noqa: E402
from protocol.messages import Point, PointElement, PolyData, cells_from_array  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    mesh_codec = codec_for("shape_msgs/msg/Mesh")
    marker_codec = codec_for("visualization_msgs/msg/Marker")
    print(f"{'model':<14} {'triangles':>9} {'bytes':>9} {'decode':>7} {'Mesh raw':>8} "
          f"{'Mesh obj':>8} {'serialize':>9} {'Marker raw':>10} {'Marker obj':>10} "
          f"{'serialize':>9}")
    for level in (4, 5, 6, 7):
        sphere = trimesh.creation.icosphere(level, radius=80.0)  # mm, an organ's size
        body = PolyData(points=np.asarray(sphere.vertices, dtype=np.float32),
                        polygons=cells_from_array(np.asarray(sphere.faces)))
        wire = body.pack()
        decode = median_ms(lambda wire=wire: PolyData.unpack(wire), args.repeat)
        mesh = mesh_codec.from_igtl(body)
        to_mesh = median_ms(lambda body=body: mesh_codec.from_igtl(body), args.repeat)
        mesh_raw = median_ms(lambda body=body: mesh_codec.from_igtl_raw(body), args.repeat)
        mesh_floor = median_ms(lambda mesh=mesh: serialize_message(mesh), args.repeat)
        triangles = len(sphere.faces)
        raw_ms = median_ms(lambda body=body: marker_codec.from_igtl_raw(body), args.repeat)
        if triangles <= 100_000:  # the object path takes seconds beyond
            marker = marker_codec.from_igtl(body)
            marker_ms = median_ms(lambda body=body: marker_codec.from_igtl(body), args.repeat)
            floor_ms = median_ms(lambda m=marker: serialize_message(m), args.repeat)
            to_marker = f"{raw_ms:10.1f} {marker_ms:10.1f} {floor_ms:9.1f}"
        else:
            to_marker = f"{raw_ms:10.1f} {'-':>10} {'-':>9}"
        print(f"icosphere({level}) {triangles:>9} {len(wire):>9} {decode:>7.1f} "
              f"{mesh_raw:>8.1f} {to_mesh:>8.1f} {mesh_floor:>9.1f} {to_marker}")

    poses = codec_for("geometry_msgs/msg/PoseArray")
    for n in (10, 10_000):
        rng = np.random.default_rng(0)
        markups = Point([PointElement(name=f"F-{i}", position=p)
                         for i, p in enumerate(rng.uniform(-100, 100, (n, 3)))])
        markups = Point.unpack(markups.pack())
        msg = poses.from_igtl(markups)
        ours = median_ms(lambda m=markups: poses.from_igtl(m), args.repeat)
        floor = median_ms(lambda msg=msg: serialize_message(msg), args.repeat)
        print(f"POINT -> PoseArray, {n:>6} points: {ours:.2f} ms (serialize {floor:.2f} ms)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
