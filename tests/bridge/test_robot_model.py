"""Loading robots from URDF: primitives, mesh formats, scale, colours, several visuals,
resource resolution, broken meshes, malformed URDFs and the mesh cache."""

from __future__ import annotations

import json
import logging
import struct
import time
from pathlib import Path

import numpy as np
import pytest

from bridge.robots import (DEFAULT_RGBA, LoadOptions, MeshCache, PackageResolver,
                           ResourceError, UrdfError, load_robot, load_robot_file, parse_urdf,
                           to_polydata)
from protocol.messages import AttributeKind, PolyData
from protocol.polydata import RGBA_ATTRIBUTE

# A tetrahedron: 4 corners, 4 triangles, extents 1 x 2 x 3 (file units).
TETRA = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]], dtype=np.float32)
TETRA_FACES = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def write_stl(path: Path, vertices: np.ndarray = TETRA, faces=TETRA_FACES) -> Path:
    """A binary STL written with struct: 80-byte header, count, 50-byte records."""
    records = [struct.pack("<3f", 0, 0, 0) + vertices[list(f)].astype("<f4").tobytes() + b"\0\0"
               for f in faces]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"\0" * 80 + struct.pack("<I", len(faces)) + b"".join(records))
    return path


def robot(*links: str, joints: str = "", materials: str = "", name: str = "r") -> str:
    return f'<robot name="{name}">{materials}{"".join(links)}{joints}</robot>'


def link(name: str, *visuals: str) -> str:
    return f'<link name="{name}">{"".join(visuals)}</link>'


def visual(geometry: str, *, origin: str = "", material: str = "", name: str = "") -> str:
    attr = f' name="{name}"' if name else ""
    return f"<visual{attr}>{origin}<geometry>{geometry}</geometry>{material}</visual>"


def fixed(name: str, parent: str, child: str, xyz: str = "0 0 0") -> str:
    return (f'<joint name="{name}" type="fixed"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz}"/></joint>')


def extent(v) -> np.ndarray:
    return np.ptp(np.asarray(v.vertices, dtype=np.float64), axis=0)


# ---------------------------------------------------------------------------- primitives


def test_primitives_have_their_sizes_in_millimetres() -> None:
    model = load_robot(robot(
        link("a", visual('<box size="0.1 0.2 0.3"/>')),
        link("b", visual('<cylinder radius="0.05" length="0.2"/>')),
        link("c", visual('<sphere radius="0.04"/>')),
        joints=fixed("ab", "a", "b") + fixed("bc", "b", "c")), cache=MeshCache())
    assert model.warnings == ()
    box, cylinder, sphere = (model.visuals_of(n)[0] for n in "abc")
    np.testing.assert_allclose(extent(box), (100, 200, 300), atol=1e-4)
    np.testing.assert_allclose(extent(cylinder), (100, 100, 200), atol=1e-3)
    np.testing.assert_allclose(np.linalg.norm(sphere.vertices, axis=1), 40.0, atol=1e-3)
    for v in (box, cylinder, sphere):
        assert v.rgba == DEFAULT_RGBA and v.colour_source == "default"
        np.testing.assert_allclose(v.vertices.mean(axis=0), 0.0, atol=1e-3)  # centred


def test_visual_origin_moves_and_turns_the_primitive() -> None:
    model = load_robot(robot(link("a", visual(
        '<box size="0.1 0.2 0.3"/>', origin='<origin xyz="1 2 3" rpy="0 0 1.5707963267948966"/>'
    ))), cache=MeshCache())
    v = model.visuals[0]
    # 90 degrees about z swaps the x and y extents; centre at (1, 2, 3) m = mm * 1000.
    np.testing.assert_allclose(extent(v), (200, 100, 300), atol=1e-3)
    np.testing.assert_allclose((v.vertices.min(0) + v.vertices.max(0)) / 2, (1000, 2000, 3000),
                               atol=1e-3)


