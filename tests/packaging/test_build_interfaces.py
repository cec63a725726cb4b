"""`slicer-ros2-bridge build-interfaces PATH...`: a user's interface packages (made here in a
temporary folder) built into a throwaway prefix, never into the project's venv.

Most tests stop before anything is built (ordering, refused input); one builds two small
packages for real (one cmake build each) and uses them from another process.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from bridge.interfaces import (MissingDependencyError, PackageError, find_packages,
                               prefix_exports, with_exports)
from bridge.interfaces.errors import DependencyCycleError
from bridge.interfaces.packages import evaluate_condition, order_packages
from bridge.interfaces.steps import (REPORT_EVERY_S, Step, compile_progress, last_line,
                                     make_progress, pip_progress, run_step)
from support import REPO, wait_until

PACKAGE_XML = """<?xml version="1.0"?>
<package format="3">
  <name>{name}</name>
  <version>0.1.0</version>
  <description>test package</description>
  <maintainer email="tests@example.org">tests</maintainer>
  <license>MIT</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
{depends}
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""

CMAKELISTS = """cmake_minimum_required(VERSION 3.20)
project({name})
find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
{finds}
rosidl_generate_interfaces(${{PROJECT_NAME}} {files} {dependencies})
ament_package()
"""


def make_package(root: Path, name: str, files: dict[str, str],
                 depends: tuple[str, ...] = (), extra_xml: str = "") -> Path:
    """A package folder: package.xml, CMakeLists.txt and the given interface files."""
    folder = root / name
    for relative, text in files.items():
        (folder / relative).parent.mkdir(parents=True, exist_ok=True)
        (folder / relative).write_text(text)
    xml_depends = "\n".join(f"  <depend>{d}</depend>" for d in depends) + extra_xml
    (folder / "package.xml").write_text(PACKAGE_XML.format(name=name, depends=xml_depends))
    (folder / "CMakeLists.txt").write_text(CMAKELISTS.format(
        name=name, finds="\n".join(f"find_package({d} REQUIRED)" for d in depends),
        files=" ".join(f'"{f}"' for f in sorted(files)),
        dependencies=f"DEPENDENCIES {' '.join(depends)}" if depends else ""))
    return folder


def cli(*args: str, tmpdir: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, TMPDIR=str(tmpdir)) if tmpdir else None
    return subprocess.run([sys.executable, "-m", "bridge.cli", "build-interfaces", *args],
                          cwd=REPO, capture_output=True, text=True, timeout=1200, env=env)


# --- refused or planned before anything is built --------------------------------------

def installed(name: str) -> bool:
    """What these tests take as installed (the venv has these and more)."""
    return name in ("std_msgs", "rosidl_default_runtime")


def test_packages_are_ordered_dependencies_first(tmp_path: Path) -> None:
    make_package(tmp_path, "c_msgs", {"msg/C.msg": "int32 c\n"})
    make_package(tmp_path, "a_msgs", {"msg/A.msg": "b_msgs/B b\n"}, ("b_msgs",))
    make_package(tmp_path / "nested", "b_msgs", {"msg/B.msg": "c_msgs/C c\n"},
                 ("c_msgs", "std_msgs"))
    found = find_packages([tmp_path])
    assert sorted(p.name for p in found) == ["a_msgs", "b_msgs", "c_msgs"]
    ordered = order_packages(found, available=installed)
    assert [p.name for p in ordered] == ["c_msgs", "b_msgs", "a_msgs"]
    # The same given one by one, in any order.
    ordered = order_packages(find_packages([tmp_path / "a_msgs", tmp_path / "c_msgs",
                                            tmp_path / "nested" / "b_msgs"]),
                             available=installed)
    assert [p.name for p in ordered] == ["c_msgs", "b_msgs", "a_msgs"]


