"""trimesh in the daemon without the optional packages the daemon never uses.

trimesh imports, as it starts, every optional package of its ``easy`` extra it finds
installed, and yourdfpy asks for ``trimesh[easy]``, so all are: scipy (spatial, optimize,
sparse, ndimage), networkx, shapely, rtree, embreex, manifold3d and svg.path. Importing
them was 0.36 s of trimesh's 0.45 s on a quiet machine (``python -X importtime -c "import
trimesh"``; most of a second under load), paid before a daemon's first robot mesh could be
read (issue 44). Reading the mesh formats of `bridge.robots.meshes.MESH_SUFFIXES` and making
the URDF primitives needs networkx only (3MF's build graph), which stays; of the others
trimesh's readers used only scipy.sparse, to average face colours per vertex, which
`bridge.robots.meshes` does with numpy. Left out, a package is absent to trimesh, which
binds an `ExceptionWrapper` in its place: only its functions that need one (convex hulls,
boolean operations, 2D paths, ray tests, proximity...) raise, when called.
"""

from __future__ import annotations

import sys

__all__ = ["MESH_EXTRAS_LEFT_OUT", "leave_out_mesh_extras"]

# Top-level names of trimesh's optional imports the daemon leaves out ("svg": svg.path).
MESH_EXTRAS_LEFT_OUT = ("scipy", "shapely", "rtree", "embreex", "manifold3d", "svg")


def leave_out_mesh_extras() -> None:
    """For a daemon process, before anything imports trimesh: each package left out
    imports as missing (None in `sys.modules`: `import` raises ModuleNotFoundError). One
    already imported stays."""
    for name in MESH_EXTRAS_LEFT_OUT:
        sys.modules.setdefault(name, None)  # type: ignore[arg-type]
