"""Markers through the daemon: every visualization_msgs/Marker type, Path, PolygonStamped
and PointStamped from a real rclpy publisher (tests/peers/marker_publisher.py) to a real
TCP client, placed by tf.

Expected geometry is computed here, independently of bridge.markers: box corners from the
pose and the scale, an arrow's tip, the ellipsoid equation, the STL the test wrote, mm =
1000 x m. The daemon runs with --robot-dir (the mesh root) and --deny-frame 'secret*'.
"""

from __future__ import annotations

import itertools
import json
import math
import os
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

from protocol.messages import AttributeKind, Message, PolyData, String, Transform
from protocol.polydata import RGBA_ATTRIBUTE
from protocol.naming import (KEY_COLOR, KEY_DELETED, KEY_LINE_WIDTH, KEY_MARKER_ID,
                             KEY_MARKER_NS, KEY_MARKER_TYPE, KEY_MARKERS, KEY_PARENT_DEVICE,
                             KEY_POINT_SIZE, KEY_POSITION, KEY_TEXT_HEIGHT)
from slicer_client.connection import CommandRefusedError, Connection
from support import (Child, Processes, RunningDaemon, assert_clean_exit, scaled, start_daemon,
                     wait_until)

ADD, DELETE, DELETEALL = 0, 2, 3
ARROW, CUBE, SPHERE, CYLINDER, LINE_STRIP, LINE_LIST = 0, 1, 2, 3, 4, 5
CUBE_LIST, SPHERE_LIST, POINTS, TEXT, MESH, TRIANGLE_LIST = 6, 7, 8, 9, 10, 11
HALF = math.sqrt(0.5)
Z90 = [0.0, 0.0, HALF, HALF]  # 90 degrees about z
RED, GREEN, BLUE = [1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0]
TETRA = [(0.0, 0.0, 0.0), (0.01, 0.0, 0.0), (0.0, 0.02, 0.0), (0.0, 0.0, 0.03)]  # metres


# A triangle whose vertices are red, green and blue (PLY vertex colours, metres).
COLOURED_PLY = """ply
format ascii 1.0
element vertex 3
property float x
property float y
property float z
property uchar red
property uchar green
property uchar blue
property uchar alpha
element face 1
property list uchar int vertex_indices
end_header
0 0 0 255 0 0 255
0.1 0 0 0 255 0 255
0 0.1 0 0 0 255 255
3 0 1 2
"""
PLY_COLOURS = {(0.0, 0.0, 0.0): RED, (100.0, 0.0, 0.0): GREEN, (0.0, 100.0, 0.0): BLUE}


def write_stl(path: Path, vertices: list[tuple[float, float, float]]) -> None:
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    lines = ["solid tetra"]
    for face in faces:
        lines += ["facet normal 0 0 0", "outer loop"]
        lines += [f"vertex {vertices[i][0]} {vertices[i][1]} {vertices[i][2]}" for i in face]
        lines += ["endloop", "endfacet"]
    path.write_text("\n".join(lines + ["endsolid tetra"]) + "\n")


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("marker-meshes")
    inside = root / "meshes"
    outside = root / "elsewhere"
    inside.mkdir()
    outside.mkdir()
    write_stl(inside / "tetra.stl", TETRA)
    write_stl(outside / "tetra.stl", TETRA)
    (inside / "broken.stl").write_text("solid nothing here\n")
    (inside / "coloured.ply").write_text(COLOURED_PLY)
    return {"inside": inside, "outside": outside, "root": root}


@pytest.fixture(scope="module")
def daemon(module_processes: Processes, folders: dict[str, Path]) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--robot-dir", str(folders["inside"]),
                           "--package-path", f"marker_meshes={folders['inside']}",
                           "--deny-frame", "secret*")
    yield running
    assert_clean_exit(running)


class Peer:
    """The marker publisher and its control file."""

    def __init__(self, processes: Processes, folder: Path) -> None:
        self.control = folder / "control.json"
        self.seq = itertools.count(1)
        self.child: Child = processes.python("markers", "marker_publisher.py",
                                             str(self.control))
        self.child.wait_for_output("READY", timeout=30)

    def send(self, **doc: Any) -> None:
        seq = next(self.seq)
        tmp = self.control.with_suffix(".tmp")
        tmp.write_text(json.dumps({"seq": seq, **doc}))
        os.replace(tmp, self.control)
        self.child.wait_for_output(f"APPLIED {seq}", timeout=30)


@pytest.fixture(scope="module")
def peer(module_processes: Processes, folders: dict[str, Path]) -> Peer:
    return Peer(module_processes, folders["root"])


