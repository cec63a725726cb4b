"""The daemon's POLYDATA as 3D Slicer's OpenIGTLink library reads it: a robot mesh, a point
cloud and markers made by our encoders, framed as sent, unpacked by OpenIGTLink 3.1 (the
library Slicer's connector links, built by the real-Slicer tier) in a small C++ probe
(tests/protocol/cpp/igtl_polydata_reader_probe.cxx) that prints what it read.

What Slicer saw before (reproduced first): colours as TYPE RGBA are read as 9 floats a row,
so the "Normals" after them came out as garbage; and one VERTICES cell per point, of which
OpenIGTLinkIO's converter writes the second cell's id past its vtkVertex (Slicer dies).
Now: colours as the point SCALAR "RGBA" (4 components) and one polyvertex cell."""

from __future__ import annotations

import subprocess
from dataclasses import dataclass

import numpy as np
import pytest

from bridge.codecs.pointcloud import CloudArrays, arrays_to_polydata
from bridge.markers.geometry import MarkerSpec, build_model
from bridge.robots import LoadOptions, MeshCache, VisualMesh, load_robot, to_polydata
from protocol.framing import encode
from protocol.messages import (AttributeKind, Message, PolyData, PolyDataAttribute, RawBody,
                               cells_from_array)
from protocol.polydata import NORMALS_ATTRIBUTE, RGBA_ATTRIBUTE
from tests.protocol.igtl3_probes import igtl3_probe

pytestmark = pytest.mark.integration


@dataclass
class Read:
    """What OpenIGTLink 3.1 made of one POLYDATA."""

    points: np.ndarray
    cells: dict[str, list[list[int]]]  # section -> each cell's point ids
    attributes: dict[str, tuple[int, np.ndarray]]  # name -> (TYPE, rows)


def read_with_igtl3(body: PolyData | RawBody) -> Read:
    raw = encode(Message("model", body))
    result = subprocess.run([str(igtl3_probe("igtl_polydata_reader_probe"))], input=raw,
                            capture_output=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr.decode(errors="replace")
    points: list[list[float]] = []
    cells: dict[str, list[list[int]]] = {}
    attributes: dict[str, tuple[int, list[list[float]]]] = {}
    section: list[list[int]] = []
    rows: list[list[float]] = []
    for line in result.stdout.decode().splitlines():
        word, *rest = line.split()
        if word == "p":
            points.append([float(v) for v in rest])
        elif word == "cells":
            section = cells.setdefault(rest[0], [])
        elif word == "c":
            section.append([int(v) for v in rest[1:]])
        elif word == "a":
            rows = []
            attributes[rest[0]] = (int(rest[1]), rows)
        elif word == "d":
            rows.append([float(v) for v in rest])
    return Read(np.array(points).reshape(-1, 3), cells,
                {name: (kind, np.array(data)) for name, (kind, data) in attributes.items()})


def sphere_visual() -> VisualMesh:
    urdf = ('<robot name="r"><link name="a"><visual><geometry><sphere radius="0.01"/>'
            '</geometry><material name="m"><color rgba="1 0.5 0 1"/></material></visual>'
            '</link></robot>')
    return load_robot(urdf, options=LoadOptions(normals=True), cache=MeshCache()).visuals[0]


def test_colours_before_normals_were_misread_as_slicer_saw_them() -> None:
    """Reproduces issue 42 (8): TYPE RGBA then NORMAL, as robots sent them: OpenIGTLink 3.1
    reads the RGBA as 9N floats, so the normals come from past the body (garbage); one
    VERTICES cell per point reaches the converter as N cells (the crash)."""
    v = sphere_visual()
    n = len(v.vertices)
    old = PolyData(points=v.vertices, vertices=cells_from_array(np.arange(n).reshape(n, 1)),
                   attributes=[PolyDataAttribute(RGBA_ATTRIBUTE, AttributeKind.RGBA,
                                                 np.tile([1, 0.5, 0, 1], (n, 1))),
                               PolyDataAttribute(NORMALS_ATTRIBUTE, AttributeKind.NORMAL,
                                                 v.normals)])
    read = read_with_igtl3(old)
    assert len(read.cells["vertices"]) == n  # one vtkVertex each: the second one crashed
    kind, normals = read.attributes[NORMALS_ATTRIBUTE]
    assert not np.allclose(normals, v.normals, atol=1e-3)


def test_robot_mesh_reads_with_its_colours_and_normals() -> None:
    v = sphere_visual()
    read = read_with_igtl3(to_polydata(v))
    n = len(v.vertices)
    np.testing.assert_allclose(read.points, v.vertices, rtol=1e-6)
    assert len(read.cells["polygons"]) == len(v.triangles) and read.cells["vertices"] == []
    kind, rgba = read.attributes[RGBA_ATTRIBUTE]
    assert kind == 0x00  # point SCALAR, 4 components
    np.testing.assert_allclose(rgba, np.tile([1, 0.5, 0, 1], (n, 1)), rtol=1e-6)
    kind, normals = read.attributes[NORMALS_ATTRIBUTE]
    assert kind == 0x02
    np.testing.assert_allclose(normals, v.normals, rtol=1e-6, atol=1e-7)


def test_point_cloud_reads_as_one_polyvertex_cell_with_its_colours_and_scalars() -> None:
    n = 50
    rng = np.random.default_rng(3)
    xyz = rng.normal(size=(n, 3))
    colours = rng.integers(0, 256, size=(n, 4), dtype=np.uint8)
    intensity = np.arange(n, dtype=np.float32) * 0.5
    read = read_with_igtl3(arrays_to_polydata(CloudArrays(xyz, colours,
                                                          {"intensity": intensity})))
    np.testing.assert_allclose(read.points, xyz * 1000.0, rtol=1e-6)
    assert read.cells["vertices"] == [list(range(n))]  # one cell: no id past a vtkVertex
    kind, rgba = read.attributes[RGBA_ATTRIBUTE]
    assert kind == 0x00
    np.testing.assert_allclose(rgba, colours / 255.0, rtol=1e-6)
    kind, values = read.attributes["intensity"]  # after the colours: read at its offset
    np.testing.assert_array_equal(values[:, 0], intensity)


def test_markers_read_with_their_colours() -> None:
    """A POINTS marker with per-point colours (one polyvertex cell) and a CUBE (packed from
    a template, RawBody)."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    per_point = np.array([[1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1], [1, 1, 1, 0.5]])
    model = build_model(MarkerSpec(kind="points", points=pts, colors=per_point,
                                   scale=np.array([0.02, 0.02, 0.0])))
    read = read_with_igtl3(model.body)
    np.testing.assert_allclose(read.points, pts * 1000.0)
    assert read.cells["vertices"] == [[0, 1, 2, 3]]
    kind, rgba = read.attributes[RGBA_ATTRIBUTE]
    assert kind == 0x00
    np.testing.assert_allclose(rgba, per_point, rtol=1e-6)
    cube = build_model(MarkerSpec(kind="cube", scale=np.array([0.02, 0.02, 0.02]),
                                  color=(1.0, 0.0, 0.0, 1.0)))
    assert isinstance(cube.body, RawBody)
    read = read_with_igtl3(cube.body)
    assert np.ptp(read.points, axis=0) == pytest.approx([20.0, 20.0, 20.0])
    kind, rgba = read.attributes[RGBA_ATTRIBUTE]
    assert kind == 0x00
    np.testing.assert_allclose(rgba, np.tile([1, 0, 0, 1], (len(read.points), 1)))


def convert_with_igtlio(body: PolyData | RawBody) -> subprocess.CompletedProcess[bytes]:
    """The same probe, then OpenIGTLinkIO's converter (what makes Slicer's model)."""
    return subprocess.run([str(igtl3_probe("igtl_polydata_reader_probe", igtlio=True))],
                          input=encode(Message("model", body)), capture_output=True,
                          timeout=60, check=False)


def vtk_output(stdout: bytes) -> tuple[list[int], dict[str, np.ndarray]]:
    """The converter's vertex cells (legacy layout) and point arrays."""
    verts: list[int] = []
    arrays: dict[str, list[list[float]]] = {}
    rows: list[list[float]] = []
    for line in stdout.decode().splitlines():
        word, *rest = line.split()
        if word == "vtkverts":
            verts = [int(v) for v in rest]
        elif word == "vtkarray":
            rows = arrays.setdefault(rest[0], [])
        elif word == "r":
            rows.append([float(v) for v in rest])
    return verts, {name: np.array(data) for name, data in arrays.items()}


