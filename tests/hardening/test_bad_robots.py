"""Hostile robot descriptions, loaded with `bridge.robots.load_robot` (what create_robot
runs): only `UrdfError` may escape, a bad mesh is a warning, a huge robot loads in bounded
time. (The robot op is being wired into the daemon separately; these check the loader.)"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from bridge.robots import model as robots
from bridge.robots.errors import UrdfError
from support import scaled


def chain(links: int, visual: str = "") -> str:
    parts = ["<robot name='big'>"]
    for i in range(links):
        parts.append(f"<link name='l{i}'>{visual}</link>")
        if i:
            parts.append(f"<joint name='j{i}' type='revolute'><parent link='l{i - 1}'/>"
                         f"<child link='l{i}'/><origin xyz='0 0 0.01'/><axis xyz='0 0 1'/>"
                         f"<limit lower='-1' upper='1' effort='1' velocity='1'/></joint>")
    parts.append("</robot>")
    return "".join(parts)


@pytest.mark.parametrize("urdf", [
    "", "not xml at all", "<robot", "<robot name='r'></robot>",
    "<robot name='r'><link name='a'/><link name='a'/></robot>",
    "<robot name='r'><link name='a'/><link name='b'/><joint name='j' type='fixed'>"
    "<parent link='a'/><child link='zz'/></joint></robot>",
    "<robot name='r'><link name='a'/><link name='b'/>"
    "<joint name='j1' type='fixed'><parent link='a'/><child link='b'/></joint>"
    "<joint name='j2' type='fixed'><parent link='b'/><child link='a'/></joint></robot>",
    "<robot name='r'><link name='a'><visual><geometry><box size='nan 1 1'/></geometry>"
    "</visual></link></robot>",
    "<robot name='r'><link name='a'><visual><origin xyz='1 2'/><geometry><sphere "
    "radius='-1'/></geometry></visual></link></robot>",
    "<?xml version='1.0'?><!DOCTYPE r [<!ENTITY a 'aaaaaaaaaa'><!ENTITY b '&a;&a;&a;&a;&a;"
    "&a;&a;&a;&a;&a;'><!ENTITY c '&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;'>]><robot name='&c;'/>",
    b"\xff\xfe<robot/>",
])
def test_malformed_urdf_is_a_urdf_error_or_a_model(urdf: str | bytes) -> None:
    start = time.monotonic()
    try:
        loaded = robots.load_robot(urdf)
    except UrdfError as error:
        assert error.field and error.expected  # names what was wrong
    else:
        assert loaded.description is not None
    assert time.monotonic() - start < scaled(5.0)  # no entity expansion blow-up


def test_ten_thousand_links_load_in_bounded_time() -> None:
    start = time.monotonic()
    loaded = robots.load_robot(chain(10_000, "<visual><geometry><box size='0.01 0.01 "
                                             "0.01'/></geometry></visual>"))
    took = time.monotonic() - start
    print(f"\n10,000-link URDF with a box each: {len(loaded.visuals)} visuals in {took:.1f} s")
    assert len(loaded.description.links) == 10_000
    assert took < scaled(60.0)


def test_a_mesh_that_is_not_a_mesh_is_a_warning(tmp_path: Path) -> None:
    (tmp_path / "fake.stl").write_bytes(b"solid \x00\xff garbage" * 100)
    (tmp_path / "fake.dae").write_text("<COLLADA><nonsense/>")
    (tmp_path / "empty.obj").write_text("")
    (tmp_path / "shell.stl").write_text("#!/bin/sh\nrm -rf /\n")
    visuals = "".join(f"<link name='{name}'><visual><geometry><mesh filename='"
                      f"{tmp_path / name}'/></geometry></visual></link>"
                      for name in ("fake.stl", "fake.dae", "empty.obj", "shell.stl"))
    joints = "".join(f"<joint name='j{i}' type='fixed'><parent link='base'/><child "
                     f"link='{name}'/></joint>"
                     for i, name in enumerate(("fake.stl", "fake.dae", "empty.obj",
                                               "shell.stl")))
    loaded = robots.load_robot(f"<robot name='r'><link name='base'><visual><geometry><box "
                               f"size='1 1 1'/></geometry></visual></link>{visuals}{joints}"
                               f"</robot>")
    assert len(loaded.visuals) >= 1  # the box still loads
    assert len(loaded.warnings) == 4, loaded.warnings