def test_several_visuals_on_one_link_in_order() -> None:
    model = load_robot(robot(link("a",
                                  visual('<box size="0.1 0.1 0.1"/>', name="body"),
                                  visual('<sphere radius="0.01"/>',
                                         origin='<origin xyz="0 0 0.2"/>'))),
                       cache=MeshCache())
    first, second = model.visuals_of("a")
    assert (first.index, first.name) == (0, "body")
    assert (second.index, second.name) == (1, "a_visual1")
    np.testing.assert_allclose(second.vertices.mean(axis=0), (0, 0, 200), atol=1e-3)


# ---------------------------------------------------------------------------- mesh files


def test_stl_with_per_visual_scale(tmp_path: Path) -> None:
    mesh = write_stl(tmp_path / "tetra.stl")
    model = load_robot(robot(
        link("a", visual(f'<mesh filename="{mesh}"/>')),
        link("b", visual(f'<mesh filename="{mesh}" scale="0.5 0.5 0.5"/>')),
        link("c", visual(f'<mesh filename="{mesh}" scale="1 2 3"/>')),
        joints=fixed("ab", "a", "b") + fixed("bc", "b", "c")), cache=MeshCache())
    assert model.warnings == ()
    # The file is in metres: 1 x 2 x 3 m, times each visual's own scale, in mm.
    np.testing.assert_allclose(extent(model.visuals_of("a")[0]), (1000, 2000, 3000))
    np.testing.assert_allclose(extent(model.visuals_of("b")[0]), (500, 1000, 1500))
    np.testing.assert_allclose(extent(model.visuals_of("c")[0]), (1000, 4000, 9000))
    for v in model.visuals:
        assert v.triangles.shape == (4, 3) and v.vertices.shape == (4, 3)


def test_a_mirroring_scale_keeps_triangles_facing_outwards(tmp_path: Path) -> None:
    mesh = write_stl(tmp_path / "tetra.stl")
    model = load_robot(robot(
        link("a", visual(f'<mesh filename="{mesh}"/>')),
        link("b", visual(f'<mesh filename="{mesh}" scale="-1 1 1"/>')),
        joints=fixed("ab", "a", "b")), cache=MeshCache())

    def signed_volume(v) -> float:
        p = v.vertices.astype(np.float64)[v.triangles.astype(np.int64)]
        return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6)

    a, b = model.visuals_of("a")[0], model.visuals_of("b")[0]
    assert signed_volume(a) == pytest.approx(signed_volume(b))
    assert signed_volume(a) > 0


DAE_GREEN = """<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="millimeter" meter="0.001"/><up_axis>Z_UP</up_axis></asset>
  <library_effects><effect id="fx"><profile_COMMON><technique sid="t"><lambert>
    <diffuse><color>0.2 0.8 0.4 1</color></diffuse></lambert></technique></profile_COMMON>
  </effect></library_effects>
  <library_materials><material id="green"><instance_effect url="#fx"/></material>
  </library_materials>
  <library_geometries><geometry id="g"><mesh>
    <source id="pos"><float_array id="pos-a" count="12">0 0 0 10 0 0 0 20 0 0 0 30</float_array>
      <technique_common><accessor source="#pos-a" count="4" stride="3">
        <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
      </accessor></technique_common></source>
    <vertices id="v"><input semantic="POSITION" source="#pos"/></vertices>
    <triangles material="m" count="4"><input semantic="VERTEX" source="#v" offset="0"/>
      <p>0 2 1 0 1 3 0 3 2 1 2 3</p></triangles>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="s"><node id="n">
    <instance_geometry url="#g"><bind_material><technique_common>
      <instance_material symbol="m" target="#green"/></technique_common></bind_material>
    </instance_geometry></node></visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#s"/></scene>
</COLLADA>
"""


