"""Generate the demo robot's mesh files (deterministic bytes; nothing downloaded).

- ``shoulder.stl``: a turret revolved from a profile (binary STL);
- ``upper_arm.obj``: a capsule written in MILLIMETRES (the URDF scales it by 0.001);
- ``forearm.dae``: a hexagonal prism in CENTIMETRES (``<unit meter="0.01">``) whose
  COLLADA material gives the colour; written by hand so no time stamp ends in the file;
- ``wrist_2.stl``: an extruded rounded-rectangle profile.

Every mesh is made with trimesh.creation or plain numpy from fixed numbers, so two runs
give identical bytes (a test checks it).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np
import numpy.typing as npt
import trimesh

__all__ = ["MESH_FILES", "FOREARM_RGBA", "write_meshes", "extrude_convex", "collada_text"]

F64 = npt.NDArray[np.float64]

# The forearm's colour comes from its DAE material only (the URDF gives none).
FOREARM_RGBA = (0.80, 0.15, 0.15, 1.0)


def extrude_convex(profile: npt.ArrayLike, height: float) -> trimesh.Trimesh:
    """A prism from a CONVEX counter-clockwise 2-D profile, from z = 0 to z = height.

    Caps are fans around the centroid; sides are quads split in two. (trimesh's own
    extrusion triangulates with optional packages; a convex profile needs none.)
    """
    p = np.asarray(profile, dtype=np.float64)
    k = len(p)
    centre = p.mean(axis=0)
    bottom = np.column_stack([p, np.zeros(k)])
    top = np.column_stack([p, np.full(k, height)])
    vertices = np.vstack([bottom, top, [[*centre, 0.0], [*centre, height]]])
    i = np.arange(k)
    j = (i + 1) % k
    cb, ct = 2 * k, 2 * k + 1
    faces = np.vstack([
        np.column_stack([np.full(k, cb), j, i]),  # bottom, facing -z
        np.column_stack([np.full(k, ct), k + i, k + j]),  # top, facing +z
        np.column_stack([i, j, k + j]),  # sides, facing outwards
        np.column_stack([i, k + j, k + i]),
    ])
    return trimesh.Trimesh(vertices, faces, process=False)


def _rounded_rectangle(width: float, depth: float, radius: float, per_corner: int = 8) -> F64:
    corners = [(width / 2 - radius, depth / 2 - radius, 0.0),
               (-width / 2 + radius, depth / 2 - radius, np.pi / 2),
               (-width / 2 + radius, -depth / 2 + radius, np.pi),
               (width / 2 - radius, -depth / 2 + radius, 1.5 * np.pi)]
    points = []
    for cx, cy, start in corners:
        for a in np.linspace(start, start + np.pi / 2, per_corner):
            points.append((cx + radius * np.cos(a), cy + radius * np.sin(a)))
    return np.asarray(points)


def _fmt(values: npt.ArrayLike, spec: str) -> str:
    return " ".join(format(float(v), spec) for v in np.asarray(values).ravel())


def collada_text(name: str, vertices: npt.ArrayLike, triangles: npt.ArrayLike,
                 rgba: tuple[float, float, float, float], unit_meter: float) -> str:
    """A minimal COLLADA 1.4.1 document: one geometry, one phong material, one node."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    points = _fmt(v, ".6f")
    indices = " ".join(str(int(x)) for x in t.ravel())
    return f"""<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset>
    <contributor><authoring_tool>slicer-ros2-bridge demo generator</authoring_tool></contributor>
    <unit name="unit" meter="{unit_meter:g}"/>
    <up_axis>Z_UP</up_axis>
  </asset>
  <library_effects>
    <effect id="{name}_effect">
      <profile_COMMON>
        <technique sid="common">
          <phong>
            <diffuse><color sid="diffuse">{_fmt(rgba, '.4f')}</color></diffuse>
          </phong>
        </technique>
      </profile_COMMON>
    </effect>
  </library_effects>
  <library_materials>
    <material id="{name}_material" name="{name}_material">
      <instance_effect url="#{name}_effect"/>
    </material>
  </library_materials>
  <library_geometries>
    <geometry id="{name}_mesh" name="{name}">
      <mesh>
        <source id="{name}_positions">
          <float_array id="{name}_positions_array" count="{v.size}">{points}</float_array>
          <technique_common>
            <accessor source="#{name}_positions_array" count="{len(v)}" stride="3">
              <param name="X" type="float"/>
              <param name="Y" type="float"/>
              <param name="Z" type="float"/>
            </accessor>
          </technique_common>
        </source>
        <vertices id="{name}_vertices">
          <input semantic="POSITION" source="#{name}_positions"/>
        </vertices>
        <triangles material="{name}_symbol" count="{len(t)}">
          <input semantic="VERTEX" source="#{name}_vertices" offset="0"/>
          <p>{indices}</p>
        </triangles>
      </mesh>
    </geometry>
  </library_geometries>
  <library_visual_scenes>
    <visual_scene id="{name}_scene">
      <node id="{name}_node" name="{name}">
        <instance_geometry url="#{name}_mesh">
          <bind_material>
            <technique_common>
              <instance_material symbol="{name}_symbol" target="#{name}_material"/>
            </technique_common>
          </bind_material>
        </instance_geometry>
      </node>
    </visual_scene>
  </library_visual_scenes>
  <scene><instance_visual_scene url="#{name}_scene"/></scene>
</COLLADA>
"""


def _shoulder() -> bytes:
    profile = [[0.0, 0.0], [0.060, 0.0], [0.065, 0.010], [0.065, 0.085], [0.058, 0.100],
               [0.045, 0.125], [0.0, 0.125]]
    mesh = trimesh.creation.revolve(profile, sections=64)
    return bytes(trimesh.exchange.stl.export_stl(mesh))


def _upper_arm() -> bytes:
    # Millimetres on purpose: many CAD exports are, and the URDF's scale fixes it.
    mesh = trimesh.creation.capsule(height=300.0, radius=45.0, count=[24, 24])
    text = trimesh.exchange.obj.export_obj(  # type: ignore[no-untyped-call]  # trimesh: unannotated
        mesh, include_normals=False, include_color=False, include_texture=False, header=None)
    return str(text).encode("utf-8")


def _forearm() -> bytes:
    # A hexagonal prism 30 cm long, radius 4 cm, centred, in centimetres.
    mesh = trimesh.creation.cylinder(radius=4.0, height=30.0, sections=6)
    return collada_text("forearm", mesh.vertices, mesh.faces, FOREARM_RGBA, 0.01).encode()


def _wrist_2() -> bytes:
    profile = _rounded_rectangle(0.07, 0.06, 0.012)
    mesh = extrude_convex(profile, 0.06)
    return bytes(trimesh.exchange.stl.export_stl(mesh))


MESH_FILES: dict[str, Callable[[], bytes]] = {
    "shoulder.stl": _shoulder,
    "upper_arm.obj": _upper_arm,
    "forearm.dae": _forearm,
    "wrist_2.stl": _wrist_2,
}


def write_meshes(folder: Path) -> list[Path]:
    """Write every demo mesh into ``folder`` (created); return the paths."""
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, make in MESH_FILES.items():
        path = folder / name
        path.write_bytes(make())
        written.append(path)
    return written
