"""Robots a user describes wrongly, through the real daemon: malformed URDF files (each
refused at create_robot, naming what is wrong), URDFs that load with warnings (textures,
odd mimics, meshes that cannot be used: a zero-sized box, NaN vertices, a corrupt file),
mesh files whose colours come from faces or a texture, and joints asked of robots that do
not exist or have not loaded.

Mesh files are written here (OBJ, PLY, STL, GLB); expected colours are the bytes written.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

from protocol.commands import ErrorCode
from protocol.messages import AttributeKind, Message, PolyData
from protocol.polydata import RGBA_ATTRIBUTE
from slicer_client.connection import CommandRefusedError, Connection
from support import Processes, RunningDaemon, assert_clean_exit, start_daemon

pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def robot_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("robots")


@pytest.fixture(scope="module")
def daemon(module_processes: Processes, robot_dir: Path) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--robot-dir", str(robot_dir))
    yield running
    assert_clean_exit(running)


def robot(body: str, name: str = "r") -> str:
    return f'<?xml version="1.0"?>\n<robot name="{name}">{body}</robot>\n'


def refusal(client: Connection, path: Path, name: str = "bad") -> CommandRefusedError:
    with pytest.raises(CommandRefusedError) as refused:
        client.command("create_robot", {"name": name,
                                        "source": {"kind": "file", "path": str(path)}})
    return refused.value


BOX = '<visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual>'
TWO = '<link name="a"/><link name="b"/>'

MALFORMED = {
    "bad-encoding": ('<?xml version="1.0" encoding="bogus"?><robot name="x"><link name="a"/>'
                     '</robot>', "URDF: expected well-formed XML, got Unsupported encoding"),
    "not-a-robot": ('<model name="x"><link name="a"/></model>',
                    "URDF root element: expected <robot>, got <model>"),
    "no-links": (robot(""), "robot 'r': expected at least one <link>, got none"),
    "rgba-out-of-range": (robot('<link name="a"><visual><geometry><box size="1 1 1"/>'
                                '</geometry><material name="m"><color rgba="2 0 0 1"/>'
                                '</material></visual></link>'),
                          "<color> rgba: expected 4 numbers in 0..1 (rgba), got [2.0, 0.0, "
                          "0.0, 1.0]"),
    "origin-words": (robot('<link name="a"><visual><origin xyz="a b c"/><geometry>'
                           '<box size="1 1 1"/></geometry></visual></link>'),
                     "link 'a' visual 0 <origin> xyz: expected 3 numbers, got a b c"),
    "mesh-without-file": (robot('<link name="a"><visual><geometry><mesh/></geometry>'
                                '</visual></link>'),
                          "link 'a' visual 0 <mesh>: expected a 'filename' attribute"),
    "box-without-size": (robot('<link name="a"><visual><geometry><box/></geometry></visual>'
                               '</link>'),
                         "link 'a' (line 2): expected a valid <link>, got missing attribute "
                         "'size'"),
    "scale-words": (robot('<link name="a"><visual><geometry><mesh filename="m.stl" '
                          'scale="a b c"/></geometry></visual></link>'),
                    "expected a valid <link>, got ValueError: could not convert string to "
                    "float: 'a'"),
    "joint-without-parent": (robot(TWO + '<joint name="j" type="fixed"><child link="b"/>'
                                   '</joint>'),
                             "joint 'j' (line 2): expected a valid <joint>, got a missing or "
                             "empty sub-element"),
    "joint-without-child-link": (robot(TWO + '<joint name="j" type="fixed"><parent link="a"/>'
                                       '<child/></joint>'),
                                 "joint 'j': expected <parent link=...> and <child link=...>, "
                                 "got parent 'a', child None"),
    "infinite-limit": (robot(TWO + '<joint name="j" type="revolute"><parent link="a"/>'
                             '<child link="b"/><axis xyz="0 0 1"/><limit lower="-inf" '
                             'upper="1" effort="1" velocity="1"/></joint>'),
                       "joint 'j' <limit>: expected finite lower and upper, got (-inf, 1.0)"),
    "mimic-without-joint": (robot(TWO + '<joint name="j" type="continuous"><parent link="a"/>'
                                  '<child link="b"/><mimic multiplier="2"/></joint>'),
                            "joint 'j' <mimic>: expected a 'joint' attribute, got none"),
    "bad-material": (robot('<material name="m"><color rgba="a b c d"/></material>'
                           '<link name="a"/>'),
                     "material 'm' (line 2): expected a valid <material>, got ValueError"),
    "duplicate-joint": (robot(TWO + '<link name="c"/><joint name="j" type="fixed">'
                              '<parent link="a"/><child link="b"/></joint><joint name="j" '
                              'type="fixed"><parent link="a"/><child link="c"/></joint>'),
                        "joint 'j' (line 2): expected a unique joint name, got a duplicate"),
    "links-in-a-loop": (robot('<link name="root"/><link name="a"/><link name="p"/>'
                              '<link name="q"/><joint name="ra" type="fixed">'
                              '<parent link="root"/><child link="a"/></joint>'
                              '<joint name="pq" type="fixed"><parent link="p"/>'
                              '<child link="q"/></joint><joint name="qp" type="fixed">'
                              '<parent link="q"/><child link="p"/></joint>'),
                        "robot 'r': expected a tree of links from the root 'root', got links "
                        "in a loop: ['p', 'q']"),
}


@pytest.mark.parametrize("case", list(MALFORMED))
def test_a_malformed_urdf_file_is_refused_naming_the_fault(
        client: Connection, robot_dir: Path, case: str) -> None:
    text, expected = MALFORMED[case]
    path = robot_dir / f"{case}.urdf"
    path.write_text(text)
    error = refusal(client, path)
    assert error.code == ErrorCode.OUT_OF_RANGE and error.field == "source.path"
    assert expected in str(error), str(error)
    assert "bad" not in [r["name"] for r in client.command("list_robots")["robots"]]
    assert not [d for d in client.command("list_bridges")["devices"] if "bad" in d]


# ------------------------------------------------------------------ meshes written here

def tetra_stl(path: Path) -> None:
    """A binary STL tetrahedron with corners at 0 and 1 cm on each axis."""
    corners = [(0, 0, 0), (0.01, 0, 0), (0, 0.01, 0), (0, 0, 0.01)]
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    data = bytearray(80) + struct.pack("<I", len(faces))
    for face in faces:
        data += struct.pack("<3f", 0, 0, 0)
        for index in face:
            data += struct.pack("<3f", *corners[index])
        data += b"\0\0"
    path.write_bytes(bytes(data))


def face_coloured_ply(path: Path, colours: tuple[str, str]) -> None:
    path.write_text("\n".join([
        "ply", "format ascii 1.0", "element vertex 4", "property float x", "property float y",
        "property float z", "element face 2", "property list uchar int vertex_indices",
        "property uchar red", "property uchar green", "property uchar blue",
        "property uchar alpha", "end_header", "0 0 0", "0.01 0 0", "0 0.01 0", "0.01 0.01 0",
        f"3 0 1 2 {colours[0]}", f"3 1 3 2 {colours[1]}"]) + "\n")


def textured_obj(folder: Path) -> None:
    """An OBJ whose material is a 2x2 PNG of one colour (10, 200, 30)."""
    from PIL import Image

    Image.new("RGB", (2, 2), (10, 200, 30)).save(folder / "green.png")
    (folder / "green.mtl").write_text("newmtl t\nKd 1 1 1\nmap_Kd green.png\n")
    (folder / "textured.obj").write_text(
        "mtllib green.mtl\nusemtl t\nv 0 0 0\nv 0.01 0 0\nv 0 0.01 0\nv 0 0 0.01\n"
        "vt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")


def rgba_of(body: PolyData) -> np.ndarray:
    (attribute,) = [a for a in body.attributes if a.name == RGBA_ATTRIBUTE]
    assert attribute.kind == AttributeKind.SCALAR  # as every reader sizes it (4 components)
    return np.asarray(attribute.data)


def is_mesh(message: Message) -> bool:
    return isinstance(message.body, PolyData)


def test_a_robot_that_loads_with_warnings_and_mesh_colours(client: Connection,
                                                            robot_dir: Path) -> None:
    folder = robot_dir / "troubled"
    (folder / "meshes").mkdir(parents=True)
    tetra_stl(folder / "meshes" / "tetra.stl")
    face_coloured_ply(folder / "meshes" / "mixed.ply", ("255 0 0 255", "0 0 255 255"))
    face_coloured_ply(folder / "meshes" / "same.ply", ("0 255 0 255", "0 255 0 255"))
    textured_obj(folder / "meshes")
    (folder / "meshes" / "nan.obj").write_text("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (folder / "meshes" / "corrupt.glb").write_bytes(b"glTF, but only the first word")

    def mesh_link(name: str, filename: str, extra: str = "") -> str:
        return (f'<link name="{name}"><visual><geometry><mesh filename="meshes/{filename}"'
                f'{extra}/></geometry></visual></link>'
                f'<joint name="{name}_j" type="fixed"><parent link="base"/>'
                f'<child link="{name}"/></joint>')

    urdf = folder / "troubled.urdf"
    urdf.write_text(robot(
        '<link name="base"><visual><geometry><box size="0 0.1 0.1"/></geometry></visual>'
        '<visual><geometry><sphere radius="0.01"/></geometry><material name="skin">'
        '<texture filename="skin.png"/></material></visual></link>'
        + mesh_link("doubled", "tetra.stl", ' scale="2"')
        + mesh_link("mixed", "mixed.ply") + mesh_link("same", "same.ply")
        + mesh_link("textured", "textured.obj") + mesh_link("nan", "nan.obj")
        + mesh_link("corrupt", "corrupt.glb")
        + '<link name="follower"/><joint name="follows" type="continuous"><parent link="base"/>'
          '<child link="follower"/><mimic joint="doubled_j"/></joint>', name="troubled"))
    result = client.command("create_robot", {"name": "troubled", "source": {
        "kind": "file", "path": str(urdf)}}, timeout=30)
    try:
        assert result["state"] == "loaded"
        warnings = result["warnings"]
        expected = [
            "link 'base' visual 1: material 'skin' has no colour defined anywhere",
            "link 'base' visual 1: material textures are not supported",
            "joint 'follows' mimics 'doubled_j', a fixed joint: its position is always the "
            "offset",
            "link 'base' visual 0: mesh 'box' (box size) cannot be used: expected a positive "
            "finite number (metres), got 0.0; the visual is left out",
            "link 'nan' visual 0: mesh 'meshes/nan.obj'",
            "link 'corrupt' visual 0: mesh 'meshes/corrupt.glb'",
        ]
        assert len(warnings) == len(expected), warnings
        for start, warning in zip(expected, warnings):
            assert warning.startswith(start), (start, warning)
        assert "expected finite vertex coordinates, got NaN or infinity" in warnings[4]
        assert "expected a readable GLB mesh" in warnings[5]
        visuals = {v["link"]: v for v in result["visuals"]}
        assert sorted(visuals) == ["base", "doubled", "mixed", "same", "textured"]
        meshes = {link: client.wait_for(v["device"], is_mesh, timeout=30).body
                  for link, v in visuals.items()}
        # scale="2" on every axis: the 1 cm tetrahedron is 2 cm (20 mm) along each.
        np.testing.assert_allclose(np.ptp(meshes["doubled"].points, axis=0), (20, 20, 20),
                                   atol=1e-4)
        # One face colour for all: the mesh's colour; two: per vertex, the shared corners
        # averaged (trimesh averages the faces around a vertex).
        np.testing.assert_allclose(rgba_of(meshes["same"]), np.tile((0, 1, 0, 1), (4, 1)))
        mixed = rgba_of(meshes["mixed"])
        by_point = {tuple(np.round(p, 3)): tuple(np.round(c, 3))
                    for p, c in zip(meshes["mixed"].points, mixed)}
        assert by_point[(0.0, 0.0, 0.0)] == (1.0, 0.0, 0.0, 1.0)
        assert by_point[(10.0, 10.0, 0.0)] == (0.0, 0.0, 1.0, 1.0)
        assert by_point[(10.0, 0.0, 0.0)] == pytest.approx((127 / 255, 0, 127 / 255, 1.0),
                                                           abs=2e-3)
        assert visuals["mixed"]["color"] == pytest.approx([0.5, 0, 0.5, 1], abs=0.01)
        # The texture is sampled per vertex: all (10, 200, 30).
        np.testing.assert_allclose(rgba_of(meshes["textured"]),
                                   np.tile((10 / 255, 200 / 255, 30 / 255, 1), (4, 1)),
                                   atol=1e-6)
        joints = client.command("describe_robot_joints", {"name": "troubled"})
        (follows,) = [j for j in joints["joints"] if j["name"] == "follows"]
        assert follows["mimic"] == {"joint": "doubled_j", "multiplier": 1.0, "offset": 0.0}
        assert follows["actuated"] is False and follows["type"] == "continuous"
    finally:
        client.command("remove_robot", {"name": "troubled"})


# ------------------------------------------------------------------ names and joints

def test_joints_of_a_robot_that_is_not_there_or_not_loaded(client: Connection) -> None:
    with pytest.raises(CommandRefusedError) as missing:
        client.command("describe_robot_joints", {"name": "nobody"})
    assert missing.value.code == ErrorCode.NOT_FOUND and missing.value.field == "name"
    waiting = client.command("create_robot", {
        "name": "unpublished", "source": {"kind": "topic", "topic": "/no_description_here"}},
        timeout=30)
    try:
        assert waiting["state"] == "waiting"
        assert waiting["reason"] == "topic /no_description_here: no description published yet"
        for op, extra in (("describe_robot_joints", {}),
                          ("set_robot_joints", {"positions": {"j": 0.0}})):
            with pytest.raises(CommandRefusedError) as not_loaded:
                client.command(op, {"name": "unpublished", **extra})
            assert not_loaded.value.code == ErrorCode.UNAVAILABLE, op
            assert "robot 'unpublished' (waiting: topic /no_description_here" in str(
                not_loaded.value)
    finally:
        client.command("remove_robot", {"name": "unpublished"})