@pytest.fixture(scope="module")
def client(daemon: RunningDaemon, peer: Peer) -> Iterator[Connection]:
    connection = daemon.connect()
    for topic, kind in (("/test_markers", "MarkerArray"), ("/test_path", "Path"),
                        ("/test_polygon", "PolygonStamped"), ("/test_point", "PointStamped"),
                        ("/test_marker", "visualization_msgs/msg/Marker")):
        result = connection.command("create_marker_subscriber",
                                    {"topic": topic, "type": kind, "fixed_frame": "world"})
        assert result["existed"] is False and result["device"].startswith("mks:")
    yield connection
    connection.close()


# ------------------------------------------------------------------ helpers


def index(client: Connection, topic: str) -> Message:
    device = client.command("list_markers", {"topic": topic})["device"]
    return client.wait_for(device, timeout=scaled(10))


def wait_markers(client: Connection, topic: str, want: set[tuple[str, int]]
                 ) -> dict[tuple[str, int], dict[str, Any]]:
    """Wait until the topic's live markers are exactly `want`; their list_markers rows."""
    found: dict[tuple[str, int], dict[str, Any]] = {}

    def ready() -> bool:
        nonlocal found
        rows = client.command("list_markers", {"topic": topic})["markers"]
        found = {(r["ns"], r["id"]): r for r in rows}
        return set(found) == want
    wait_until(ready, 10, f"markers {sorted(want)} on {topic}")  # scaled there
    return found


def model(client: Connection, device: str) -> Message:
    return client.wait_for(device, timeout=scaled(10))


def points(message: Message) -> np.ndarray:
    assert isinstance(message.body, PolyData), message
    return np.asarray(message.body.points, dtype=np.float64)


def rgba(message: Message) -> np.ndarray:
    assert isinstance(message.body, PolyData)
    (attribute,) = [a for a in message.body.attributes if a.name == RGBA_ATTRIBUTE]
    assert attribute.kind == AttributeKind.SCALAR  # as every reader sizes it (4 components)
    return np.asarray(attribute.data, dtype=np.float64)


def box_corners(centre: np.ndarray, rotation: np.ndarray, size: np.ndarray) -> set[tuple]:
    out = set()
    for signs in itertools.product((-0.5, 0.5), repeat=3):
        corner = centre + rotation @ (np.array(signs) * size)
        out.add(tuple(np.round(corner * 1000.0, 2)))
    return out


def rounded(p: np.ndarray) -> set[tuple]:
    return {tuple(np.round(row, 2)) for row in p}


def rot_z90() -> np.ndarray:
    return np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


SHAPES = [
    {"ns": "shapes", "id": 1, "type": CUBE, "pos": [0.1, 0.0, 0.0], "scale": [0.2, 0.4, 0.6],
     "color": RED},
    {"ns": "shapes", "id": 2, "type": CUBE, "quat": Z90, "scale": [0.2, 0.4, 0.6],
     "color": [0.0, 0.5, 1.0, 0.5]},
    {"ns": "shapes", "id": 3, "type": SPHERE, "pos": [0.0, 0.0, 1.0],
     "scale": [0.2, 0.4, 0.6]},
    {"ns": "shapes", "id": 4, "type": CYLINDER, "scale": [0.2, 0.2, 0.5]},
    {"ns": "arrows", "id": 5, "type": ARROW, "quat": Z90, "scale": [1.0, 0.1, 0.1]},
    {"ns": "arrows", "id": 6, "type": ARROW, "points": [[0, 0, 0], [0, 0, 0.5]],
     "scale": [0.02, 0.04, 0.1]},
    {"ns": "lines", "id": 7, "type": LINE_STRIP, "pos": [0.0, 0.0, 0.5], "scale": [0.01, 0, 0],
     "points": [[0, 0, 0], [1, 0, 0], [1, 1, 0]], "colors": [RED, GREEN, BLUE]},
    {"ns": "lines", "id": 8, "type": LINE_LIST, "scale": [0.02, 0, 0],
     "points": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 1], [5, 5, 5]]},
    {"ns": "lists", "id": 9, "type": CUBE_LIST, "scale": [0.1, 0.1, 0.1],
     "points": [[0, 0, 0], [1, 0, 0]], "colors": [RED, BLUE]},
    {"ns": "lists", "id": 10, "type": SPHERE_LIST, "scale": [0.1, 0.1, 0.1],
     "points": [[0, 0, 0], [1, 0, 0], [0, 1, 0]]},
    {"ns": "lists", "id": 11, "type": POINTS, "scale": [0.02, 0.03, 0],
     "points": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "color": GREEN},
    {"ns": "lists", "id": 12, "type": TRIANGLE_LIST, "scale": [2.0, 2.0, 2.0],
     "points": [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1], [0.1, 0, 0.1],
                [0, 0.1, 0.1]], "colors": [RED, RED, RED, BLUE, BLUE, BLUE]},
    {"ns": "", "id": 13, "type": TEXT, "pos": [0.1, 0.2, 0.3], "scale": [0, 0, 0.05],
     "text": "hello marker", "color": [1.0, 1.0, 0.0, 1.0]},
]


