"""Render the demo robot as a client receives it over OpenIGTLink -> docs/demo-robot.png.

    .venv/bin/pip install vtk          # for this script only; not a project dependency
    .venv/bin/python tools/render_demo_picture.py [--out docs/demo-robot.png]

What it does, end to end through the real path (nothing is read from the URDF here):
starts `slicer-ros2-bridge demo` (daemon + state publisher + joint motion) on a free port
in a ROS domain of its own, connects a client, receives every link POLYDATA (mm, link
frame, colour in ``ros2.color``) and every link TRANSFORM (mm, in the fixed frame), places
each mesh under its link's transform (``ros2.parent_device``) as 3D Slicer's ROS2Bridge
module does, and renders offscreen with VTK (EGL or OSMesa, no display needed).
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from protocol.messages import Message, PolyData, Transform  # noqa: E402
from slicer_client.connection import Connection  # noqa: E402
from tools.offscreen_png import write_png  # noqa: E402


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _start_demo(port: int, log: Path) -> subprocess.Popen[bytes]:
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(1, 100)),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="render-roslog-"))
    with log.open("wb") as out:
        demo = subprocess.Popen([sys.executable, "-u", "-m", "bridge.cli", "demo", "--port",
                                 str(port)], stdout=out, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, cwd=str(REPO), env=env,
                                start_new_session=True)
    deadline = time.monotonic() + 90
    while "Stop with Ctrl-C" not in log.read_text(errors="replace"):
        if demo.poll() is not None or time.monotonic() > deadline:
            raise SystemExit(f"the demo did not start:\n{log.read_text()[-3000:]}")
        time.sleep(0.1)
    return demo


def receive_robot(port: int, settle_s: float) -> tuple[list[Message], dict[str, np.ndarray]]:
    """Every visual's POLYDATA message and every link device's matrix (mm)."""
    with Connection("127.0.0.1", port) as client:
        robot = client.command("create_robot", {"name": "demo"}, timeout=60)  # existed
        visuals = [v["device"] for v in robot["visuals"]]
        links = [item["device"] for item in robot["links"]]
        meshes = [client.wait_for(d, lambda m: isinstance(m.body, PolyData), timeout=30)
                  for d in visuals]
        for device in links:
            client.wait_for(device, lambda m: isinstance(m.body, Transform), timeout=30)
        # Watch the arm swing for `settle_s`; keep the pose reaching furthest out while
        # every link stays above the floor (a picture that shows the arm's joints).
        flange = next(item["device"] for item in robot["links"]
                      if item["link"] == "tool_flange")
        best: dict[str, np.ndarray] = {}
        best_z = -np.inf
        deadline = time.monotonic() + settle_s
        while time.monotonic() < deadline:
            snapshot = {}
            for device in links:
                message = client.latest(device)
                assert message is not None and isinstance(message.body, Transform)
                snapshot[device] = np.asarray(message.body.matrix, dtype=np.float64)
            lowest = min(m[2, 3] for m in snapshot.values())
            reach = float(np.hypot(*snapshot[flange][:2, 3])) if lowest > 60.0 else -1.0
            if reach > best_z:
                best, best_z = snapshot, reach
            time.sleep(0.05)  # sampling the pose, not synchronising
    return meshes, best


def render(meshes: list[Message], matrices: dict[str, np.ndarray], out: Path,
           size: tuple[int, int]) -> None:
    try:
        import vtk
        from vtk.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    except ImportError:
        raise SystemExit("VTK is needed: .venv/bin/pip install vtk (not a project "
                         "dependency)") from None
    renderer = vtk.vtkRenderer()
    renderer.GradientBackgroundOn()
    renderer.SetBackground(0.93, 0.94, 0.96)
    renderer.SetBackground2(0.62, 0.68, 0.78)
    for message in meshes:
        body = message.body
        assert isinstance(body, PolyData)
        points = vtk.vtkPoints()
        points.SetData(numpy_to_vtk(np.ascontiguousarray(body.points, dtype=np.float32),
                                    deep=True))
        cells = vtk.vtkCellArray()
        triangles = np.asarray(body.polygons, dtype=np.int64).reshape(-1, 4)[:, 1:]
        offsets = np.arange(0, 3 * len(triangles) + 1, 3, dtype=np.int64)
        cells.SetData(numpy_to_vtkIdTypeArray(offsets, deep=True),
                      numpy_to_vtkIdTypeArray(triangles.ravel().copy(), deep=True))
        poly = vtk.vtkPolyData()
        poly.SetPoints(points)
        poly.SetPolys(cells)
        normals = vtk.vtkPolyDataNormals()  # smooth shading on curved parts, sharp on CAD
        normals.SetInputData(poly)
        normals.SetFeatureAngle(40)
        mapper = vtk.vtkPolyDataMapper()
        mapper.SetInputConnection(normals.GetOutputPort())
        actor = vtk.vtkActor()
        actor.SetMapper(mapper)
        rgba = [float(v) for v in message.metadata.get("ros2.color", "0.7 0.7 0.7 1").split()]
        prop = actor.GetProperty()
        prop.SetColor(*rgba[:3])
        prop.SetOpacity(rgba[3] if len(rgba) > 3 else 1.0)
        prop.SetSpecular(0.3)
        prop.SetSpecularPower(30)
        # The mesh is in its link's frame: put it under the link's TRANSFORM (mm).
        matrix = matrices[message.metadata["ros2.parent_device"]]
        vtk_matrix = vtk.vtkMatrix4x4()
        for i in range(4):
            for j in range(4):
                vtk_matrix.SetElement(i, j, float(matrix[i, j]))
        actor.SetUserMatrix(vtk_matrix)
        renderer.AddActor(actor)
    # A floor grid (100 mm squares) under the base, for scale.
    floor = vtk.vtkPlaneSource()
    floor.SetOrigin(-400, -400, -0.5)
    floor.SetPoint1(400, -400, -0.5)
    floor.SetPoint2(-400, 400, -0.5)
    floor.SetResolution(8, 8)
    floor_mapper = vtk.vtkPolyDataMapper()
    floor_mapper.SetInputConnection(floor.GetOutputPort())
    floor_actor = vtk.vtkActor()
    floor_actor.SetMapper(floor_mapper)
    floor_actor.GetProperty().SetRepresentationToWireframe()
    floor_actor.GetProperty().SetColor(0.45, 0.48, 0.55)
    renderer.AddActor(floor_actor)
    camera = renderer.GetActiveCamera()
    camera.SetViewUp(0, 0, 1)
    camera.SetPosition(1400, -1100, 800)
    camera.SetFocalPoint(0, 0, 300)
    renderer.ResetCamera()
    camera.Zoom(1.15)
    caption = vtk.vtkTextActor()
    caption.SetInput(f"slicer-ros2-bridge demo: {len(meshes)} link meshes + "
                     f"{len(matrices)} link transforms received over OpenIGTLink")
    caption.GetTextProperty().SetFontSize(20)
    caption.GetTextProperty().SetColor(0.15, 0.17, 0.2)
    caption.SetPosition(16, size[1] - 40)
    renderer.AddViewProp(caption)
    write_png([renderer], size, out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "demo-robot.png")
    parser.add_argument("--settle", type=float, default=9.0,
                        help="seconds of motion watched for the pose with the tool highest "
                             "(default 9: a full swing)")
    parser.add_argument("--size", type=int, nargs=2, default=(1200, 900))
    args = parser.parse_args(argv)
    port = _free_port()
    log = Path(tempfile.mkdtemp(prefix="render-demo-")) / "demo.log"
    demo = _start_demo(port, log)
    try:
        meshes, matrices = receive_robot(port, args.settle)
    finally:
        os.killpg(demo.pid, signal.SIGINT)
        code = demo.wait(30)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    render(meshes, matrices, args.out, tuple(args.size))  # type: ignore[arg-type]
    print(f"wrote {args.out} ({len(meshes)} meshes, {len(matrices)} links); demo exit {code}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
