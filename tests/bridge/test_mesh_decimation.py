"""Mesh decimation (`bridge.robots.meshes.decimate`): a mesh over its triangle budget is
reduced by vertex clustering, keeping its shape and colours; alone, through a mesh file's
loading (`max_triangles`), through the cache and through a robot's `LoadOptions`.

Expected values come from the input geometry itself (a sphere of known radius, a colour per
hemisphere), never from the function under test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from bridge.robots import LoadOptions, MeshCache, load_robot_file
from bridge.robots.errors import MeshError
from bridge.robots.meshes import box_mesh, decimate, load_mesh_file, sphere_mesh

RADIUS = 0.1  # metres
RED = (255, 0, 0, 255)
BLUE = (0, 0, 255, 255)


@pytest.fixture(scope="module")
def fine_sphere() -> tuple[np.ndarray, np.ndarray]:
    """An icosphere of 20,480 triangles (10,242 vertices), radius 0.1 m."""
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=RADIUS)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.uint32)


def check_valid(vertices: np.ndarray, triangles: np.ndarray) -> None:
    """Indices in range, every vertex used, no degenerate or repeated triangle."""
    assert triangles.dtype == np.uint32 and triangles.ndim == 2 and triangles.shape[1] == 3
    assert int(triangles.max()) == len(vertices) - 1
    assert len(np.unique(triangles)) == len(vertices)
    t = triangles.astype(np.int64)
    assert np.all((t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2]))
    rotated = np.array([np.roll(row, -int(np.argmin(row))) for row in t])
    assert len(np.unique(rotated, axis=0)) == len(t)


@pytest.mark.parametrize("budget", [50, 1000, 5000])
def test_a_fine_sphere_is_reduced_within_budget_and_stays_a_sphere(
        fine_sphere: tuple[np.ndarray, np.ndarray], budget: int) -> None:
    vertices, triangles = fine_sphere
    new_vertices, new_triangles, colours = decimate(vertices, triangles, budget)
    assert colours is None
    # Within the budget, and not needlessly coarse (the finest grid that fits is kept).
    assert budget // 4 < len(new_triangles) <= budget
    check_valid(new_vertices, new_triangles)
    # Cluster centres are means of points on the sphere: inside it, near its surface.
    radii = np.linalg.norm(new_vertices, axis=1)
    assert np.all(radii <= RADIUS + 1e-12)
    assert np.all(radii > (0.7 if budget < 100 else 0.9) * RADIUS)
    extent = np.ptp(new_vertices, axis=0)
    assert np.all(extent <= 2 * RADIUS + 1e-12) and np.all(extent > 1.4 * RADIUS)
    # Deterministic: the same input gives the same arrays.
    again = decimate(vertices, triangles, budget)
    np.testing.assert_array_equal(again[0], new_vertices)
    np.testing.assert_array_equal(again[1], new_triangles)


def test_colours_are_averaged_per_cluster(fine_sphere: tuple[np.ndarray, np.ndarray]) -> None:
    vertices, triangles = fine_sphere
    # Red above z = 0.02 m, blue below -0.02 m, a red/blue mix between.
    colours = np.where((vertices[:, 2] > 0)[:, None], RED, BLUE).astype(np.uint8)
    new_vertices, new_triangles, new_colours = decimate(vertices, triangles, 2000, colours)
    assert new_colours is not None and new_colours.dtype == np.uint8
    assert new_colours.shape == (len(new_vertices), 4)
    # Clusters are small (the grid is fine): well inside a hemisphere, a cluster holds
    # only points of that hemisphere and keeps its colour exactly.
    high = new_vertices[:, 2] > 0.02
    low = new_vertices[:, 2] < -0.02
    assert high.sum() > 100 and low.sum() > 100
    assert np.all(new_colours[high] == RED) and np.all(new_colours[low] == BLUE)
    # Alpha is 255 everywhere; red + blue of any cluster sum to 255 (rounded means).
    assert np.all(new_colours[:, 3] == 255) and np.all(new_colours[:, 1] == 0)
    assert np.all(np.abs(new_colours[:, 0].astype(int) + new_colours[:, 2] - 255) <= 1)


def test_a_mesh_within_budget_is_returned_as_it_is() -> None:
    sphere = sphere_mesh(RADIUS)
    colours = np.full((len(sphere.vertices), 4), 7, dtype=np.uint8)
    out = decimate(sphere.vertices, sphere.triangles, sphere.triangle_count, colours)
    assert out[0] is sphere.vertices and out[1] is sphere.triangles and out[2] is colours


def test_a_budget_below_a_tetrahedron_is_refused() -> None:
    sphere = sphere_mesh(RADIUS)
    with pytest.raises(MeshError) as error:
        decimate(sphere.vertices, sphere.triangles, 3)
    assert str(error.value) == "max_triangles: expected at least 4, got 3"


def test_a_budget_no_grid_can_meet_is_refused_not_exceeded_or_emptied() -> None:
    """The coarsest clustering of a box keeps its 12 triangles, and a sphere's coarsest
    non-empty one 18: a smaller budget must neither give more triangles than asked nor a
    mesh with no triangle left (the visual would vanish without a word)."""
    box = box_mesh((0.2, 0.2, 0.2))
    with pytest.raises(MeshError) as error:
        decimate(box.vertices, box.triangles, 4)
    assert str(error.value) == ("max_triangles: expected at least 12 for this mesh of 12 "
                                "triangles, got 4")
    sphere = sphere_mesh(RADIUS)  # 1280 triangles
    with pytest.raises(MeshError) as error:
        decimate(sphere.vertices, sphere.triangles, 10)
    assert str(error.value) == ("max_triangles: expected at least 18 for this mesh of 1280 "
                                "triangles, got 10")
    vertices, triangles, _ = decimate(sphere.vertices, sphere.triangles, 18)
    assert len(triangles) == 18
    check_valid(vertices, triangles)


@pytest.fixture(scope="module")
def sphere_stl(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("meshes") / "ball.stl"
    trimesh.creation.icosphere(subdivisions=5, radius=RADIUS).export(str(path))
    return path


def test_a_mesh_file_over_budget_is_decimated_as_it_loads(sphere_stl: Path) -> None:
    full = load_mesh_file(sphere_stl)
    assert full.triangle_count == full.original_triangles == 20480
    assert full.description == "stl ball.stl, 20480 triangles"
    small = load_mesh_file(sphere_stl, (2.0, 2.0, 2.0), max_triangles=800)
    assert small.original_triangles == 20480 and 200 < small.triangle_count <= 800
    assert small.description == f"stl ball.stl, 20480 triangles decimated to " \
                                f"{small.triangle_count}"
    assert not small.vertices.flags.writeable and not small.triangles.flags.writeable
    check_valid(small.vertices, small.triangles)
    # The scale applies to the decimated mesh: a sphere of radius 0.2 m now.
    radii = np.linalg.norm(small.vertices, axis=1)
    assert np.all(radii <= 2 * RADIUS * (1 + 1e-6)) and np.all(radii > 0.9 * 2 * RADIUS)
    # A budget the file meets already changes nothing.
    same = load_mesh_file(sphere_stl, max_triangles=20480)
    assert same.description == full.description
    np.testing.assert_array_equal(same.triangles, full.triangles)


def test_the_cache_keeps_one_mesh_per_budget(sphere_stl: Path) -> None:
    cache = MeshCache()
    a = cache.mesh_file(sphere_stl, max_triangles=500)
    b = cache.mesh_file(sphere_stl, max_triangles=500)
    c = cache.mesh_file(sphere_stl, max_triangles=2000)
    assert a is b and c is not a
    assert (cache.hits, cache.misses, len(cache)) == (1, 2, 2)
    assert a.triangle_count <= 500 < c.triangle_count <= 2000


def test_a_robot_loaded_with_a_budget_gets_decimated_visuals(sphere_stl: Path,
                                                            tmp_path: Path) -> None:
    urdf = tmp_path / "ball.urdf"
    urdf.write_text(f"""<robot name="ball">
  <link name="base"><visual><origin xyz="0 0 0.5"/>
    <geometry><mesh filename="{sphere_stl}"/></geometry></visual></link>
</robot>""")
    model = load_robot_file(urdf, options=LoadOptions(max_triangles=300), cache=MeshCache())
    assert model.warnings == ()
    (visual,) = model.visuals
    assert 75 < len(visual.triangles) <= 300
    assert visual.source.endswith(f"decimated to {len(visual.triangles)})")
    # Millimetres, in the link frame: a 100 mm sphere 500 mm up.
    radii = np.linalg.norm(visual.vertices - np.array([0, 0, 500], dtype=np.float32), axis=1)
    assert np.all(radii <= 100.001) and np.all(radii > 70)
    # A budget the mesh cannot meet is a warning on the robot, which still loads.
    tiny = load_robot_file(urdf, options=LoadOptions(max_triangles=4), cache=MeshCache())
    assert tiny.visuals == ()
    (warning,) = tiny.warnings
    assert warning == (f"link 'base' visual 0: mesh '{sphere_stl}' (max_triangles) cannot be "
                       f"used: expected at least 18 for this mesh of 20480 triangles, got 4; "
                       f"the visual is left out")