# ------------------------------------------------------------------ tests


def test_every_marker_type_in_mm_placed_by_tf(client: Connection, peer: Peer,
                                              folders: dict[str, Path]) -> None:
    mesh = {"ns": "mesh", "id": 14, "type": MESH, "pos": [0.0, 0.0, 1.0],
            "scale": [2.0, 2.0, 2.0], "mesh": f"file://{folders['inside']}/tetra.stl",
            "color": BLUE}
    # frame_locked: each model stays in its frame, under the frame's TRANSFORM.
    peer.send(markers=[dict(m, locked=True) for m in SHAPES + [mesh]])
    want = {(m["ns"], m["id"]) for m in SHAPES + [mesh]}
    rows = wait_markers(client, "/test_markers", want)
    dev = {key: row["device"] for key, row in rows.items()}

    # Identity in the metadata; one TRANSFORM for the frame, shared by all.
    cube = model(client, dev[("shapes", 1)])
    meta = cube.metadata
    assert (meta[KEY_MARKER_NS], meta[KEY_MARKER_ID], meta[KEY_MARKER_TYPE]) == \
        ("shapes", "1", "cube")
    assert {row["frame_device"] for row in rows.values()} == {meta[KEY_PARENT_DEVICE]}
    frame = client.wait_for(meta[KEY_PARENT_DEVICE], lambda m: isinstance(m.body, Transform),
                            timeout=scaled(10))
    np.testing.assert_allclose(np.asarray(frame.body.matrix)[:3, 3], [100.0, 200.0, 300.0],
                               atol=1e-3)
    np.testing.assert_allclose(np.asarray(frame.body.matrix)[:3, :3], np.eye(3), atol=1e-6)

    # CUBE: its 8 corners, the colour on every point and in metadata.
    assert rounded(points(cube)) == box_corners(np.array([0.1, 0, 0]), np.eye(3),
                                                np.array([0.2, 0.4, 0.6]))
    np.testing.assert_allclose(rgba(cube), np.tile(RED, (8, 1)))
    assert [float(v) for v in meta[KEY_COLOR].split()] == RED
    turned = model(client, dev[("shapes", 2)])
    assert rounded(points(turned)) == box_corners(np.zeros(3), rot_z90(),
                                                  np.array([0.2, 0.4, 0.6]))
    np.testing.assert_allclose(rgba(turned)[0], [0.0, 0.5, 1.0, 0.5])

    # SPHERE: an ellipsoid of semi-axes 100, 200, 300 mm about (0, 0, 1000).
    p = points(model(client, dev[("shapes", 3)]))
    radius = (p[:, 0] / 100.0) ** 2 + (p[:, 1] / 200.0) ** 2 + ((p[:, 2] - 1000.0) / 300.0) ** 2
    np.testing.assert_allclose(radius, 1.0, atol=1e-4)
    np.testing.assert_allclose(p.max(axis=0), [100.0, 200.0, 1300.0], atol=0.5)

    # CYLINDER along z: radius 100 mm, ends at z = +-250 mm.
    p = points(model(client, dev[("shapes", 4)]))
    r = np.hypot(p[:, 0], p[:, 1])
    assert r.max() == pytest.approx(100.0, abs=1e-3)
    assert set(np.round(p[:, 2], 3)) == {-250.0, 250.0}
    assert np.all((np.isclose(r, 100.0, atol=1e-3)) | (r < 1e-6))

    # ARROW from its pose, turned 90 degrees about z: 1000 mm along +y, tip on the axis.
    p = points(model(client, dev[("arrows", 5)]))
    assert p[:, 1].min() == pytest.approx(0.0, abs=1e-3)
    assert p[:, 1].max() == pytest.approx(1000.0, abs=1e-3)
    tip = p[np.argmax(p[:, 1])]
    np.testing.assert_allclose(tip, [0.0, 1000.0, 0.0], atol=1e-3)
    assert np.abs(p[:, 0]).max() == pytest.approx(50.0, abs=1e-3)  # head diameter 0.1 m
    # ARROW from two points: tip at points[1], head 100 mm long, head diameter 40 mm.
    p = points(model(client, dev[("arrows", 6)]))
    np.testing.assert_allclose(p[np.argmax(p[:, 2])], [0.0, 0.0, 500.0], atol=1e-3)
    assert p[:, 2].min() == pytest.approx(0.0, abs=1e-3)
    wide = p[np.hypot(p[:, 0], p[:, 1]) > 15.0]  # the head's base ring (radius 20 mm)
    np.testing.assert_allclose(wide[:, 2], 400.0, atol=1e-3)
    assert np.hypot(p[:, 0], p[:, 1]).max() == pytest.approx(20.0, abs=1e-3)

    # LINE_STRIP: one polyline cell, per-point colours, the pose's z, width in metadata.
    strip = model(client, dev[("lines", 7)])
    np.testing.assert_allclose(points(strip), [[0, 0, 500], [1000, 0, 500], [1000, 1000, 500]])
    assert list(strip.body.lines) == [3, 0, 1, 2]
    np.testing.assert_allclose(rgba(strip), [RED, GREEN, BLUE])
    assert float(strip.metadata[KEY_LINE_WIDTH]) == pytest.approx(10.0)
    # LINE_LIST: two segments (the fifth point has no partner).
    assert list(model(client, dev[("lines", 8)]).body.lines) == [2, 0, 1, 2, 2, 3]

    # CUBE_LIST: 8 corners per point, each point's colour on its cube.
    cubes = model(client, dev[("lists", 9)])
    p, c = points(cubes), rgba(cubes)
    expected = box_corners(np.zeros(3), np.eye(3), np.full(3, 0.1)) | box_corners(
        np.array([1.0, 0, 0]), np.eye(3), np.full(3, 0.1))
    assert rounded(p) == expected and len(p) == 16
    np.testing.assert_allclose(c[p[:, 0] > 500.0], np.tile(BLUE, (8, 1)))
    np.testing.assert_allclose(c[p[:, 0] < 500.0], np.tile(RED, (8, 1)))
    # SPHERE_LIST: every point 50 mm from one of the centres, as many per centre.
    p = points(model(client, dev[("lists", 10)]))
    centres = np.array([[0, 0, 0], [1000, 0, 0], [0, 1000, 0]], dtype=float)
    d = np.linalg.norm(p[:, None, :] - centres[None, :, :], axis=2)
    np.testing.assert_allclose(d.min(axis=1), 50.0, atol=1e-3)
    counts = np.bincount(d.argmin(axis=1), minlength=3)
    assert counts[0] == counts[1] == counts[2] > 0
    # POINTS: one polyvertex cell of the 4 points (a second vertex cell crashed Slicer's
    # converter), point size in metadata.
    pts = model(client, dev[("lists", 11)])
    assert list(pts.body.vertices) == [4, 0, 1, 2, 3]
    np.testing.assert_allclose(points(pts), [[0, 0, 0], [1000, 0, 0], [0, 1000, 0],
                                             [0, 0, 1000]])
    assert pts.metadata[KEY_POINT_SIZE] == "20 30"
    # TRIANGLE_LIST: points scaled by 2 (as RViz), two triangles, per-vertex colours.
    tri = model(client, dev[("lists", 12)])
    np.testing.assert_allclose(points(tri), np.array(SHAPES[11]["points"]) * 2000.0,
                               atol=1e-3)
    assert list(tri.body.polygons) == [3, 0, 1, 2, 3, 3, 4, 5]
    np.testing.assert_allclose(rgba(tri), [RED] * 3 + [BLUE] * 3)

    # TEXT_VIEW_FACING: a STRING with the text, placed by its metadata.
    text = model(client, dev[("", 13)])
    assert isinstance(text.body, String) and text.body.text == "hello marker"
    assert [float(v) for v in text.metadata[KEY_POSITION].split()] == [100.0, 200.0, 300.0]
    assert float(text.metadata[KEY_TEXT_HEIGHT]) == pytest.approx(50.0)
    assert [float(v) for v in text.metadata[KEY_COLOR].split()] == [1.0, 1.0, 0.0, 1.0]

    # MESH_RESOURCE inside the mesh root: the STL's vertices x2, lifted 1000 mm.
    p = points(model(client, dev[("mesh", 14)]))
    expected = {tuple(np.round(np.array(v) * 2000.0 + [0, 0, 1000.0], 2)) for v in TETRA}
    assert rounded(p) == expected


