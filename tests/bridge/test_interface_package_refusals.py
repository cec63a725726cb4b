"""`build-interfaces` input it refuses before anything is built: package.xml files that are
not a package, no CMakeLists.txt, two packages of a name, nothing to build, ignored
folders, REP 149 conditions that do not parse, and a machine without the build tools, cmake,
the generators or a working target Python. Real files in a temporary folder, real PATH
lookups and processes; no build runs."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from bridge.interfaces import InterfacePackage, PackageError, find_packages
from bridge.interfaces.build import Target, check_build_tools, plan_build
from bridge.interfaces.errors import ToolMissingError
from bridge.interfaces.packages import evaluate_condition

PACKAGE_XML = """<?xml version="1.0"?>
<package format="3">
  <name>{name}</name>
  <version>0.1.0</version>
  <description>test package</description>
  <maintainer email="tests@example.org">tests</maintainer>
  <license>MIT</license>
</package>
"""
CMAKELISTS = "project({name})\nrosidl_generate_interfaces(${{PROJECT_NAME}} \"msg/A.msg\")\n"


def _package(folder: Path, name: str, *, cmake: bool = True) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "package.xml").write_text(PACKAGE_XML.format(name=name))
    if cmake:
        (folder / "CMakeLists.txt").write_text(CMAKELISTS.format(name=name))
    return folder


def _refused(paths: list[Path]) -> str:
    with pytest.raises(PackageError) as raised:
        find_packages(paths)
    return str(raised.value)


def test_a_package_xml_that_is_not_xml_is_named(tmp_path: Path) -> None:
    folder = tmp_path / "broken_msgs"
    folder.mkdir()
    (folder / "package.xml").write_text("<package><name>broken_msgs</name>")
    says = _refused([folder])
    assert says.startswith(f"{folder / 'package.xml'}: expected a readable package.xml, got ")


@pytest.mark.parametrize("xml, got", [
    ("<manifest><name>a_msgs</name></manifest>", "got <manifest> named 'a_msgs'"),
    ("<package><name>Bad-Name</name></package>", "got <package> named 'Bad-Name'"),
])
def test_a_package_xml_without_a_proper_name_is_named(tmp_path: Path, xml: str,
                                                      got: str) -> None:
    folder = tmp_path / "pkg"
    folder.mkdir()
    (folder / "package.xml").write_text(xml)
    says = _refused([folder])
    assert "expected <package> with a <name> of lowercase letters, digits and _" in says
    assert says.endswith(got)


def test_a_package_without_cmakelists_is_no_interface_package(tmp_path: Path) -> None:
    folder = _package(tmp_path / "doc_only", "doc_only", cmake=False)
    says = _refused([folder])
    assert says == (f"{folder}: expected an interface package (a CMakeLists.txt that calls "
                    f"rosidl_generate_interfaces), got none in {folder / 'CMakeLists.txt'}")


def test_two_packages_of_one_name_are_refused(tmp_path: Path) -> None:
    first = _package(tmp_path / "ws" / "a" / "twin_msgs", "twin_msgs")
    second = _package(tmp_path / "ws" / "b" / "twin_msgs", "twin_msgs")
    says = _refused([tmp_path / "ws"])
    assert says == (f"expected one folder per package name, got two named twin_msgs: "
                    f"{first.resolve()} and {second.resolve()}")


def test_ignored_folders_are_not_searched_and_nothing_found_is_refused(tmp_path: Path) -> None:
    ws = tmp_path / "ws"
    _package(ws / "old" / "old_msgs", "old_msgs")
    (ws / "old" / "COLCON_IGNORE").write_text("")
    kept = _package(ws / "new" / "new_msgs", "new_msgs")
    assert [(p.name, p.path) for p in find_packages([ws])] == [("new_msgs", kept.resolve())]
    (ws / "new" / "AMENT_IGNORE").write_text("")
    says = _refused([ws])
    assert says == (f"expected interface packages (folders with a package.xml) under {ws}, "
                    f"found none")


@pytest.mark.parametrize("condition", [
    "$ROS_VERSION == 2; rm -rf",  # a character no condition has
    "$ROS_VERSION == 2 2",  # something after a whole condition
    "($ROS_VERSION == 2 x",  # a parenthesis never closed
    "$ROS_VERSION is 2",  # not a comparison
    "== == 2",  # an operator where a value goes
])
def test_conditions_that_do_not_parse_are_refused(condition: str) -> None:
    with pytest.raises(PackageError) as raised:
        evaluate_condition(condition, where="a_msgs/package.xml")
    says = str(raised.value)
    assert says.startswith("a_msgs/package.xml: expected a condition like '$ROS_VERSION == 2', "
                           f"got {condition!r}")


# ------------------------------------------------------------------ the build machine

def _target(tmp_path: Path, python: Path | None = None) -> Target:
    prefix = tmp_path / "env"
    (prefix / "bin").mkdir(parents=True, exist_ok=True)
    return Target(python or Path(sys.executable), prefix, prefix)


def _tools_dir(tmp_path: Path, *tools: str) -> Path:
    """A PATH folder with only these of the real tools."""
    import shutil

    folder = tmp_path / "tools"
    folder.mkdir(exist_ok=True)
    for tool in tools:
        real = shutil.which(tool)
        if real is None:
            pytest.skip(f"{tool} is not installed here")
        (folder / tool).symlink_to(real)
    return folder


def test_no_compilers_on_path_are_named(tmp_path: Path,
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PATH", str(_tools_dir(tmp_path, "make")))
    with pytest.raises(ToolMissingError) as raised:
        check_build_tools(_target(tmp_path))
    assert str(raised.value).startswith("expected the build tools cc, c++ and make on PATH, "
                                        "got none for cc, c++ (on Debian: apt-get install "
                                        "build-essential)")


def test_no_cmake_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PATH", str(_tools_dir(tmp_path, "cc", "c++", "make")))
    target = _target(tmp_path)
    with pytest.raises(ToolMissingError) as raised:
        check_build_tools(target)
    assert str(raised.value) == (f"expected cmake >= 3.20 on PATH or in {target.env_prefix}"
                                 f"/bin, got none: pip install cmake")


def test_an_environment_without_the_generators_is_named(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PATH", str(_tools_dir(tmp_path, "cc", "c++", "make", "cmake")))
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    target = _target(tmp_path)
    with pytest.raises(ToolMissingError) as raised:
        check_build_tools(target)
    assert str(raised.value).startswith(f"expected the ROS interface generators in "
                                        f"{target.env_prefix}, got none: pip install "
                                        f"'slicer-ros2-bridge[interfaces]'")


def test_a_target_python_that_does_not_run_is_named(tmp_path: Path) -> None:
    broken = tmp_path / "python"
    broken.write_text("#!/bin/sh\necho 'no such interpreter' >&2\nexit 3\n")
    broken.chmod(0o755)
    package = InterfacePackage("a_msgs", tmp_path, ("std_msgs",))
    with pytest.raises(ToolMissingError) as raised:
        plan_build([package], _target(tmp_path, broken), force=False)
    assert str(raised.value) == (f"expected {broken} to run, got exit code 3: "
                                 f"no such interpreter")