def test_a_missing_dependency_is_named_and_nothing_is_built(tmp_path: Path) -> None:
    make_package(tmp_path / "src", "probe_a_msgs", {"msg/A.msg": "int32 a\n"},
                 ("std_msgs", "no_such_msgs"))
    prefix, build = tmp_path / "prefix", tmp_path / "build"
    result = cli(str(tmp_path / "src"), "--prefix", str(prefix), "--build-dir", str(build))
    assert result.returncode == 2, result.stdout + result.stderr
    assert "probe_a_msgs depends on no_such_msgs" in result.stderr
    assert "std_msgs" not in result.stderr.split("got:")[1]  # the venv has it
    assert not prefix.exists() and not any(build.iterdir() if build.exists() else [])
    with pytest.raises(MissingDependencyError) as raised:
        order_packages(find_packages([tmp_path / "src"]), available=lambda name: False)
    assert raised.value.missing == [("probe_a_msgs", "std_msgs"),
                                    ("probe_a_msgs", "no_such_msgs"),
                                    ("probe_a_msgs", "rosidl_default_runtime")]


def test_a_dependency_cycle_is_named_and_nothing_is_built(tmp_path: Path) -> None:
    make_package(tmp_path, "probe_a_msgs", {"msg/A.msg": "int32 a\n"}, ("probe_b_msgs",))
    make_package(tmp_path, "probe_b_msgs", {"msg/B.msg": "int32 b\n"}, ("probe_c_msgs",))
    make_package(tmp_path, "probe_c_msgs", {"msg/C.msg": "int32 c\n"}, ("probe_a_msgs",))
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    result = cli(str(tmp_path), "--prefix", str(tmp_path / "prefix"), tmpdir=scratch)
    assert result.returncode == 2, result.stdout + result.stderr
    assert ("expected package dependencies without a cycle, got probe_a_msgs -> "
            "probe_b_msgs -> probe_c_msgs -> probe_a_msgs") in result.stderr
    assert not (tmp_path / "prefix").exists()
    assert list(scratch.iterdir()) == []  # no build folder left behind either
    with pytest.raises(DependencyCycleError) as raised:
        order_packages(find_packages([tmp_path]), available=lambda name: True)
    assert raised.value.cycle == ["probe_a_msgs", "probe_b_msgs", "probe_c_msgs",
                                  "probe_a_msgs"]


def test_conditions_of_package_xml_are_evaluated_for_ros_2(tmp_path: Path) -> None:
    # As crtk_msgs writes its ROS 1 / ROS 2 dependencies.
    conditional = ('\n  <depend condition="$ROS_VERSION == 1">message_generation</depend>'
                   '\n  <depend condition="$ROS_VERSION == 2">std_msgs</depend>')
    folder = make_package(tmp_path, "probe_msgs", {"msg/A.msg": "int32 a\n"},
                          extra_xml=conditional)
    (package,) = find_packages([folder])
    assert package.depends == ("std_msgs", "rosidl_default_runtime")
    assert evaluate_condition("$ROS_VERSION == 2 and ($ROS_DISTRO != humble or x == y)")
    assert not evaluate_condition("$ROS_VERSION == 1 or $UNSET_VARIABLE == set")
    with pytest.raises(PackageError, match="expected a condition like"):
        evaluate_condition("$ROS_VERSION ==", where="package.xml")


def test_bad_paths_and_non_interface_packages_are_refused(tmp_path: Path) -> None:
    result = cli(str(tmp_path / "absent"))
    assert result.returncode == 2
    assert "expected a package folder or a folder of packages, got" in result.stderr
    assert "(absent)" in result.stderr

    plain = tmp_path / "ws" / "plain_node"
    plain.mkdir(parents=True)
    (plain / "package.xml").write_text(PACKAGE_XML.format(name="plain_node", depends=""))
    (plain / "CMakeLists.txt").write_text("project(plain_node)\nadd_executable(x x.cpp)\n")
    result = cli(str(plain))
    assert result.returncode == 2
    assert "expected an interface package" in result.stderr

    # In a workspace it is skipped with a line; the interface package beside it is found.
    make_package(tmp_path / "ws", "std_msgs", {"msg/Fake.msg": "int32 a\n"})
    result = cli(str(tmp_path / "ws"), "--prefix", str(tmp_path / "prefix"))
    assert result.returncode == 0, result.stderr
    assert f"skipping {plain}: not an interface package" in result.stdout
    # std_msgs is importable in this environment: skipped, so nothing is built at all.
    assert re.search(r"^\[1/1\] std_msgs: importable already \(.*/std_msgs\), skipped$",
                     result.stdout, re.MULTILINE), result.stdout
    assert re.fullmatch(r"done in \d+ s: nothing to build; 1 importable already \(--force "
                        r"rebuilds them\)", result.stdout.splitlines()[-1]), result.stdout