def tf_known(client: Connection, parent: str, child: str) -> None:
    client.command("lookup_transform", {"parent": parent, "child": child,
                                        "timeout": scaled(10)})


def test_path_polygon_point(client: Connection, peer: Peer) -> None:
    tf_known(client, "world", "base")
    peer.send(path={"frame": "base", "points": [[0, 0, 0], [1, 0, 0], [1, 2, 0]]},
              polygon={"frame": "world", "points": [[0, 0, 0], [1, 0, 0], [1, 1, 0],
                                                     [0, 1, 0]]},
              point={"frame": "", "point": [1.0, 2.0, 3.0]})
    path = wait_markers(client, "/test_path", {("", 0)})[("", 0)]
    # A Path has no frame_locked: placed once in the fixed frame, as RViz shows it (base is
    # at (100, 200, 300) mm in world).
    assert path["type"] == "path" and path["frame"] == "base" and path["placed"] is True
    assert path["frame_device"] == "mkf:world>world"
    body = model(client, path["device"])
    np.testing.assert_allclose(points(body), [[100, 200, 300], [1100, 200, 300],
                                              [1100, 2200, 300]], atol=1e-3)
    assert list(body.body.lines) == [3, 0, 1, 2]
    polygon = wait_markers(client, "/test_polygon", {("", 0)})[("", 0)]
    assert list(model(client, polygon["device"]).body.lines) == [5, 0, 1, 2, 3, 0]
    point = wait_markers(client, "/test_point", {("", 0)})[("", 0)]
    assert point["frame"] == "world"  # an empty frame_id is the fixed frame
    body = model(client, point["device"])
    np.testing.assert_allclose(points(body), [[1000.0, 2000.0, 3000.0]])
    assert list(body.body.vertices) == [1, 0]
    frame = client.wait_for(point["frame_device"], lambda m: isinstance(m.body, Transform),
                            timeout=scaled(10))
    np.testing.assert_allclose(np.asarray(frame.body.matrix), np.eye(4), atol=1e-9)


