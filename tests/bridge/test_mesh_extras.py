"""The daemon reads meshes with trimesh's optional packages left out (issue 44: importing
them was most of a daemon's first robot): a process that leaves them out imports none of
them but networkx, for a 3MF file, and reads every mesh format and primitive of a robot
into the very arrays and colours a process with them reads."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from bridge.robots import MeshCache, load_robot_file
from bridge.robots.demo import demo_urdf_path
from bridge.robots.mesh_extras import MESH_EXTRAS_LEFT_OUT

REPO = Path(__file__).resolve().parents[2]

PRIMITIVES = ('<link name="box"><visual><geometry><box size="0.1 0.2 0.3"/></geometry>'
              '</visual></link><link name="tube"><visual><geometry><cylinder radius="0.01" '
              'length="0.3"/></geometry></visual></link><link name="ball"><visual><geometry>'
              '<sphere radius="0.025"/></geometry></visual></link>')
# Two faces of their own colours sharing an edge: trimesh averages them on the shared
# vertices (with scipy.sparse, which the daemon leaves out).
FACE_COLOURED_PLY = """ply
format ascii 1.0
element vertex 4
property float x
property float y
property float z
element face 2
property list uchar int vertex_indices
property uchar red
property uchar green
property uchar blue
property uchar alpha
end_header
0 0 0
1 0 0
0 1 0
0 0 1
3 0 1 2 255 0 0 255
3 0 1 3 0 10 255 255
"""

# Each visual of a robot, as bytes digests of what the loader made (mm, link frame).
READ = """
import hashlib, json, sys
from pathlib import Path
if sys.argv[1] == "lean":
    from bridge.robots.mesh_extras import leave_out_mesh_extras
    leave_out_mesh_extras()
from bridge.robots import MeshCache, load_robot_file
model = load_robot_file(Path(sys.argv[2]), package_paths=json.loads(sys.argv[3]),
                        cache=MeshCache())
print(json.dumps({"visuals": {f"{v.link}/{v.index}": [
    hashlib.sha256(v.vertices.tobytes() + v.triangles.tobytes()).hexdigest(), list(v.rgba),
    None if v.vertex_rgba is None else hashlib.sha256(v.vertex_rgba.tobytes()).hexdigest(),
    v.colour_source] for v in model.visuals}, "warnings": list(model.warnings),
    "extras": sorted({m.split(".")[0] for m in sys.modules if m.split(".")[0] in sys.argv[4:]
                      and sys.modules[m] is not None})}))
"""


def _robot_of_every_kind(tmp_path: Path) -> tuple[Path, dict[str, Path]]:
    """The demo arm (STL, OBJ and DAE meshes, colours from the URDF and from a DAE) with a
    box, a cylinder and a sphere, a PLY of two face colours, a 3MF and a GLB added."""
    import trimesh

    urdf, packages = demo_urdf_path(tmp_path / "demo")
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    (meshes / "faces.ply").write_text(FACE_COLOURED_PLY)
    box = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
    (meshes / "box.3mf").write_bytes(trimesh.exchange.threemf.export_3MF(box))
    ball = trimesh.creation.icosphere(subdivisions=1, radius=0.02)
    ball.visual.vertex_colors = np.linspace(0, 255, len(ball.vertices) * 4).astype(
        np.uint8).reshape(-1, 4)
    (meshes / "ball.glb").write_bytes(ball.export(file_type="glb"))
    files = "".join(f'<link name="{path.stem}_{path.suffix[1:]}"><visual><geometry><mesh '
                    f'filename="file://{path}"/></geometry></visual></link>'
                    for path in sorted(meshes.iterdir()))
    names = ["box", "tube", "ball"] + [f"{p.stem}_{p.suffix[1:]}" for p in meshes.iterdir()]
    text = urdf.read_text()
    root = text.index(">", text.index("<robot")) + 1
    joints = "".join(f'<joint name="to_{name}" type="fixed"><parent link="base_link"/>'
                     f'<child link="{name}"/></joint>' for name in names)
    mixed = urdf.with_name("mixed.urdf")
    mixed.write_text(text[:root] + PRIMITIVES + files + joints + text[root:])
    return mixed, packages


def _read(mode: str, urdf: Path, packages: dict[str, Path]) -> dict[str, object]:
    done = subprocess.run(
        [sys.executable, "-c", READ, mode, str(urdf),
         json.dumps({name: str(path) for name, path in packages.items()}),
         *MESH_EXTRAS_LEFT_OUT], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    result: dict[str, object] = json.loads(done.stdout.splitlines()[-1])
    return result


def test_meshes_read_without_the_extras_are_those_read_with_them(tmp_path: Path) -> None:
    urdf, packages = _robot_of_every_kind(tmp_path)
    model = load_robot_file(urdf, package_paths=packages, cache=MeshCache())
    formats = {Path(v.source.split(" -> ")[0]).suffix for v in model.visuals}
    assert formats >= {".stl", ".obj", ".dae", ".ply", ".3mf", ".glb"}
    assert model.warnings == ()
    assert {v.link for v in model.visuals} >= {"box", "tube", "ball"}
    faces = next(v for v in model.visuals if v.link == "faces_ply")
    assert faces.vertex_rgba is not None  # per vertex: the shared edge's ends averaged
    lean = _read("lean", urdf, packages)
    full = _read("full", urdf, packages)
    # This machine has the extras (yourdfpy asks for trimesh[easy]): trimesh imports them.
    assert set(full["extras"]) >= {"scipy", "networkx", "shapely"}  # type: ignore[arg-type]
    # Left out, but networkx taken back for the 3MF file (its reader's build graph).
    assert lean["extras"] == ["networkx"] and lean["warnings"] == []
    assert lean["visuals"] == full["visuals"]
    # ... and both are what this process read.
    for v in model.visuals:
        digest, rgba, vertex_rgba, colour_source = lean["visuals"][f"{v.link}/{v.index}"]  # type: ignore[index]
        assert digest == hashlib.sha256(v.vertices.tobytes() + v.triangles.tobytes()).hexdigest()
        np.testing.assert_array_equal(rgba, v.rgba)
        assert (vertex_rgba is None) == (v.vertex_rgba is None)
        assert colour_source == v.colour_source
    assert {entry[3] for entry in lean["visuals"].values()} >= {"urdf", "mesh", "default"}  # type: ignore[union-attr]