def test_help_says_what_it_builds() -> None:
    result = cli("--help")
    assert result.returncode == 0
    text = " ".join(result.stdout.split())
    assert "Build ROS 2 interface packages" in text
    assert "rosidl_generate_interfaces" in text
    assert "Dependencies are built first" in text
    assert "--prefix" in text and "--force" in text


# --- built for real -----------------------------------------------------------------

@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory
          ) -> tuple[Path, subprocess.CompletedProcess[str]]:
    """Two packages, the second using the first's message, built into a throwaway prefix
    with one command (given in the wrong order on purpose)."""
    root = tmp_path_factory.mktemp("interfaces")
    make_package(root / "src", "probe_user_msgs",
                 {"msg/Reading.msg": "probe_base_msgs/Sample sample\n"
                                     "geometry_msgs/Point where\n",
                  "srv/Ask.srv": "string question\n---\nprobe_base_msgs/Sample answer\n"},
                 ("probe_base_msgs", "geometry_msgs"))
    make_package(root / "src", "probe_base_msgs",
                 {"msg/Sample.msg": "int32 count\nstring label\nfloat64[] values\n"})
    prefix = root / "prefix"
    result = cli(str(root / "src" / "probe_user_msgs"), str(root / "src" / "probe_base_msgs"),
                 "--prefix", str(prefix), "--build-dir", str(root / "build"))
    return prefix, result


def test_dependencies_are_built_first_with_progress_lines(
        built: tuple[Path, subprocess.CompletedProcess[str]]) -> None:
    prefix, result = built
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    lines = result.stdout.splitlines()
    assert lines[0] == (f"building 2 interface package(s) into {prefix}: probe_user_msgs, "
                        f"probe_base_msgs")
    steps = [line for line in lines if line.endswith(" ...")]
    assert steps == [
        "[1/2] probe_base_msgs: configuring (cmake) ...",
        f"[1/2] probe_base_msgs: building and installing (make -j{jobs()} install) ...",
        "[1/2] probe_base_msgs: checking that probe_base_msgs.msg import in a fresh "
        "interpreter ...",
        "[2/2] probe_user_msgs: configuring (cmake) ...",
        f"[2/2] probe_user_msgs: building and installing (make -j{jobs()} install) ...",
        "[2/2] probe_user_msgs: checking that probe_user_msgs.msg, probe_user_msgs.srv "
        "import in a fresh interpreter ...",
    ]
    # Every step ends with its time; a step longer than 5 s said how it went meanwhile.
    for step in steps:
        label = step[:-len(" ...")]
        (done,) = [line for line in lines if line.startswith(f"{label}: done in ")]
        took = float(done.split("done in ")[1].split(" s")[0])
        ticks = [line for line in lines if re.fullmatch(re.escape(label) + r": \d+ s(, .*)?",
                                                          line)]
        assert len(ticks) >= int(took // 5) - 1, (step, took, ticks)
        if "(make -j" in label and ticks:
            assert re.search(r": \d+ s, \d+%", ticks[-1]), ticks
    assert "[1/2] probe_base_msgs: built and installed; 1 types import and serialize" in lines
    # Reading; Ask and its Request, Response and Event (Jazzy's service introspection).
    assert "[2/2] probe_user_msgs: built and installed; 5 types import and serialize" in lines
    assert re.fullmatch(r"done in \d+ s: built probe_base_msgs, probe_user_msgs into " +
                        re.escape(str(prefix)), lines[lines.index("to use them, export:") - 1])


def jobs() -> int:
    return max(1, min(4, os.cpu_count() or 1))


def test_the_built_messages_round_trip_through_rclpy_in_another_process(
        built: tuple[Path, subprocess.CompletedProcess[str]]) -> None:
    prefix, result = built
    assert result.returncode == 0, result.stderr[-3000:]
    script = """
import json
from rclpy.serialization import deserialize_message, serialize_message
from probe_base_msgs.msg import Sample
from probe_user_msgs.msg import Reading
from probe_user_msgs.srv import Ask
reading = Reading(sample=Sample(count=-7, label="seven", values=[0.5, -2.25]))
reading.where.x = 1.5
data = serialize_message(reading)
back = deserialize_message(data, Reading)
answer = deserialize_message(serialize_message(Ask.Response(answer=reading.sample)),
                             Ask.Response)
print(json.dumps({"equal": back == reading, "count": back.sample.count,
                  "label": back.sample.label, "values": list(back.sample.values),
                  "x": back.where.x, "answer": answer.answer.label}))
"""
    env = with_exports(os.environ, prefix_exports(prefix))
    ran = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env=env, cwd=prefix, timeout=120)
    assert ran.returncode == 0, ran.stderr
    assert json.loads(ran.stdout) == {"equal": True, "count": -7,
                                      "label": "seven", "values": [0.5, -2.25], "x": 1.5,
                                      "answer": "seven"}
    # Nothing went into this environment.
    assert not (Path(sys.prefix) / "share" / "probe_base_msgs").exists()
    index = prefix / "share" / "ament_index" / "resource_index" / "packages"
    assert sorted(p.name for p in index.iterdir()) == ["probe_base_msgs", "probe_user_msgs"]


