"""trimesh in the daemon without the optional packages the daemon never uses.

trimesh imports, as it starts, every optional package of its ``easy`` extra it finds
installed, and yourdfpy asks for ``trimesh[easy]``, so all are: scipy (spatial, optimize,
sparse, ndimage), networkx, shapely, rtree, embreex, manifold3d and svg.path. Importing
them was 0.45 s of trimesh's 0.55 s in a daemon on a quiet machine (``python -X importtime
-c "import trimesh"``; most of a second under load), paid before a daemon's first robot
mesh could be read (issue 44). Reading the formats of `bridge.robots.meshes.MESH_SUFFIXES`
and making the URDF primitives needs none of them but networkx for 3MF (its build graph),
which `bridge.robots.meshes` takes back for the first 3MF file (`take_back`); trimesh's
readers used scipy.sparse only to average face colours per vertex, which
`bridge.robots.meshes` does with numpy. Left out, a package is absent to trimesh, which
binds an `ExceptionWrapper` in its place: only its functions that need one (convex hulls,
graphs, boolean operations, 2D paths, ray tests, proximity...) raise, when called.
"""

from __future__ import annotations

import sys

__all__ = ["MESH_EXTRAS_LEFT_OUT", "leave_out_mesh_extras", "take_back"]

# Top-level names of trimesh's optional imports the daemon leaves out ("svg": svg.path).
MESH_EXTRAS_LEFT_OUT = ("scipy", "networkx", "shapely", "rtree", "embreex", "manifold3d",
                        "svg")


def leave_out_mesh_extras() -> None:
    """For a daemon process, before anything imports trimesh: each package left out
    imports as missing (None in `sys.modules`: `import` raises ModuleNotFoundError). One
    already imported stays."""
    for name in MESH_EXTRAS_LEFT_OUT:
        sys.modules.setdefault(name, None)  # type: ignore[arg-type]


def take_back(name: str) -> None:
    """A package left out may be imported again (its None entry goes), for the one reader
    that needs it; nothing changes for one never left out."""
    if name in sys.modules and sys.modules[name] is None:
        del sys.modules[name]