def test_slicers_converter_dies_on_a_vertex_cell_per_point_and_takes_one_polyvertex() -> None:
    """Issue 42 (8), against OpenIGTLinkIO's own converter: a cloud of 4 points as one
    VERTICES cell each kills it (the id of cell i is written at index i of a vtkVertex of
    one id: glibc aborts, "munmap_chunk(): invalid pointer", as Slicer did); the daemon's
    cloud (one polyvertex cell, colours as the SCALAR "RGBA") converts, keeping the first
    point's vertex (the module adds the rest) and the 4-component colours."""
    xyz = np.array([[0.01 * i, 0.02 * i, 0.03 * i] for i in range(4)])
    colours = np.array([[40 * i, 80, 120, 255] for i in range(4)], dtype=np.uint8)
    body = arrays_to_polydata(CloudArrays(xyz, colours, {}))
    old = PolyData(points=body.points, vertices=cells_from_array(np.arange(4).reshape(4, 1)),
                   attributes=[PolyDataAttribute(RGBA_ATTRIBUTE, AttributeKind.RGBA,
                                                 colours / 255.0)])
    crashed = convert_with_igtlio(old)
    assert crashed.returncode != 0 and b"vtkverts" not in crashed.stdout, crashed
    done = convert_with_igtlio(body)
    assert done.returncode == 0, done.stderr.decode(errors="replace")
    verts, arrays = vtk_output(done.stdout)
    assert verts == [1, 0]
    np.testing.assert_allclose(arrays[RGBA_ATTRIBUTE], colours / 255.0, rtol=1e-6)


def test_slicers_converter_reads_robot_normals_and_marker_colours() -> None:
    v = sphere_visual()
    done = convert_with_igtlio(to_polydata(v))
    assert done.returncode == 0, done.stderr.decode(errors="replace")
    verts, arrays = vtk_output(done.stdout)
    assert verts == [] and arrays[RGBA_ATTRIBUTE].shape == (len(v.vertices), 4)
    np.testing.assert_allclose(arrays[NORMALS_ATTRIBUTE], v.normals, rtol=1e-6, atol=1e-7)
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float64)
    model = build_model(MarkerSpec(kind="points", points=pts, color=(0.0, 0.0, 1.0, 1.0),
                                   scale=np.array([0.005, 0.005, 0.0])))
    done = convert_with_igtlio(model.body)
    assert done.returncode == 0, done.stderr.decode(errors="replace")
    verts, arrays = vtk_output(done.stdout)
    assert verts == [1, 0]
    np.testing.assert_allclose(arrays[RGBA_ATTRIBUTE], np.tile([0, 0, 1, 1], (3, 1)))