def test_a_failed_step_shows_its_log_and_installs_nothing(tmp_path: Path) -> None:
    make_package(tmp_path, "probe_broken_msgs", {"msg/Broken.msg": "int32 count extra !!\n"})
    build = tmp_path / "build"
    result = cli(str(tmp_path / "probe_broken_msgs"), "--prefix", str(tmp_path / "prefix"),
                 "--build-dir", str(build))
    assert result.returncode == 1, result.stdout + result.stderr
    log = build / "probe_broken_msgs" / "configure.log"
    assert ("[1/1] probe_broken_msgs: configuring (cmake) failed: expected exit code 0 "
            "from ") in result.stderr
    assert f"the last lines of its log ({log}):" in result.stderr
    tail = result.stderr.split(f"({log}):")[1]
    assert "value 'extra !!' can not be converted" in tail  # rosidl's own words
    assert log.is_file()
    assert not (tmp_path / "prefix" / "share" / "probe_broken_msgs").exists()


# --- the progress reporter (also setup_env.py's, for pip) --------------------------------

def _reported(step: Step, release: Path) -> list[str]:
    """What `run_step` said of ``step``, a command that works until ``release`` exists:
    its start, one progress line, its end."""
    said: list[str] = []
    runner = threading.Thread(target=run_step, args=(step, said.append))
    runner.start()
    try:
        wait_until(lambda: len(said) >= 2, timeout=REPORT_EVERY_S * 3, what="a progress line")
    finally:
        release.write_text("")
        runner.join(60)
    return said


def test_a_long_step_reports_what_it_does_until_it_ends(tmp_path: Path) -> None:
    """A pip-like command that works until the test lets it end: a line at the start, one
    every REPORT_EVERY_S with pip's last action (not its warnings), one at the end."""
    release = tmp_path / "release"
    script = ("import pathlib, sys, time\n"
              "print('Collecting ros-jazzy-rclpy==7.1.6', flush=True)\n"
              "print('  Downloading ros_rclpy-7.1.6-cp311-manylinux_2_28_x86_64.whl (2.6 MB)',"
              " flush=True)\n"
              "print('WARNING: Location ignored', flush=True)\n"
              f"while not pathlib.Path({str(release)!r}).exists():\n"
              "    time.sleep(0.05)\n"
              "print('Successfully installed ros-rclpy-7.1.6')\n")
    said = _reported(Step("[setup] pip install", [sys.executable, "-c", script], tmp_path,
                          tmp_path / "pip.log", where=pip_progress), release)
    assert said[0] == "[setup] pip install ..."
    assert re.fullmatch(r"\[setup\] pip install: \d+ s, Downloading ros_rclpy-7\.1\.6-cp311-"
                        r"manylinux_2_28_x86_64\.whl \(2\.6 MB\)", said[1]), said
    assert re.fullmatch(r"\[setup\] pip install: done in \d+\.\d s", said[-1]), said
    assert (tmp_path / "pip.log").read_text().endswith("Successfully installed ros-rclpy-7.1.6\n")


