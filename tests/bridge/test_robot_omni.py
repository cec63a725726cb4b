"""The real Sensable Omni (../shared/robots/sensable_omni_model): meshes, units, colours, FK.

Expected values are computed here independently: the binary STL is parsed with struct and
numpy, and rpy/axis rotations are written out by hand.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest

from bridge.robots import LoadOptions, MeshCache, load_robot_file, to_polydata
from protocol.messages import AttributeKind, PolyData
from protocol.polydata import RGBA_ATTRIBUTE
from support import require_shared

OMNI_COLOURS = {
    "metal_seamed": (0.4627450980392157, 0.4666666666666667, 0.4509803921568628, 1.0),
    "blue": (0.0, 0.0, 0.8, 1.0),
}
# link -> (mesh file, visual origin xyz, rpy, material) as written in omni.urdf
OMNI_VISUALS = {
    "base": ("base.stl", (0, -0.02, 0), (0, 0, 0), "metal_seamed"),
    "torso": ("torso.stl", (0, 0, 0.036), (-1.5707, 0, 0), "blue"),
    "upper_arm": ("upper_arm.stl", (0.0075, 0, 0), (0, 0, 0), "metal_seamed"),
    "lower_arm": ("lower_arm.stl", (0, 0, 0), (1.5707, 0, 0), "metal_seamed"),
    "wrist": ("wrist.stl", (0, 0, 0), (3.14159, 0, 0), "metal_seamed"),
    "tip": ("tip.stl", (0, 0, 0), (-1.5707, 0, 0), "metal_seamed"),
    "stylus": ("stylus.stl", (0, -0.039, 0), (1.5707, 1.5707, 0), "blue"),
}


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rpy(r: float, p: float, y: float) -> np.ndarray:
    return rot_z(y) @ rot_y(p) @ rot_x(r)  # URDF: fixed axes x, then y, then z


def pose(rotation: np.ndarray, xyz: tuple[float, float, float]) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = xyz
    return m


def read_binary_stl(path: Path) -> tuple[int, np.ndarray]:
    """(triangle count from the header, (3 * count, 3) float32 corner positions)."""
    raw = path.read_bytes()
    (count,) = struct.unpack_from("<I", raw, 80)
    assert len(raw) == 84 + 50 * count, "not a binary STL"
    record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attr", "<u2")])
    triangles = np.frombuffer(raw, dtype=record, count=count, offset=84)
    return count, triangles["corners"].reshape(-1, 3)


@pytest.fixture(scope="module")
def omni_dir() -> Path:
    return require_shared("robots/sensable_omni_model")


@pytest.fixture(scope="module")
def omni(omni_dir: Path):
    return load_robot_file(omni_dir / "urdf" / "omni.urdf",
                           package_paths={"sensable_omni_model": omni_dir}, cache=MeshCache())


def test_every_link_has_its_mesh_with_the_file_counts(omni, omni_dir: Path) -> None:
    assert omni.warnings == ()
    assert omni.root_link == "base"
    assert sorted(v.link for v in omni.visuals) == sorted(OMNI_VISUALS)
    for visual in omni.visuals:
        count, corners = read_binary_stl(omni_dir / "meshes" / OMNI_VISUALS[visual.link][0])
        distinct = len(np.unique(corners, axis=0))
        assert visual.triangles.shape == (count, 3), visual.link
        assert visual.vertices.shape == (distinct, 3), visual.link
        assert visual.vertices.dtype == np.float32 and visual.triangles.dtype == np.uint32
        assert int(visual.triangles.max()) == distinct - 1


def test_vertices_are_millimetres_in_the_link_frame(omni, omni_dir: Path) -> None:
    for visual in omni.visuals:
        filename, xyz, angles, _ = OMNI_VISUALS[visual.link]
        _, corners = read_binary_stl(omni_dir / "meshes" / filename)
        # URDF scale is 1 for the Omni; metres -> mm is x1000.
        in_link = corners.astype(np.float64) @ rpy(*angles).T + np.asarray(xyz)
        expected_low, expected_high = in_link.min(axis=0) * 1000, in_link.max(axis=0) * 1000
        np.testing.assert_allclose(visual.vertices.min(axis=0), expected_low, atol=1e-3)
        np.testing.assert_allclose(visual.vertices.max(axis=0), expected_high, atol=1e-3)
    base = omni.visuals_of("base")[0]
    # The base is ~16.7 cm wide: 167 mm, not 0.167 (units) nor 167000.
    assert 160 < float(np.ptp(base.vertices[:, 0])) < 170


def test_colours_come_from_the_urdf_materials(omni) -> None:
    for visual in omni.visuals:
        material = OMNI_VISUALS[visual.link][3]
        assert visual.rgba == pytest.approx(OMNI_COLOURS[material])
        assert visual.colour_source == "urdf"


def test_forward_kinematics_with_the_waist_at_90_degrees(omni) -> None:
    poses = omni.link_poses({"waist": math.pi / 2})
    np.testing.assert_allclose(poses["base"], np.eye(4))
    np.testing.assert_allclose(poses["torso"], pose(rot_z(math.pi / 2), (0, 0, 0.09)),
                               atol=1e-12)
    # shoulder at 0: origin (-0.0075, 0, 0.035) turned by the waist: x -> y.
    np.testing.assert_allclose(poses["upper_arm"],
                               pose(rot_z(math.pi / 2), (0, -0.0075, 0.125)), atol=1e-12)


def test_forward_kinematics_of_the_whole_chain(omni) -> None:
    q = {"waist": 0.3, "shoulder": 0.5, "elbow": -0.2, "yaw": 4.5, "pitch": 0.7, "roll": 1.1}
    # Chain written out from omni.urdf: origin(xyz, rpy) @ rotation about the axis.
    chain = [
        ("torso", (0, 0, 0.09), (0, 0, 0), rot_z(q["waist"])),
        ("upper_arm", (-0.0075, 0, 0.035), (0, 0, 0), rot_x(q["shoulder"])),
        ("lower_arm", (0.0075, 0.134, 0), (-1.5, 0, 0), rot_x(q["elbow"])),
        ("wrist", (0, 0.08, 0), (0, 0, 0), rot_y(q["yaw"])),
        ("tip", (0, 0.0525, 0), (1.5707, 0, 0), rot_x(q["pitch"])),
        ("stylus", (0, -0.029, 0), (3.14159, 3.14159, 0), rot_y(q["roll"])),
    ]
    expected = np.eye(4)
    poses = omni.link_poses(q)
    for link, xyz, angles, motion in chain:
        expected = expected @ pose(rpy(*angles), xyz) @ pose(motion, (0, 0, 0))
        np.testing.assert_allclose(poses[link], expected, atol=1e-12, err_msg=link)


def test_polydata_of_a_link_packs_and_unpacks(omni) -> None:
    visual = omni.visuals_of("torso")[0]
    body = to_polydata(visual)
    again = PolyData.unpack(body.pack())
    np.testing.assert_array_equal(again.points, visual.vertices)
    assert len(again.polygons) == 4 * len(visual.triangles)
    np.testing.assert_array_equal(again.polygons.reshape(-1, 4)[:, 1:], visual.triangles)
    (rgba,) = [a for a in again.attributes if a.name == RGBA_ATTRIBUTE]
    assert (rgba.kind, rgba.data.shape[1]) == (AttributeKind.SCALAR, 4)
    np.testing.assert_allclose(rgba.data, np.tile(OMNI_COLOURS["blue"], (len(visual.vertices), 1)),
                               atol=1e-7)


def test_decimation_keeps_the_shape_within_budget(omni_dir: Path) -> None:
    model = load_robot_file(omni_dir / "urdf" / "omni.urdf",
                            package_paths={"sensable_omni_model": omni_dir},
                            options=LoadOptions(max_triangles=1000), cache=MeshCache())
    full = load_robot_file(omni_dir / "urdf" / "omni.urdf",
                           package_paths={"sensable_omni_model": omni_dir}, cache=MeshCache())
    for small, big in zip(model.visuals, full.visuals):
        assert 100 < len(small.triangles) <= 1000
        assert "decimated" in small.source
        # Clustering moves points inside the hull only: bounding boxes shrink a little.
        extent_small = np.ptp(small.vertices, axis=0)
        extent_big = np.ptp(big.vertices, axis=0)
        assert np.all(extent_small <= extent_big + 1e-3)
        assert np.all(extent_small > 0.7 * extent_big)