def test_markers_move_with_tf(client: Connection, peer: Peer) -> None:
    cube = {"ns": "moving", "id": 1, "type": CUBE, "frame": "moving", "scale": [0.1] * 3,
            "locked": True}
    peer.send(marker={"action": DELETEALL})
    peer.send(marker=cube, moving=[0.5, 0.0, 0.0])
    row = wait_markers(client, "/test_marker", {("moving", 1)})[("moving", 1)]
    device = row["frame_device"]

    def at(xyz: list[float]) -> Any:
        return lambda m: isinstance(m.body, Transform) and np.allclose(
            np.asarray(m.body.matrix)[:3, 3], xyz, atol=1e-3)
    client.wait_for(device, at([500.0, 0.0, 0.0]), timeout=scaled(10))
    before = model(client, row["device"])
    peer.send(moving=[0.0, 1.0, 0.0])
    client.wait_for(device, at([0.0, 1000.0, 0.0]), timeout=scaled(10))
    # The model itself was not re-sent: the same message object is the latest.
    assert client.latest(row["device"]) is before


def test_an_unlocked_marker_is_placed_once_and_stays(client: Connection, peer: Peer) -> None:
    """frame_locked false (RViz's default): placed by tf when it comes, then it stays where
    it was put while its frame moves on; the locked twin follows."""
    locked = {"ns": "twin", "id": 1, "type": CUBE, "frame": "moving", "scale": [0.1] * 3,
              "pos": [0.0, 0.0, 0.1], "locked": True}
    unlocked = dict(locked, id=2, locked=False)
    peer.send(marker={"action": DELETEALL})
    peer.send(moving=[0.5, 0.0, 0.0])
    peer.send(marker=locked)
    row = wait_markers(client, "/test_marker", {("twin", 1)})[("twin", 1)]

    def at(xyz: list[float]) -> Any:
        return lambda m: isinstance(m.body, Transform) and np.allclose(
            np.asarray(m.body.matrix)[:3, 3], xyz, atol=1e-3)
    client.wait_for(row["frame_device"], at([500.0, 0.0, 0.0]), timeout=scaled(10))
    peer.send(markers=[], marker=unlocked)  # "moving" is at (0.5, 0, 0) now
    rows = wait_markers(client, "/test_marker", {("twin", 1), ("twin", 2)})
    placed = rows[("twin", 2)]
    assert placed["placed"] is True and placed["frame"] == "moving"
    assert placed["frame_device"] == "mkf:world>world"
    body = model(client, placed["device"])
    assert body.metadata[KEY_PARENT_DEVICE] == "mkf:world>world"
    corners = box_corners(np.array([0.5, 0.0, 0.1]), np.eye(3), np.full(3, 0.1))
    assert rounded(points(body)) == corners
    peer.send(moving=[0.0, 1.0, 0.0])
    client.wait_for(row["frame_device"], at([0.0, 1000.0, 0.0]), timeout=scaled(10))
    assert client.latest(placed["device"]) is body  # not moved, not re-sent
    assert rounded(points(client.latest(placed["device"]))) == corners