def test_dae_material_colour_and_unit(tmp_path: Path) -> None:
    mesh = tmp_path / "green.dae"
    mesh.write_text(DAE_GREEN)
    model = load_robot(robot(
        link("a", visual(f'<mesh filename="{mesh}"/>')),
        link("b", visual(f'<mesh filename="{mesh}"/>',
                         material='<material name="red"><color rgba="1 0 0 1"/></material>')),
        joints=fixed("ab", "a", "b")), cache=MeshCache())
    assert model.warnings == ()
    a, b = model.visuals_of("a")[0], model.visuals_of("b")[0]
    assert a.colour_source == "mesh"
    assert a.rgba == pytest.approx((0.2, 0.8, 0.4, 1.0), abs=1 / 255)
    assert b.colour_source == "urdf" and b.rgba == (1.0, 0.0, 0.0, 1.0)  # the URDF wins
    # <unit meter="0.001">: 10 x 20 x 30 file units are 10 x 20 x 30 mm.
    np.testing.assert_allclose(extent(a), (10, 20, 30), atol=1e-4)
    assert a.triangles.shape == (4, 3)


def test_obj_with_and_without_mtl_colour(tmp_path: Path) -> None:
    body = "v 0 0 0\nv 1 0 0\nv 0 2 0\nv 0 0 3\n"
    faces = "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
    (tmp_path / "plain.obj").write_text(body + faces)
    (tmp_path / "paint.mtl").write_text("newmtl paint\nKd 0.1 0.2 0.9\n")
    (tmp_path / "painted.obj").write_text("mtllib paint.mtl\n" + body + "usemtl paint\n" + faces)
    model = load_robot(robot(
        link("a", visual('<mesh filename="plain.obj"/>')),
        link("b", visual('<mesh filename="painted.obj" scale="0.001 0.001 0.001"/>')),
        joints=fixed("ab", "a", "b")), base_dir=tmp_path, cache=MeshCache())
    assert model.warnings == ()
    a, b = model.visuals_of("a")[0], model.visuals_of("b")[0]
    assert a.triangles.shape == b.triangles.shape == (4, 3)
    np.testing.assert_allclose(extent(a), (1000, 2000, 3000), atol=1e-3)
    np.testing.assert_allclose(extent(b), (1, 2, 3), atol=1e-6)
    assert a.rgba == DEFAULT_RGBA and a.colour_source == "default"
    assert b.colour_source == "mesh"
    assert b.rgba[:3] == pytest.approx((0.1, 0.2, 0.9), abs=1 / 255)


def test_named_materials_robot_level_and_inline() -> None:
    materials = '<material name="teal"><color rgba="0 0.5 0.5 1"/></material>'
    model = load_robot(robot(
        link("a", visual('<box size="1 1 1"/>', material='<material name="teal"/>')),
        link("b", visual('<box size="1 1 1"/>',
                         material='<material name="rose">'
                                  '<color rgba="1 0.2 0.5 0.5"/></material>')),
        link("c", visual('<box size="1 1 1"/>', material='<material name="rose"/>')),
        link("d", visual('<box size="1 1 1"/>', material='<material name="nowhere"/>')),
        joints=fixed("ab", "a", "b") + fixed("bc", "b", "c") + fixed("cd", "c", "d"),
        materials=materials), cache=MeshCache())
    colours = {v.link: v.rgba for v in model.visuals}
    assert colours == {"a": (0, 0.5, 0.5, 1), "b": (1, 0.2, 0.5, 0.5), "c": (1, 0.2, 0.5, 0.5),
                       "d": DEFAULT_RGBA}
    assert any("'nowhere'" in w and "link 'd'" in w for w in model.warnings)


# ---------------------------------------------------------------------------- broken meshes


