"""Mesh files parsed in reader processes (issue 44, `bridge.robots.mesh_readers`): a robot
read through them is the robot read in this process, array for array and warning for
warning; a reader that dies takes out only the file that killed it (a warning, as for any
unreadable file) and the next robot still loads; the readers end with `close`, and with
the daemon."""

from __future__ import annotations

import os
import signal
import struct
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest
import trimesh

from bridge.robots import MeshCache, load_robot
from bridge.robots.mesh_readers import MeshReaders
from bridge.robots.model import RobotModel, to_polydata
from mesh_reader_faults import die_on_crash_files
from protocol.messages import PolyData
from support import (Processes, alive, assert_clean_exit, children_of, scaled, start_daemon,
                     wait_until)


def capsule(seed: int) -> trimesh.Trimesh:
    """A bumped capsule of a few thousand triangles, its own shape per seed."""
    rng = np.random.default_rng(seed)
    mesh = trimesh.creation.capsule(height=0.1, radius=0.03, count=[24, 24])
    mesh.vertices = mesh.vertices * (1 + 0.3 * rng.random(3)) \
        + 0.002 * rng.standard_normal(mesh.vertices.shape)
    return mesh


def write_meshes(folder: Path) -> list[str]:
    """One file per format a robot package usually holds: binary STL, COLLADA with colours
    (in centimetres), OBJ; and an STL used by two links."""
    names = []
    for seed, kind in enumerate(("stl", "dae", "obj")):
        mesh = capsule(seed)
        if kind == "dae":
            mesh.visual.face_colors = [200, 40, 40, 255]
        data = mesh.export(file_type=kind)
        path = folder / f"part_{seed}.{kind}"
        path.write_bytes(data.encode() if isinstance(data, str) else data)
        names.append(path.name)
    return names + [names[0]]


def urdf(files: list[str]) -> str:
    links = "".join(f'<link name="l{i}"><visual><origin xyz="0 0 {i * 0.1}" rpy="0 0.3 0"/>'
                    f'<geometry><mesh filename="{name}" scale="1 2 1"/></geometry></visual>'
                    f'</link>' for i, name in enumerate(files))
    joints = "".join(f'<joint name="j{i}" type="fixed"><parent link="l{i - 1}"/>'
                     f'<child link="l{i}"/></joint>' for i in range(1, len(files)))
    return f'<robot name="r">{links}{joints}</robot>'


BAD_FILES = {
    "notes.stl": b"these are notes, not triangles\n" * 3,
    "truncated.stl": b"\0" * 80 + struct.pack("<I", 1000) + b"\1" * 120,
    "empty.obj": b"# no vertices\n",
    "broken.dae": b"<COLLADA><library_geometries><geometry",
}


@pytest.fixture(scope="module")
def forkserver() -> Iterator[None]:
    """The process-wide forkserver (and multiprocessing's resource tracker) the readers of
    this process fork from: started before the tests that check their children, ended after
    the last (a daemon's end with it)."""
    import multiprocessing.forkserver
    import multiprocessing.resource_tracker

    pool = MeshReaders(1)
    pool.start()
    pool.close()
    yield
    multiprocessing.forkserver._forkserver._stop()  # type: ignore[attr-defined]
    multiprocessing.resource_tracker._resource_tracker._stop()  # type: ignore[attr-defined]


@pytest.fixture
def readers(forkserver: None) -> Iterator[MeshReaders]:
    """Readers up: every file is read in them (before, in the asking thread)."""
    pool = MeshReaders(2)
    pool.start()
    assert pool.ready
    yield pool
    pool.close()


def polydata(model: RobotModel) -> list[tuple[str, bytes]]:
    return [(v.link, to_polydata(v).pack()) for v in model.visuals]


def test_a_robot_read_by_the_readers_is_the_robot_read_here(tmp_path: Path,
                                                            readers: MeshReaders) -> None:
    files = write_meshes(tmp_path)
    here = load_robot(urdf(files), base_dir=tmp_path, cache=MeshCache())
    cache = MeshCache()
    there = load_robot(urdf(files), base_dir=tmp_path, cache=cache, readers=readers)
    assert [v.source for v in there.visuals] == [v.source for v in here.visuals]
    assert [v.source.split("(")[-1].split(",")[0] for v in there.visuals] == \
        ["stl part_0.stl", "dae part_1.dae", "obj part_2.obj", "stl part_0.stl"]
    for a, b in zip(here.visuals, there.visuals):
        assert np.array_equal(a.vertices, b.vertices) and a.vertices.dtype == b.vertices.dtype
        assert np.array_equal(a.triangles, b.triangles)
        assert (a.rgba, a.colour_source) == (b.rgba, b.colour_source)
    assert polydata(there) == polydata(here)
    assert len(PolyData.unpack(polydata(there)[1][1]).points) == len(there.visuals[1].vertices)
    # The STL two links use was read once.
    assert (cache.misses, cache.hits) == (3, 1)
    assert len(readers.pids()) == 2