def test_delete_deleteall_and_lifetime(client: Connection, peer: Peer,
                                       daemon: RunningDaemon) -> None:
    # DELETEALL at the head of the array removes the first test's markers.
    peer.send(markers=[{"action": DELETEALL}] + [
        {"ns": "d", "id": i, "type": CUBE, "scale": [0.1] * 3} for i in range(3)])
    rows = wait_markers(client, "/test_markers", {("d", 0), ("d", 1), ("d", 2)})
    peer.send(markers=[{"ns": "d", "id": 1, "action": DELETE}])
    rows_after = wait_markers(client, "/test_markers", {("d", 0), ("d", 2)})
    gone = rows[("d", 1)]["device"]
    status = index(client, "/test_markers")
    assert gone not in json.loads(status.metadata[KEY_MARKERS])
    assert {rows_after[("d", 0)]["device"], rows_after[("d", 2)]["device"]} == \
        set(json.loads(status.metadata[KEY_MARKERS]))
    # A client subscribing now gets the live models and not the deleted one (markers go
    # to the clients that created or subscribed to their topic: issue 22).
    late = daemon.connect()
    try:
        assert late.command("create_marker_subscriber", {
            "topic": "/test_markers", "type": "MarkerArray",
            "fixed_frame": "world"})["existed"] is True
        late.wait_for(rows[("d", 2)]["device"], timeout=scaled(10))
        late.wait_for(status.device_name, timeout=scaled(10))
        assert late.latest(gone) is None
    finally:
        late.close()
    peer.send(markers=[{"action": DELETEALL}])
    wait_markers(client, "/test_markers", set())
    status = index(client, "/test_markers")
    assert json.loads(status.metadata[KEY_MARKERS]) == []
    # Lifetime: gone on its own, by the daemon's timer; one without lifetime stays.
    peer.send(markers=[{"ns": "life", "id": 1, "type": SPHERE, "scale": [0.1] * 3,
                        "lifetime": 0.4},
                       {"ns": "life", "id": 2, "type": SPHERE, "scale": [0.1] * 3}])
    wait_markers(client, "/test_markers", {("life", 2)})
    status = client.wait_for(status.device_name, lambda m: json.loads(
        m.metadata[KEY_DELETED]) != [], timeout=scaled(10))
    assert len(json.loads(status.metadata[KEY_MARKERS])) == 1


def test_bad_markers_are_refused_and_the_daemon_serves(client: Connection, peer: Peer,
                                                       folders: dict[str, Path]) -> None:
    cases = [
        ({"ns": "bad", "id": 1, "type": CUBE, "pos": [float("nan"), 0, 0]},
         "pose.position: expected finite numbers"),
        ({"ns": "bad", "id": 2, "type": CUBE, "scale": [0.0, 1.0, 1.0]},
         "scale.x: expected a positive size in metres, got 0"),
        ({"ns": "bad", "id": 3, "type": 42}, "type: expected a Marker type 0..11"),
        ({"ns": "bad", "id": 4, "type": TRIANGLE_LIST, "points": [[0, 0, 0], [1, 0, 0]]},
         "points: expected a multiple of 3 points"),
        ({"ns": "bad", "id": 5, "type": MESH, "mesh": str(folders["outside"] / "tetra.stl")},
         "expected an existing file inside a --robot-dir or --package-path folder"),
        ({"ns": "bad", "id": 6, "type": MESH, "mesh": str(folders["inside"] / "broken.stl")},
         "mesh_resource: expected"),
        ({"ns": "bad", "id": 7, "type": MESH, "mesh": "http://example.com/a.stl"},
         "nothing is downloaded"),
    ]
    device = index(client, "/test_marker").device_name
    for marker, words in cases:
        peer.send(marker=marker)
        status = client.wait_for(device, lambda m, n=marker["id"]: isinstance(
            m.body, String) and f"id {n}:" in json.loads(m.body.text)["error"],
            timeout=scaled(10))
        error = json.loads(status.body.text)["error"]
        assert words in error, error
    # The same topic still shows a good marker.
    peer.send(marker={"action": DELETEALL})
    peer.send(marker={"ns": "good", "id": 1, "type": CUBE, "scale": [0.1] * 3})
    wait_markers(client, "/test_marker", {("good", 1)})