def test_missing_mesh_is_a_warning_naming_file_and_link(tmp_path: Path, caplog) -> None:
    good = write_stl(tmp_path / "good.stl")
    caplog.set_level(logging.WARNING, logger="bridge.robots")
    model = load_robot(robot(
        link("base", visual(f'<mesh filename="{good}"/>')),
        link("arm", visual('<mesh filename="package://pkg/meshes/absent.stl"/>'),
             visual('<box size="0.1 0.1 0.1"/>')),
        joints=fixed("j", "base", "arm")),
        package_paths={"pkg": tmp_path}, cache=MeshCache())
    (warning,) = model.warnings
    assert "link 'arm'" in warning and "package://pkg/meshes/absent.stl" in warning
    assert str(tmp_path / "meshes" / "absent.stl") in warning
    assert [(v.link, v.index) for v in model.visuals] == [("base", 0), ("arm", 1)]
    assert any("absent.stl" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("filename, content", [
    ("notes.stl", b"these are notes, not triangles\n" * 3),
    ("truncated.stl", b"\0" * 80 + struct.pack("<I", 1000) + b"\1" * 120),
    ("notes.txt", b"solid nothing\n"),
    ("empty.obj", b"# no vertices\n"),
    ("broken.dae", b"<COLLADA><library_geometries><geometry"),
])
def test_a_file_that_is_not_a_mesh_is_a_warning(tmp_path: Path, filename: str,
                                                content: bytes) -> None:
    (tmp_path / filename).write_bytes(content)
    model = load_robot(robot(
        link("a", visual('<box size="0.1 0.1 0.1"/>')),
        link("b", visual(f'<mesh filename="{filename}"/>')),
        joints=fixed("j", "a", "b")), base_dir=tmp_path, cache=MeshCache())
    (warning,) = model.warnings
    assert "link 'b'" in warning and filename in warning
    assert [v.link for v in model.visuals] == ["a"]


# ---------------------------------------------------------------------------- malformed URDF

GOOD_JOINT = ('<joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
              '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>')


@pytest.mark.parametrize("text, names", [
    ("<robot name='r'><link name='a'></robot>", "well-formed XML"),
    ("", "well-formed XML"),
    ("<model name='r'><link name='a'/></model>", "<model>"),
    ("<robot><link name='a'/></robot>", "<robot>"),
    ("<robot name='r'></robot>", "at least one <link>"),
    ("<robot name='r'><link/></robot>", "<link>"),
    ("<robot name='r'><link name='a'/><link name='a'/></robot>", "link 'a'"),
    ("<robot name='r'><link name='a'/><link name='b'/></robot>", "exactly one root"),
    ("<robot name='r'><link name='a'/><link name='b'/>" + GOOD_JOINT.replace("revolute", "hinge")
     + "</robot>", "joint 'j' type"),
    ("<robot name='r'><link name='a'/><link name='b'/>" + GOOD_JOINT.replace('"b"', '"c"')
     + "</robot>", "joint 'j' <child>"),
    ("<robot name='r'><link name='a'/><link name='b'/><joint name='j' type='fixed'>"
     "<parent link='a'/></joint></robot>", "joint 'j'"),
    ("<robot name='r'><link name='a'/><link name='b'/>" + GOOD_JOINT.split("<limit")[0]
     + "</joint></robot>", "joint 'j' <limit>"),
    ("<robot name='r'><link name='a'/><link name='b'/>"
     + GOOD_JOINT.replace("<axis", "<origin xyz='1 2'/><axis") + "</robot>",
     "joint 'j' <origin> xyz"),
    ("<robot name='r'><link name='a'/><link name='b'/>"
     + GOOD_JOINT.replace("<axis", "<origin xyz='1 two 3'/><axis") + "</robot>",
     "joint 'j' <origin> xyz"),
    ("<robot name='r'><link name='a'/><link name='b'/>"
     + GOOD_JOINT.replace('xyz="0 0 1"', 'xyz="0 0 0"') + "</robot>", "joint 'j' <axis>"),
    ("<robot name='r'><link name='a'><visual><geometry/></visual></link></robot>", "link 'a'"),
    ("<robot name='r'><link name='a'><visual><geometry><box size='1 1'/></geometry></visual>"
     "</link></robot>", "link 'a' visual 0 <box>"),
    ("<robot name='r'><link name='a'><visual><geometry><box size='1 1 1'/></geometry>"
     "<material name='m'><color rgba='1 0 0'/></material></visual></link></robot>",
     "link 'a' visual 0 <material>"),
    # a loop: a -> b -> c -> b leaves no single root-reachable tree
    ("<robot name='r'><link name='a'/><link name='b'/><link name='c'/>"
     "<joint name='j1' type='fixed'><parent link='a'/><child link='b'/></joint>"
     "<joint name='j2' type='fixed'><parent link='b'/><child link='c'/></joint>"
     "<joint name='j3' type='fixed'><parent link='c'/><child link='b'/></joint></robot>",
     "link 'b'"),
])
def test_malformed_urdf_is_a_typed_error_naming_the_problem(text: str, names: str) -> None:
    with pytest.raises(UrdfError) as info:
        load_robot(text, cache=MeshCache())
    assert names in str(info.value)
    assert info.value.expected and info.value.field


def test_a_mimic_of_a_missing_joint_is_skipped_as_robot_state_publisher_does() -> None:
    # As in example-robot-data's hands: the robot loads, the joint moves on its own.
    text = ("<robot name='r'><link name='a'/><link name='b'/>"
            + GOOD_JOINT.replace("</joint>", "<mimic joint='ghost' multiplier='2'/></joint>")
            + "</robot>")
    model = load_robot(text, cache=MeshCache())
    assert [w for w in model.warnings if "ghost" in w] == [
        "joint 'j' mimics 'ghost', which is not a joint of this robot: the mimic is ignored "
        "and 'j' moves by its own joint state"]
    spec = parse_urdf(text)
    assert spec.joints["j"].mimic is None
    assert "j" in spec.actuated_joints
    pose = model.link_poses({"j": 0.5})["b"]
    assert pose[:3, :3] == pytest.approx(
        np.array([[np.cos(0.5), -np.sin(0.5), 0], [np.sin(0.5), np.cos(0.5), 0], [0, 0, 1]]))


def test_mimic_loop_is_refused() -> None:
    def j(name: str, child: str, mimic: str) -> str:
        return (f'<joint name="{name}" type="continuous"><parent link="a"/><child link="{child}"/>'
                f'<mimic joint="{mimic}"/></joint>')
    text = robot(link("a"), link("b"), link("c"), joints=j("j1", "b", "j2") + j("j2", "c", "j1"))
    with pytest.raises(UrdfError, match="mimic"):
        parse_urdf(text)


def test_unreadable_urdf_file_is_a_typed_error(tmp_path: Path) -> None:
    with pytest.raises(UrdfError, match="readable URDF file"):
        load_robot_file(tmp_path / "absent.urdf")


def test_ten_thousand_links_load_in_linear_time() -> None:
    def chain(n: int) -> str:
        links = "".join(f'<link name="l{i}"><visual><origin xyz="0 0 0.05"/><geometry>'
                        f'<box size="0.01 0.01 0.1"/></geometry></visual></link>'
                        for i in range(n))
        joints = "".join(
            f'<joint name="j{i}" type="revolute"><parent link="l{i - 1}"/><child link="l{i}"/>'
            f'<origin xyz="0 0 0.1"/><axis xyz="0 1 0"/>'
            f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
            for i in range(1, n))
        return f'<robot name="chain">{links}{joints}</robot>'

    def best_time(text: str) -> float:
        times = []
        for _ in range(2):
            start = time.perf_counter()
            model = load_robot(text, cache=MeshCache())
            model.link_poses({})
            times.append(time.perf_counter() - start)
        return min(times)

    small, big = chain(1000), chain(10_000)
    t_small, t_big = best_time(small), best_time(big)
    model = load_robot(big, cache=MeshCache())
    assert len(model.visuals) == 10_000 and model.warnings == ()
    # A straight chain: the last link sits 9,999 x 0.1 m up.
    assert model.link_poses({})["l9999"][2, 3] == pytest.approx(999.9)
    # 10x the links: linear is ~10x, quadratic would be ~100x.
    assert t_big < 30 * t_small, (t_small, t_big)


# ---------------------------------------------------------------------------- resources


def test_package_uri_via_package_paths(tmp_path: Path) -> None:
    write_stl(tmp_path / "anything" / "meshes" / "m.stl")
    text = robot(link("a", visual('<mesh filename="package://my_pkg/meshes/m.stl"/>')))
    model = load_robot(text, package_paths={"my_pkg": tmp_path / "anything"}, cache=MeshCache())
    assert model.warnings == () and len(model.visuals) == 1
    assert str(tmp_path / "anything" / "meshes" / "m.stl") in model.visuals[0].source


def test_package_uri_via_ros_package_path(tmp_path: Path, monkeypatch) -> None:
    write_stl(tmp_path / "ws" / "src" / "my_pkg" / "meshes" / "m.stl")
    # An entry that is the package itself, found by its package.xml name.
    write_stl(tmp_path / "elsewhere" / "folder" / "meshes" / "n.stl")
    (tmp_path / "elsewhere" / "folder" / "package.xml").write_text(
        "<package><name>other_pkg</name></package>")
    monkeypatch.setenv("ROS_PACKAGE_PATH", f"{tmp_path / 'nothing'}:{tmp_path / 'ws' / 'src'}:"
                                           f"{tmp_path / 'elsewhere' / 'folder'}")
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    text = robot(link("a", visual('<mesh filename="package://my_pkg/meshes/m.stl"/>')),
                 link("b", visual('<mesh filename="package://other_pkg/meshes/n.stl"/>')),
                 joints=fixed("j", "a", "b"))
    model = load_robot(text, cache=MeshCache())
    assert model.warnings == () and len(model.visuals) == 2


def test_package_uri_via_ament_index_and_precedence(tmp_path: Path, monkeypatch) -> None:
    write_stl(tmp_path / "install" / "share" / "my_pkg" / "meshes" / "m.stl")
    write_stl(tmp_path / "explicit" / "meshes" / "m.stl", TETRA * 2)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "install"))
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    text = robot(link("a", visual('<mesh filename="package://my_pkg/meshes/m.stl"/>')))
    from_ament = load_robot(text, cache=MeshCache())
    assert from_ament.warnings == ()
    np.testing.assert_allclose(extent(from_ament.visuals[0]), (1000, 2000, 3000))
    explicit = load_robot(text, package_paths={"my_pkg": tmp_path / "explicit"},
                          cache=MeshCache())
    np.testing.assert_allclose(extent(explicit.visuals[0]), (2000, 4000, 6000))


