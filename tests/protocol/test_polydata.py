"""protocol.polydata: POLYDATA as every OpenIGTLink reader reads it (colours as a point
SCALAR "RGBA" of 4 components, point-only geometry as one polyvertex cell, point
attributes of the kinds OpenIGTLink 3.1 sizes right), and colours read back in both forms."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from protocol.errors import EncodeError
from protocol.messages import AttributeKind, PolyData, PolyDataAttribute
from protocol.polydata import (RGBA_ATTRIBUTE, colour_attribute, point_attribute, point_colours,
                               vertex_cell)

COLOURS = np.array([[1.0, 0.5, 0.0, 1.0], [0.0, 0.25, 1.0, 0.5], [0.0, 0.0, 0.0, 1.0]],
                   np.float32)
POINTS = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0]], np.float32)


def test_colours_and_one_polyvertex_cell_on_the_wire() -> None:
    """The bytes after the points: VERTICES [3, 0, 1, 2]; one attribute header TYPE 0x00
    (point SCALAR), NCOMPONENTS 4, N 3; "RGBA\\0" padded to 6; then 3 rows of 4 floats."""
    body = PolyData(points=POINTS, vertices=vertex_cell(3), attributes=[colour_attribute(COLOURS)])
    raw = body.pack()
    counts = struct.unpack_from(">10I", raw)
    assert counts == (3, 1, 16, 0, 0, 0, 0, 0, 0, 1)  # NPOINTS, NVERTICES 1 of 16 bytes, ...
    pos = 40 + 36
    assert struct.unpack_from(">4I", raw, pos) == (3, 0, 1, 2)
    pos += 16
    assert struct.unpack_from(">BBI", raw, pos) == (0x00, 4, 3)
    assert raw[pos + 6:pos + 12] == b"RGBA\0\0"
    np.testing.assert_array_equal(np.frombuffer(raw, ">f4", 12, pos + 12).reshape(3, 4), COLOURS)
    assert len(raw) == pos + 12 + 48
    again = PolyData.unpack(raw)
    assert again == body and again.pack() == raw
    (attr,) = again.attributes
    assert (attr.name, attr.kind, attr.on_cells) == (RGBA_ATTRIBUTE, AttributeKind.SCALAR, False)


def test_vertex_cell() -> None:
    assert vertex_cell(4).tolist() == [4, 0, 1, 2, 3]
    assert vertex_cell(1).tolist() == [1, 0]
    assert vertex_cell(0).tolist() == [] and vertex_cell(0).dtype == np.uint32
    with pytest.raises(EncodeError, match="point count"):
        vertex_cell(-1)


@pytest.mark.parametrize("kind", [AttributeKind.RGBA, AttributeKind.TCOORDS,
                                  AttributeKind.TENSOR])
def test_only_the_kinds_every_reader_sizes_right(kind: AttributeKind) -> None:
    """OpenIGTLink 3.1's C reader takes every TYPE but point SCALAR/VECTOR/NORMAL as 9
    floats a row: the daemon makes none of them."""
    with pytest.raises(EncodeError) as error:
        point_attribute("x", kind, np.zeros((2, 9 if kind == AttributeKind.TENSOR else 3)))
    assert kind.name in str(error.value) and "SCALAR, VECTOR or NORMAL" in str(error.value)
    normals = point_attribute("Normals", AttributeKind.NORMAL, np.eye(3, dtype=np.float32))
    assert (normals.kind, normals.on_cells) == (AttributeKind.NORMAL, False)


def test_colour_attribute_wants_four_components() -> None:
    with pytest.raises(EncodeError, match=r"shape \(N, 4\)"):
        colour_attribute(np.zeros((3, 3)))


def test_point_colours_read_both_forms_and_slicers_padded_one() -> None:
    """Clients built before send TYPE RGBA (any name), 3D Slicer sends it padded to 9
    components (protocol.messages keeps 4), the daemon now a SCALAR "RGBA": the same
    colours from each."""
    scalar = PolyData.unpack(PolyData(points=POINTS, attributes=[colour_attribute(COLOURS)])
                             .pack())
    old = PolyData.unpack(PolyData(points=POINTS, attributes=[
        PolyDataAttribute("Colors", AttributeKind.RGBA, COLOURS)]).pack())
    # Slicer's layout: NCOMPONENTS 9 and 9N floats, the N rows of 4 first, then filler.
    head = bytearray(old.pack()[:40 + 36 + 6 + 8])  # counts, points, header, "Colors\0\0"
    struct.pack_into(">B", head, 40 + 36 + 1, 9)
    floats = np.concatenate([COLOURS.ravel(), np.full(15, 7.0, np.float32)])
    padded = PolyData.unpack(bytes(head) + floats.astype(">f4").tobytes())
    for body in (scalar, old, padded):
        np.testing.assert_array_equal(point_colours(body.attributes, 3), COLOURS)
    # Not colours: another SCALAR name, cell data, a wrong row count.
    for attr in (PolyDataAttribute("weights", AttributeKind.SCALAR, COLOURS),
                 PolyDataAttribute(RGBA_ATTRIBUTE, AttributeKind.RGBA, COLOURS, on_cells=True),
                 PolyDataAttribute(RGBA_ATTRIBUTE, AttributeKind.SCALAR, COLOURS[:2])):
        assert point_colours([attr], 3) is None