def test_a_refused_marker_s_error_stays_for_later_indexes_and_clients(
        client: Connection, peer: Peer, folders: dict[str, Path],
        daemon: RunningDaemon) -> None:
    """Issue 25, item 7: a mesh marker refused by the folders, beside a good one: the
    topic's index names the refusal while it lasts, in the index of the same message (sent
    after the refusal, as the good marker was added), in later ones, and to a client that
    connects later; a fixed marker clears it."""
    outside = {"ns": "keep", "id": 2, "type": MESH,
               "mesh": str(folders["outside"] / "tetra.stl")}
    cube = {"ns": "keep", "id": 1, "type": CUBE, "scale": [0.1] * 3}
    peer.send(markers=[{"action": DELETEALL}, cube, outside])
    wait_markers(client, "/test_markers", {("keep", 1)})
    device = index(client, "/test_markers").device_name

    def error_of(message: Message) -> str:
        return str(json.loads(message.body.text)["error"])

    def names_it(message: Message) -> bool:
        return isinstance(message.body, String) and "id 2:" in error_of(message) and \
            "inside a --robot-dir or --package-path folder" in error_of(message)
    assert names_it(client.wait_for(device, lambda m: json.loads(m.metadata[KEY_MARKERS]) != [],
                                    timeout=scaled(10)))
    peer.send(markers=[cube, outside, dict(cube, id=3)])  # one more: a new index
    wait_markers(client, "/test_markers", {("keep", 1), ("keep", 3)})
    latest = client.wait_for(device, lambda m: len(json.loads(m.metadata[KEY_MARKERS])) == 2,
                             timeout=scaled(10))
    assert names_it(latest), latest.body.text
    late = daemon.connect()  # markers go to the clients that asked for them (issue 22)
    try:
        assert late.command("create_marker_subscriber", {
            "topic": "/test_markers", "type": "MarkerArray",
            "fixed_frame": "world"})["existed"] is True
        assert names_it(late.wait_for(device, timeout=scaled(10)))
    finally:
        late.close()
    peer.send(markers=[dict(outside, type=CUBE, mesh="", scale=[0.1] * 3)])
    wait_markers(client, "/test_markers", {("keep", 1), ("keep", 2), ("keep", 3)})
    fixed = client.wait_for(device, lambda m: len(json.loads(m.metadata[KEY_MARKERS])) == 3,
                            timeout=scaled(10))
    assert error_of(fixed) == "", fixed.body.text


def test_denied_frame_is_withheld(client: Connection, peer: Peer) -> None:
    peer.send(markers=[{"action": DELETEALL},
                       {"ns": "s", "id": 1, "type": CUBE, "frame": "secret_frame",
                        "scale": [0.1] * 3},
                       {"ns": "s", "id": 2, "type": CUBE, "frame": "base",
                        "scale": [0.1] * 3}])
    wait_markers(client, "/test_markers", {("s", 2)})
    listing = client.command("list_markers", {"topic": "/test_markers"})
    (withheld,) = listing["withheld"]
    assert withheld["id"] == 1 and "secret*" in withheld["reason"]
    assert not any("secret" in d for d in client.devices())
    with pytest.raises(CommandRefusedError) as refused:
        client.command("create_marker_subscriber", {"topic": "/other", "type": "Marker",
                                                    "fixed_frame": "secret_base"})
    assert refused.value.field == "fixed_frame"


def test_op_errors(client: Connection) -> None:
    with pytest.raises(CommandRefusedError) as error:
        client.command("create_marker_subscriber", {"topic": "/x", "type": "Image",
                                                    "fixed_frame": "world"})
    assert error.value.field == "type" and "MarkerArray" in str(error.value)
    with pytest.raises(CommandRefusedError) as error:
        client.command("remove_marker_subscriber", {"topic": "/never"})
    assert error.value.code.name == "NOT_FOUND"
    again = client.command("create_marker_subscriber", {"topic": "/test_markers",
                                                        "type": "MarkerArray",
                                                        "fixed_frame": "world"})
    assert again["existed"] is True
    with pytest.raises(CommandRefusedError):
        client.command("create_marker_subscriber", {"topic": "/test_markers",
                                                    "type": "MarkerArray",
                                                    "fixed_frame": "base"})
    made = client.command("create_marker_subscriber", {"topic": "/removable",
                                                       "type": "Path", "fixed_frame": "world"})
    removed = client.command("remove_marker_subscriber", {"topic": "/removable"})
    assert removed["devices"] == [made["device"]]


