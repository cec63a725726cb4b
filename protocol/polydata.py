"""POLYDATA as every OpenIGTLink reader reads it: the one owner of how the daemon lays out
the colours, point-only geometry and attributes of the models it sends to clients, and of
reading colours back from any client.

polydata.md allows more than the readers 3D Slicer links read right:

- OpenIGTLink 3.1's C unpacker (``Source/igtlutil/igtl_polydata.c``,
  ``igtl_polydata_unpack``, its attribute-data loop) sizes a point SCALAR by NCOMPONENTS, a
  point NORMAL or VECTOR as 3 floats a row, and every other TYPE (RGBA, TCOORDS and every
  cell attribute, 0x1_) as TENSOR, 9 floats a row. An RGBA attribute of N rows is read as
  9N floats: each attribute after it comes from a wrong offset (a robot's "Normals" were
  garbage) and a last one runs 5N floats past the body.
- OpenIGTLinkIO's converter (``Converter/igtlioPolyDataConverter.cxx``,
  ``IGTLToVTKPolyData``, the vertices loop) makes one ``vtkVertex`` per VERTICES cell and
  sets id ``i`` of it, ``i`` being the cell's index: from the second cell on it writes past
  the one id a vtkVertex holds and Slicer dies (``munmap_chunk(): invalid pointer``). Of a
  cell of several ids it keeps the first.

So what the daemon sends is:

- colours: a point SCALAR named `RGBA_ATTRIBUTE` with 4 components, 0..1
  (`colour_attribute`): every reader sizes a SCALAR by its own NCOMPONENTS, and VTK shows
  a 4-component array as RGBA;
- point-only geometry (clouds, POINTS markers): ONE polyvertex cell ``[n, 0, ..., n-1]``
  (`vertex_cell`), which Slicer's converter reads without harm; it keeps the first point
  only, so the ROS2Bridge module gives such a model one vertex per point again
  (``slicer_client/scene_plan.py``, `is_point_like`);
- attributes on points only, of kinds SCALAR, VECTOR and NORMAL (`point_attribute`): the
  readers above mis-size all cell data, so the daemon makes none (nothing it converts
  has any: a ROS mesh, cloud or marker carries values per point).

Reading back, `point_colours` accepts both colour forms: TYPE RGBA (clients built before
this, and 3D Slicer itself, whose packer pads it to 9 components: ``protocol.messages``
keeps 4) and the SCALAR(4) "RGBA" above.
"""

from __future__ import annotations

from typing import Iterable, Optional

import numpy as np
import numpy.typing as npt

from protocol.errors import EncodeError
from protocol.messages import AttributeKind, PolyDataAttribute

__all__ = ["NORMALS_ATTRIBUTE", "POINT_KINDS", "RGBA_ATTRIBUTE", "colour_attribute",
           "point_attribute", "point_colours", "vertex_cell"]

RGBA_ATTRIBUTE = "RGBA"  # each point's colour, r g b a in 0..1
NORMALS_ATTRIBUTE = "Normals"  # each point's unit normal (smooth shading)
# The kinds OpenIGTLink 3.1's C unpacker sizes right (see the module doc).
POINT_KINDS = (AttributeKind.SCALAR, AttributeKind.VECTOR, AttributeKind.NORMAL)

U32Array = npt.NDArray[np.uint32]
F32Array = npt.NDArray[np.float32]


def point_attribute(name: str, kind: AttributeKind, data: npt.ArrayLike) -> PolyDataAttribute:
    """A point attribute for clients: SCALAR, VECTOR or NORMAL only (EncodeError
    otherwise); `PolyData.pack` checks the rows and components."""
    if kind not in POINT_KINDS:
        raise EncodeError(f"POLYDATA attribute {name!r}",
                          "a point SCALAR, VECTOR or NORMAL (what every reader sizes right)",
                          AttributeKind(kind).name)
    return PolyDataAttribute(name, kind, np.asarray(data), on_cells=False)


def colour_attribute(rgba: npt.ArrayLike) -> PolyDataAttribute:
    """Each point's colour ((N, 4), 0..1) as the point SCALAR "RGBA" of 4 components."""
    data = np.asarray(rgba)
    if data.ndim != 2 or data.shape[1] != 4:
        raise EncodeError(f"POLYDATA attribute {RGBA_ATTRIBUTE!r}", "shape (N, 4), 0..1",
                          f"shape {data.shape}")
    return point_attribute(RGBA_ATTRIBUTE, AttributeKind.SCALAR, data)


def vertex_cell(n: int) -> U32Array:
    """The VERTICES of `n` points drawn as points: one polyvertex cell ``[n, 0..n-1]``
    (none for no points)."""
    if n < 0:
        raise EncodeError("POLYDATA vertices", "a point count >= 0", n)
    if n == 0:
        return np.zeros(0, dtype=np.uint32)
    cell = np.empty(n + 1, dtype=np.uint32)
    cell[0] = n
    cell[1:] = np.arange(n, dtype=np.uint32)
    return cell


def point_colours(attributes: Iterable[PolyDataAttribute], npoints: int
                  ) -> Optional[F32Array]:
    """The points' colours ((npoints, 4) float32, as sent: 0..1 by convention) from the
    first colour attribute: TYPE RGBA under any name, or a 4-component SCALAR named
    "RGBA"; None if there is none."""
    for attr in attributes:
        if attr.on_cells:
            continue
        data = np.asarray(attr.data)
        if data.ndim != 2 or data.shape != (npoints, 4):
            continue
        if attr.kind == AttributeKind.RGBA or (
                attr.kind == AttributeKind.SCALAR and attr.name == RGBA_ATTRIBUTE):
            return data.astype(np.float32, copy=False)
    return None