def test_file_uri_and_relative_path(tmp_path: Path) -> None:
    write_stl(tmp_path / "robot" / "meshes" / "with space.stl")
    urdf = tmp_path / "robot" / "urdf" / "r.urdf"
    urdf.parent.mkdir(parents=True)
    urdf.write_text(robot(
        link("a", visual(f'<mesh filename="file://{tmp_path}/robot/meshes/with%20space.stl"/>')),
        link("b", visual('<mesh filename="../meshes/with space.stl"/>')),
        joints=fixed("j", "a", "b")))
    model = load_robot_file(urdf, cache=MeshCache())
    assert model.warnings == () and len(model.visuals) == 2


def test_resolver_refuses_remote_and_names_the_package() -> None:
    resolver = PackageResolver({}, ros_package_path=(), ament_prefix_path=())
    with pytest.raises(ResourceError, match="nothing is downloaded"):
        resolver.resolve("https://example.com/m.stl")
    with pytest.raises(ResourceError, match="--package-path ghost=DIR"):
        resolver.resolve("package://ghost/m.stl")


# ---------------------------------------------------------------------------- cache, logging


def test_cache_reuses_meshes_and_rereads_an_edited_file(tmp_path: Path) -> None:
    mesh = write_stl(tmp_path / "m.stl")
    text = robot(link("a", visual(f'<mesh filename="{mesh}"/>')),
                 link("b", visual(f'<mesh filename="{mesh}" scale="2 2 2"/>')),
                 joints=fixed("j", "a", "b"))
    cache = MeshCache()
    first = load_robot(text, cache=cache)
    assert (cache.hits, cache.misses) == (0, 2)  # one entry per (file, scale)
    second = load_robot(text, cache=cache)
    assert (cache.hits, cache.misses) == (2, 2)
    assert second.visuals[0].triangles is first.visuals[0].triangles  # shared, read-only
    assert not first.visuals[0].vertices.flags.writeable
    write_stl(mesh, TETRA * 3)
    import os
    os.utime(mesh, ns=(time.time_ns(), time.time_ns() + 10_000_000))
    third = load_robot(text, cache=cache)
    np.testing.assert_allclose(extent(third.visuals[0]), (3000, 6000, 9000))


