"""Collision geometry of robots and obstacle meshes (issue 46): where each link's geometry
comes from, the obstacle meshes refused with typed errors, and distances checked against
trimesh's closest point."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bridge.robots import load_robot, load_robot_file
from bridge.robots.demo import demo_urdf_path
from seven_dof_urdf import SEVEN_DOF_URDF

pytest.importorskip("pinocchio", reason="motion needs pin (pyproject's dependencies)")
trimesh = pytest.importorskip("trimesh")

from bridge.motion import collisions  # noqa: E402
from bridge.motion.collisions import CollisionWorld  # noqa: E402
from bridge.motion.errors import NoCollisionGeometry, ObstacleError  # noqa: E402
from bridge.motion.model import MotionModel  # noqa: E402

BOX = trimesh.creation.box((0.1, 0.1, 0.1))
PROBE = """<robot name="probe">
  <link name="base"/>
  <link name="tool"><collision><geometry><sphere radius="0.05"/></geometry></collision>
    <collision><geometry><mesh filename="missing/tool.stl"/></geometry></collision></link>
  <joint name="x" type="prismatic"><parent link="base"/><child link="tool"/>
    <axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


def test_links_use_their_collision_elements_else_their_visuals(tmp_path: Path) -> None:
    seven = CollisionWorld(MotionModel(load_robot(SEVEN_DOF_URDF)))
    assert seven.source_of("link1") == "collision" and seven.source_of("tcp") == "none"
    assert "tcp" not in seven.links and "hand" in seven.links
    urdf, packages = demo_urdf_path(tmp_path)
    demo = CollisionWorld(MotionModel(load_robot_file(urdf, package_paths=packages)))
    # The demo arm has visuals only: every link with a visual collides by its visuals.
    assert demo.source_of("base_link") == "visual" and "tool_flange" in demo.links


def test_an_unreadable_collision_mesh_is_a_warning_and_the_rest_is_used() -> None:
    world = CollisionWorld(MotionModel(load_robot(PROBE)))
    assert world.links == ("tool",)
    assert len(world.warnings) == 1
    assert "link 'tool' collision 1 left out" in world.warnings[0]
    assert "missing/tool.stl" in world.warnings[0]


@pytest.mark.parametrize("x", [0.3, 0.5, 0.8])
def test_the_distance_is_trimesh_s_closest_point_minus_the_radius(x: float) -> None:
    world = CollisionWorld(MotionModel(load_robot(PROBE)))
    pose = np.eye(4)
    pose[:3, :3] = trimesh.transformations.rotation_matrix(0.4, [0, 0, 1])[:3, :3]
    pose[:3, 3] = (1.0, 0.2, 0.0)
    world.set_obstacle("block", BOX.vertices, BOX.faces, pose)
    [distance] = world.distances(np.array([x]), "tool")
    placed = BOX.copy()
    placed.apply_transform(pose)
    _, gap, _ = trimesh.proximity.closest_point(placed, [[x, 0.0, 0.0]])
    assert distance.distance_m * 1000.0 == pytest.approx((gap[0] - 0.05) * 1000.0, abs=1e-3)
    # The nearest points: on the sphere's surface, and on the box.
    assert np.linalg.norm(distance.on_link - (x, 0.0, 0.0)) == pytest.approx(0.05, abs=1e-9)
    assert world.contacts(np.array([x])) == []


def test_contact_names_the_link_and_the_obstacle() -> None:
    world = CollisionWorld(MotionModel(load_robot(PROBE)))
    world.set_obstacle("block", BOX.vertices, BOX.faces)
    [contact] = world.contacts(np.array([0.08]))  # the sphere reaches 0.03 into the box
    assert (contact.link, contact.obstacle) == ("tool", "block")
    assert world.distances(np.array([0.08]), "tool")[0].distance_m == 0.0
    hit = world.path_contact(np.linspace([1.0], [0.0], 101))
    assert hit is not None and hit[1] == contact
    # First contact where the sphere's surface (centre - 0.05) reaches the face at 0.05:
    # configuration 90, x = 1 - 0.9 (0.0999...: just in).
    assert hit[0] == 90 and math.isclose(1.0 - hit[0] / 100, 0.1)


@pytest.mark.parametrize("points, triangles, field, expected", [
    ([[0, 0, 0], [1, 0, 0], [float("nan"), 0, 0]], [[0, 1, 2]], "points", "finite numbers"),
    ([[0, 0, 0], [1, 0, 0], [1e36, 0, 0]], [[0, 1, 2]], "points", "within float32 in mm"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]], "triangles", "indices of points 0..2"),
    ([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]], "triangles", "triangles with an area"),
    ([[0, 0, 0], [1, 0, 0]], [[0, 1, 1]], "points", "at least 3 points"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.zeros((0, 3), dtype=int), "triangles",
     "at least one triangle"),
])
def test_bad_obstacle_meshes_are_typed_errors(points: list, triangles: list, field: str,
                                              expected: str) -> None:
    world = CollisionWorld(MotionModel(load_robot(PROBE)))
    with pytest.raises(ObstacleError) as caught:
        world.set_obstacle("bad", points, triangles)
    assert caught.value.field == f"obstacle 'bad'.{field}"
    assert expected in str(caught.value)
    assert world.obstacles == {}


def test_a_huge_obstacle_mesh_is_refused_before_it_is_built(monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    monkeypatch.setattr(collisions, "MAX_OBSTACLE_TRIANGLES", 11)
    world = CollisionWorld(MotionModel(load_robot(PROBE)))
    with pytest.raises(ObstacleError, match="at most 11 triangles"):
        world.set_obstacle("box", BOX.vertices, BOX.faces)  # 12 triangles


def test_a_robot_without_geometry_refuses_collision_queries() -> None:
    bare = CollisionWorld(MotionModel(load_robot(
        '<robot name="bare"><link name="a"/><link name="b"/><joint name="j" type="revolute">'
        '<parent link="a"/><child link="b"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')))
    with pytest.raises(NoCollisionGeometry, match="no link has any"):
        bare.require_geometry()
    with pytest.raises(NoCollisionGeometry) as caught:
        bare.distances(np.array([0.0]), "b")
    assert caught.value.field == "link"