def test_pythonic_client_follows_markers(daemon: RunningDaemon, peer: Peer) -> None:
    import slicer_client

    with slicer_client.connect("127.0.0.1", daemon.port, reconnect=False) as ros:
        events: list[str] = []
        markers = ros.markers("/test_markers", "MarkerArray", "world",
                              callback=lambda kind, *rest: events.append(kind))
        peer.send(markers=[{"action": DELETEALL},
                           {"ns": "py", "id": 1, "type": CUBE, "pos": [0.0, 0.0, 0.1],
                            "scale": [0.2, 0.2, 0.2], "locked": True},
                           {"ns": "py", "id": 2, "type": TEXT, "text": "label",
                            "pos": [0.0, 0.0, 0.5], "locked": True}])
        # Waits for the frames' poses too (issue 25, item 7): each marker can be placed.
        found = markers.wait_for_markers(
            lambda m: {(i.ns, i.id) for i in m.values()} == {("py", 1), ("py", 2)},
            timeout=scaled(10))
        assert all(i.frame_device in markers.frames for i in found.values())
        cube = markers.find("py", 1)
        assert cube is not None and cube.kind == "cube" and cube.frame == "base"
        fixed = markers.points_in_fixed_frame(cube)
        assert fixed is not None  # base is at (100, 200, 300) mm in world
        assert rounded(fixed) == box_corners(np.array([0.1, 0.2, 0.4]), np.eye(3),
                                             np.full(3, 0.2))
        text = markers.find("py", 2)
        assert text is not None and text.kind == "text_view_facing"
        np.testing.assert_allclose(markers.points_in_fixed_frame(text), [[100, 200, 800]])
        peer.send(markers=[{"ns": "py", "id": 1, "action": DELETE}])
        markers.wait_for_markers(lambda m: len(m) == 1, timeout=scaled(10))
        assert markers.find("py", 1) is None
        # Callbacks run on the client's callback thread, after the state changed.
        wait_until(lambda: "deleted" in events, 10, "the 'deleted' callback")
        assert len(found) == 2
        # The CamelCase facade wraps the same resource.
        node = ros.GetDefaultROS2Node().CreateAndAddMarkerSubscriberNode(
            "MarkerArray", "/test_markers", "world")
        assert node.GetNumberOfMarkers() == 1 and node.GetMarkerDeviceNames() == [
            markers.find("py", 2).device]
        assert ros.GetDefaultROS2Node().RemoveAndDeleteMarkerSubscriberNode("/test_markers")


def test_removing_frees_devices_and_a_shared_frame_with_its_last_user(client: Connection,
                                                                     peer: Peer) -> None:
    # The fixed frame's TRANSFORM also parents every placed marker: none may be left.
    client.command("remove_marker_subscriber", {"topic": "/test_path"})
    peer.send(marker={"action": DELETEALL})  # (/test_markers is gone by now, or unused)
    wait_markers(client, "/test_marker", set())
    peer.send(polygon={"frame": "world", "points": [[0, 0, 0], [1, 0, 0], [1, 1, 0]]},
              point={"frame": "world", "point": [0.0, 0.0, 0.0]})
    polygon = wait_markers(client, "/test_polygon", {("", 0)})[("", 0)]
    point = wait_markers(client, "/test_point", {("", 0)})[("", 0)]
    assert polygon["frame_device"] == point["frame_device"]  # one TRANSFORM per frame
    shared = polygon["frame_device"]
    removed = client.command("remove_marker_subscriber", {"topic": "/test_polygon"})
    assert set(removed["devices"]) == {polygon["device"], "mks:test_polygon"}
    devices = set(client.command("list_bridges")["devices"])
    assert polygon["device"] not in devices and "mks:test_polygon" not in devices
    assert shared in devices and point["device"] in devices  # the point still uses it
    client.command("remove_marker_subscriber", {"topic": "/test_point"})
    devices = set(client.command("list_bridges")["devices"])
    assert shared not in devices and point["device"] not in devices


def test_mesh_resource_by_package_uri_with_its_own_colours_or_the_markers(
        client: Connection, peer: Peer) -> None:
    uri = "package://marker_meshes/coloured.ply"
    peer.send(marker={"action": DELETEALL})
    peer.send(marker={"ns": "ply", "id": 1, "type": MESH, "mesh": uri, "embedded": True,
                      "color": [0.5, 0.5, 0.5, 1.0], "locked": True})
    peer.send(marker={"ns": "ply", "id": 2, "type": MESH, "mesh": uri, "embedded": False,
                      "color": [0.5, 0.5, 0.5, 1.0], "pos": [0.0, 0.0, 1.0], "locked": True})
    rows = wait_markers(client, "/test_marker", {("ply", 1), ("ply", 2)})
    own = model(client, rows[("ply", 1)]["device"])
    for point, colour in zip(points(own), rgba(own)):
        np.testing.assert_allclose(colour, PLY_COLOURS[tuple(np.round(point, 3))], atol=1e-6)
    assert own.metadata["ros2.point_colors"] == "1"
    plain = model(client, rows[("ply", 2)]["device"])
    assert rounded(points(plain)) == {(x, y, 1000.0) for x, y, _ in PLY_COLOURS}
    np.testing.assert_allclose(rgba(plain), np.full((3, 4), [0.5, 0.5, 0.5, 1.0]))
