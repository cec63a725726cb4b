"""A client may load a robot by file path only inside --robot-dir or --package-path folders:
otherwise any client could make the daemon read (and probe for) any file on its machine.
The operator's own start-up config is trusted."""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import pytest

from protocol.commands import ErrorCode
from slicer_client.connection import CommandRefusedError, Connection
from support import Processes, RunningDaemon, assert_clean_exit, start_daemon

ONE_LINK = "<robot name='{name}'><link name='base'/></robot>"
STL = ("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
       "endloop\nendfacet\nendsolid t\n")


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    allowed = tmp_path_factory.mktemp("robots")
    package = tmp_path_factory.mktemp("package")
    outside = tmp_path_factory.mktemp("elsewhere")
    (allowed / "inside.urdf").write_text(ONE_LINK.format(name="inside"))
    (package / "urdf").mkdir()
    (package / "urdf" / "arm.urdf").write_text(ONE_LINK.format(name="arm"))
    (outside / "secret.urdf").write_text(ONE_LINK.format(name="secret"))
    (allowed / "link.urdf").symlink_to(outside / "secret.urdf")
    return {"allowed": allowed, "package": package, "outside": outside}


@pytest.fixture(scope="module")
def daemon(module_processes: Processes, folders: dict[str, Path]) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--robot-dir", str(folders["allowed"]),
                           "--package-path", f"armpkg={folders['package']}")
    yield running
    assert_clean_exit(running)


def create(client: Connection, name: str, path: str) -> dict:
    return client.command("create_robot", {"name": name, "source": {"kind": "file",
                                                                    "path": path}}, timeout=30)


def test_files_inside_robot_dirs_and_package_paths_load(daemon: RunningDaemon,
                                                        folders: dict[str, Path]) -> None:
    with daemon.connect() as client:
        assert create(client, "inside", str(folders["allowed"] / "inside.urdf"))["robot"] \
            == "inside"
        assert create(client, "arm", "package://armpkg/urdf/arm.urdf")["robot"] == "arm"


@pytest.mark.parametrize("where", ["outside", "symlink", "dotdot"])
def test_other_files_are_forbidden_and_named(daemon: RunningDaemon, folders: dict[str, Path],
                                            where: str) -> None:
    path = {"outside": str(folders["outside"] / "secret.urdf"),
            "symlink": str(folders["allowed"] / "link.urdf"),
            "dotdot": str(folders["allowed"] / ".." / folders["outside"].name / "secret.urdf"),
            }[where]
    with daemon.connect() as client:
        with pytest.raises(CommandRefusedError) as refused:
            create(client, f"bad_{where}", path)
        assert refused.value.error.code == ErrorCode.FORBIDDEN
        assert refused.value.error.field == "source.path"
        assert "--robot-dir" in refused.value.error.message
        robots = client.command("list_robots")["robots"]
        assert f"bad_{where}" not in {robot["name"] for robot in robots}


def test_the_operators_start_up_config_is_trusted(processes: Processes,
                                                  folders: dict[str, Path],
                                                  tmp_path: Path) -> None:
    """The operator's URDF file may name meshes anywhere; a client's, even one inside the
    robot folders, reads meshes only inside them (SecurityPolicy.content_guard)."""
    mesh = folders["outside"] / "secret.stl"
    mesh.write_text(STL)
    with_mesh = ("<robot name='m'><link name='base'><visual><geometry><mesh filename='%s'/>"
                 "</geometry></visual></link></robot>" % mesh.as_uri())
    (folders["outside"] / "meshy.urdf").write_text(with_mesh)
    (folders["allowed"] / "meshy.urdf").write_text(with_mesh)
    config = tmp_path / "bridges.yaml"
    config.write_text("robots:\n  - {name: secret, source: {kind: file, path: '%s'}}\n"
                      "  - {name: meshy, source: {kind: file, path: '%s'}}\n"
                      % (folders["outside"] / "secret.urdf", folders["outside"] / "meshy.urdf"))
    daemon = start_daemon(processes, "--config", str(config),
                          "--robot-dir", str(folders["allowed"]))
    with daemon.connect() as client:
        create(client, "clients", str(folders["allowed"] / "meshy.urdf"))
        robots = {robot["name"]: robot for robot in client.command("list_robots")["robots"]}
        assert (robots["secret"]["state"], robots["meshy"]["state"]) == ("loaded", "loaded")
        assert robots["meshy"]["visuals"] == 1  # the operator's: read from outside
        assert (robots["clients"]["visuals"], robots["clients"]["warnings"]) == (0, 1)
    assert_clean_exit(daemon)