def test_a_cache_folder_gives_another_process_the_meshes_as_read(tmp_path: Path) -> None:
    """A mesh kept in a cache's folder comes back equal, colours, counts and description
    included, without the file being parsed; a damaged entry and an edited file are read
    again from the file."""
    import os

    from bridge.robots.demo import demo_urdf_path

    urdf, packages = demo_urdf_path(tmp_path / "demo")  # STL, OBJ, COLLADA, colours
    folder = tmp_path / "kept"
    first_cache = MeshCache(folder=folder)
    first = load_robot_file(urdf, package_paths=packages, cache=first_cache)
    files = sorted(folder.iterdir())
    assert first_cache.folder_hits == 0 and len(files) == 4  # one per mesh file
    later = MeshCache(folder=folder)  # as a daemon started again would have
    second = load_robot_file(urdf, package_paths=packages, cache=later)
    assert later.folder_hits == 4
    for a, b in zip(first.visuals, second.visuals, strict=True):
        np.testing.assert_array_equal(a.vertices, b.vertices)
        np.testing.assert_array_equal(a.triangles, b.triangles)
        assert (a.rgba, a.source, a.colour_source) == (b.rgba, b.source, b.colour_source)
        assert (a.vertex_rgba is None) == (b.vertex_rgba is None)
        if a.vertex_rgba is not None:
            np.testing.assert_array_equal(a.vertex_rgba, b.vertex_rgba)
        assert not b.vertices.flags.writeable
    files[0].write_bytes(files[0].read_bytes()[:-5])  # damaged: read from the file
    third = MeshCache(folder=folder)
    load_robot_file(urdf, package_paths=packages, cache=third)
    assert third.folder_hits == 3
    # An entry whose triangles name a vertex it does not have is read from the file too.
    head, body = files[1].read_bytes().split(b"\n", 1)
    counts = json.loads(head)
    at = counts["vertices"] * 24  # the first triangle's first index, after the vertices
    bad = body[:at] + np.uint32(counts["vertices"]).tobytes() + body[at + 4:]
    files[1].write_bytes(head + b"\n" + bad)
    fourth = MeshCache(folder=folder)
    again = load_robot_file(urdf, package_paths=packages, cache=fourth)
    assert fourth.folder_hits == 3
    assert all(int(v.triangles.max()) < len(v.vertices) for v in again.visuals)

    mesh = write_stl(tmp_path / "m.stl")
    text = robot(link("a", visual(f'<mesh filename="{mesh}"/>')))
    load_robot(text, cache=MeshCache(folder=folder))
    write_stl(mesh, TETRA * 3)
    os.utime(mesh, ns=(time.time_ns(), time.time_ns() + 10_000_000))
    edited = MeshCache(folder=folder)
    np.testing.assert_allclose(extent(load_robot(text, cache=edited).visuals[0]),
                               (3000, 6000, 9000))
    assert edited.folder_hits == 0