def test_bad_meshes_give_the_warnings_they_give_here(tmp_path: Path,
                                                    readers: MeshReaders) -> None:
    for name, content in BAD_FILES.items():
        (tmp_path / name).write_bytes(content)
    files = [*BAD_FILES, "absent.stl", *write_meshes(tmp_path)[:1]]
    here = load_robot(urdf(files), base_dir=tmp_path, cache=MeshCache())
    there = load_robot(urdf(files), base_dir=tmp_path, cache=MeshCache(), readers=readers)
    assert len(here.warnings) == len(BAD_FILES) + 1
    assert there.warnings == here.warnings  # in URDF order, word for word
    assert [v.link for v in there.visuals] == [v.link for v in here.visuals] == ["l5"]


def test_files_are_read_here_until_the_readers_are_up(tmp_path: Path, forkserver: None) -> None:
    """The first file starts the readers and is read in the asking thread, as is every
    file until they are up; then they read."""
    files = write_meshes(tmp_path)
    readers = MeshReaders(2)
    try:
        assert (readers.ready, readers.pids()) == (False, [])
        here = readers.read(tmp_path / files[1])
        wait_until(lambda: readers.ready, what="the readers up")
        assert len(readers.pids()) == 2
        there = readers.read(tmp_path / files[1])
        assert np.array_equal(here.vertices, there.vertices)
        assert np.array_equal(here.triangles, there.triangles)
        assert (here.rgba, here.description) == (there.rgba, there.description)
        # Read-only as a mesh read here is: one cached copy serves every robot.
        assert not any(array.flags.writeable for array in (
            here.vertices, here.triangles, there.vertices, there.triangles))
    finally:
        readers.close()


def test_a_reader_that_dies_leaves_out_only_its_file(tmp_path: Path, forkserver: None) -> None:
    files = write_meshes(tmp_path)
    (tmp_path / "crash.stl").write_bytes((tmp_path / files[0]).read_bytes())
    readers = MeshReaders(2, read_file=die_on_crash_files)
    readers.start()  # (a file read before would be read here, in this process)
    try:
        model = load_robot(urdf(["crash.stl", *files[:3]]), base_dir=tmp_path,
                           cache=MeshCache(), readers=readers)
        (warning,) = model.warnings
        assert "link 'l0'" in warning and "crash.stl" in warning
        assert "expected a mesh file its reader process survives, got the reader process " \
            "died reading it" in warning
        assert [v.link for v in model.visuals] == ["l1", "l2", "l3"]
        # The pool was replaced: the next robot's meshes are read as before.
        again = load_robot(urdf(files), base_dir=tmp_path, cache=MeshCache(), readers=readers)
        assert (again.warnings, len(again.visuals)) == ((), 4)
        pids = readers.pids()
        assert pids
    finally:
        readers.close()
    assert readers.pids() == []
    wait_until(lambda: not any(alive(pid) for pid in pids), what="the readers ended")
    with pytest.raises(Exception) as closed:
        readers.read(tmp_path / files[0])
    assert "the mesh readers are stopped" in str(closed.value)


def test_the_daemons_readers_read_its_robots_and_end_with_it(processes: Processes,
                                                             tmp_path: Path) -> None:
    files = write_meshes(tmp_path)
    (tmp_path / "robot.urdf").write_text(urdf(files))
    daemon = start_daemon(processes, "--robot-dir", str(tmp_path))
    assert children_of(daemon.child.pid) == []  # no readers before a robot
    with daemon.connect() as client:
        created = client.command("create_robot", {"name": "r", "source": {
            "kind": "file", "path": str(tmp_path / "robot.urdf")}}, timeout=60)
        assert created["robot"] == "r"
        (robot,) = client.command("list_robots")["robots"]
        assert (robot["state"], robot["visuals"], robot["warnings"]) == ("loaded", 4, 0)
    # The forkserver and its two readers (and multiprocessing's resource tracker), started
    # by the first file read.
    wait_until(lambda: len(children_of(daemon.child.pid)) >= 3, what="the daemon's readers")
    readers = {pid for pid, _, _ in children_of(daemon.child.pid)}
    # Ctrl-C in a terminal reaches the whole process group: the readers too.
    os.killpg(daemon.child.pid, signal.SIGINT)
    daemon.child.popen.wait(scaled(30))
    wait_until(lambda: not any(alive(pid) for pid in readers), what="the readers ended")
    assert_clean_exit(daemon)  # exit code 0, and no reader's KeyboardInterrupt traceback