# What `setup.py -q build_ext` writes (its log in a set-up of this project): setuptools'
# warning with the source line Python echoes under it, then compiler diagnostics with
# their source excerpts.
BUILD_EXT_OUTPUT = (
    "/v/lib/python3.11/site-packages/setuptools/config/pyprojecttoml.py:108: "
    "_BetaConfiguration: Support for `[tool.setuptools]` in `pyproject.toml` is still *beta*.\n"
    "  warnings.warn(msg, _BetaConfiguration)\n")
BUILD_EXT_COMPILING = (
    "bridge/ros/_rcl_reader.c: In function '__pyx_pf_set_subscriptions':\n"
    "bridge/ros/_rcl_reader.c:6327:26: warning: comparison of integer expressions of "
    "different signedness [-Wsign-compare]\n"
    " 6327 |   __pyx_t_7 = (__pyx_t_6 != __pyx_v_count);\n"
    "      |                          ^~\n")


def test_progress_lines_leave_out_source_excerpts_and_echoed_warnings(
        tmp_path: Path) -> None:
    """Issue 43, item 12: set-up progress said `build_ext: 10 s, |     ^` and
    `warnings.warn(msg, _BetaConfiguration)`: the last line of the output, whatever it
    was. A compile now says the file it is at; any step's last line is one that says
    something (the warning itself, not the source Python echoes, nor a caret line)."""
    assert last_line(BUILD_EXT_OUTPUT).startswith(  # type: ignore[union-attr]
        "/v/lib/python3.11/site-packages/setuptools/config/pyprojecttoml.py:108: _Beta")
    assert last_line(BUILD_EXT_COMPILING) == BUILD_EXT_COMPILING.splitlines()[1][:87] + "..."
    assert compile_progress(BUILD_EXT_OUTPUT) is None
    assert compile_progress(BUILD_EXT_OUTPUT + BUILD_EXT_COMPILING) == \
        "compiling bridge/ros/_rcl_reader.c"
    release = tmp_path / "release"
    script = (f"import pathlib, sys, time\n"
              f"sys.stdout.write({BUILD_EXT_OUTPUT + BUILD_EXT_COMPILING!r})\n"
              f"sys.stdout.flush()\n"
              f"while not pathlib.Path({str(release)!r}).exists():\n"
              f"    time.sleep(0.05)\n")
    said = _reported(Step("[setup] setup.py build_ext", [sys.executable, "-c", script],
                          tmp_path, tmp_path / "build-ext.log", where=compile_progress), release)
    assert re.fullmatch(r"\[setup\] setup\.py build_ext: \d+ s, compiling "
                        r"bridge/ros/_rcl_reader\.c", said[1]), said


def test_make_progress_names_the_percentage_and_the_target() -> None:
    output = ("[  1%] Generating C code for ROS interfaces\n"
              "[ 45%] Building C object CMakeFiles/turtlesim__rosidl_generator_c.dir/"
              "rosidl_generator_c/turtlesim/msg/detail/pose__functions.c.o\n")
    assert make_progress(output) == "45%, compiling turtlesim__rosidl_generator_c"
    assert make_progress("[ 56%] Linking C shared library libturtlesim__rosidl_generator_c.so"
                         "\n") == "56%, linking libturtlesim__rosidl_generator_c.so"
    assert make_progress("[  2%] Generating C code for ROS interfaces\n") == \
        "2%, Generating C code for ROS interfaces"
    assert make_progress("-- Install configuration: \"\"\n") is None