def test_a_cache_folder_keeps_the_most_recently_used_meshes(tmp_path: Path,
                                                            monkeypatch) -> None:
    import os

    from bridge.robots import meshes

    monkeypatch.setattr(meshes, "MESH_FOLDER_ENTRIES", 2)
    monkeypatch.setattr(meshes, "_PRUNE_EVERY", 1)
    folder = tmp_path / "kept"
    files = [write_stl(tmp_path / f"m{i}.stl", TETRA * (i + 1)) for i in range(3)]
    for number, path in enumerate(files):
        MeshCache(folder=folder).mesh_file(path)
        when = time.time() - 100 + number * 10  # used in this order, 10 s apart
        os.utime(max(folder.iterdir(), key=lambda p: p.stat().st_mtime_ns), (when, when))
    assert len(list(folder.iterdir())) == 2
    last = MeshCache(folder=folder)
    last.mesh_file(files[2])
    last.mesh_file(files[1])
    last.mesh_file(files[0])  # the oldest went: read from its file
    assert last.folder_hits == 2


def test_progress_is_logged_when_loading_is_slow(tmp_path: Path, caplog) -> None:
    caplog.set_level(logging.INFO, logger="bridge.robots")
    load_robot(robot(link("a", visual('<box size="1 1 1"/>'))),
               options=LoadOptions(progress_after_s=0.0), cache=MeshCache())
    assert any("visual 1/1" in r.getMessage() for r in caplog.records)


def test_polydata_has_points_triangles_colours_and_normals() -> None:
    model = load_robot(robot(link("a", visual(
        '<sphere radius="0.01"/>',
        material='<material name="m"><color rgba="1 0.5 0 1"/></material>'
    ))), options=LoadOptions(normals=True), cache=MeshCache())
    v = model.visuals[0]
    body = PolyData.unpack(to_polydata(v).pack())
    # Colours as the point SCALAR "RGBA" (4 components) and normals as NORMAL: the kinds
    # OpenIGTLink 3.1's reader sizes right (it read a TYPE RGBA as 9 floats a row).
    named = {a.name: a for a in body.attributes}
    assert {(name, a.kind, a.on_cells) for name, a in named.items()} == {
        (RGBA_ATTRIBUTE, AttributeKind.SCALAR, False), ("Normals", AttributeKind.NORMAL, False)}
    np.testing.assert_allclose(named[RGBA_ATTRIBUTE].data[0], (1, 0.5, 0, 1))
    # Sphere normals point away from the centre.
    radial = v.vertices / np.linalg.norm(v.vertices, axis=1, keepdims=True)
    assert float(np.min(np.einsum("ij,ij->i", radial, named["Normals"].data))) > 0.95


def test_obj_with_two_materials_gives_per_vertex_colours(tmp_path: Path) -> None:
    (tmp_path / "two.mtl").write_text("newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\n")
    (tmp_path / "two.obj").write_text(
        "mtllib two.mtl\nv 0 0 0\nv 1 0 0\nv 0 2 0\nv 0 0 3\n"
        "usemtl red\nf 1 3 2\nf 1 2 4\nusemtl blue\nf 1 4 3\nf 2 3 4\n")
    model = load_robot(robot(link("a", visual('<mesh filename="two.obj"/>'))),
                       base_dir=tmp_path, cache=MeshCache())
    v = model.visuals[0]
    assert v.colour_source == "mesh" and v.vertex_rgba is not None
    assert v.triangles.shape == (4, 3)
    # Each triangle has its material's colour at all three corners (any triangle order).
    red_corners = [{(0, 0, 0), (0, 2000, 0), (1000, 0, 0)}, {(0, 0, 0), (1000, 0, 0), (0, 0, 3000)}]
    for tri in v.triangles.astype(np.int64):
        corners = {tuple(int(round(c)) for c in v.vertices[i]) for i in tri}
        expected = [1, 0, 0, 1] if corners in red_corners else [0, 0, 1, 1]
        np.testing.assert_array_equal(v.vertex_rgba[tri], np.tile(expected, (3, 1)))
    (rgba,) = PolyData.unpack(to_polydata(v).pack()).attributes
    np.testing.assert_array_equal(rgba.data, v.vertex_rgba)


def test_a_collada_scene_that_drops_its_triangles_says_why(tmp_path: Path) -> None:
    from bridge.robots.demo import DEMO_PACKAGE, demo_urdf_path
    from bridge.robots.meshes import MeshError, load_mesh_file

    _, packages = demo_urdf_path(tmp_path / "demo")
    good = packages[DEMO_PACKAGE] / "meshes" / "forearm.dae"
    triangles = len(load_mesh_file(good).triangles)
    text = good.read_text()
    assert 'target="#forearm_material"' in text
    broken = tmp_path / "broken.dae"
    broken.write_text(text.replace('target="#forearm_material"', 'target="#missing"'))
    with pytest.raises(MeshError) as info:
        load_mesh_file(broken)
    message = str(info.value)
    # Not "no triangles in the file": the triangles are there, the binding is what broke.
    assert "no triangles in the file" not in message
    assert f"got {triangles} triangles in <library_geometries> that the scene drops" in message
    assert "Material #missing not found" in message
