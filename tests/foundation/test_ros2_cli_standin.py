"""tools/reference_suite/ros2_cli.py, run exactly as SlicerROS2's unit tests run `ros2`:
`unset PYTHONHOME ; unset PYTHONPATH ; . setup.sh ; /usr/bin/python3 .../ros2 <command>`
through a shell, against the turtlesim stand-in it starts itself."""

from __future__ import annotations

import json
import os
import shlex
import subprocess
from typing import Iterator

import pytest

from interface_builds import BuiltInterfaces
from reference_suite import SUITE, as_the_suite, group_members, ros2, stop_group
from support import Child, Processes

pytestmark = pytest.mark.integration  # starts processes

@pytest.fixture
def turtlesim(turtlesim_interfaces: BuiltInterfaces, processes: Processes) -> Iterator[Child]:
    """`ros2 run turtlesim turtlesim_node` through the suite's shell line."""
    node = processes.start("ros2-run",
                           ["sh", "-c", as_the_suite("run turtlesim turtlesim_node")])
    try:
        node.wait_for_output("READY", timeout=30)
        yield node
    finally:
        stop_group(node)


def test_setup_sh_prints_nothing_and_names_the_distribution() -> None:
    result = subprocess.run(["sh", "-c", f". {shlex.quote(str(SUITE / 'setup.sh'))} && "
                             f"echo $ROS_VERSION $ROS_DISTRO"], capture_output=True, text=True,
                            timeout=30, env={k: v for k, v in os.environ.items()
                                             if k != "ROS_DISTRO"})
    assert (result.returncode, result.stdout, result.stderr) == (0, "2 jazzy\n", "")


def test_node_and_service_lists_show_turtlesim_and_never_the_lister(
        turtlesim: Child) -> None:
    nodes = ros2("node list")
    assert nodes.returncode == 0, nodes.stderr
    listed = nodes.stdout.splitlines()
    assert "/turtlesim" in listed
    assert all(name.startswith("/") and not name.split("/")[-1].startswith("_")
               for name in listed), listed

    services = ros2("service list")
    assert services.returncode == 0, services.stderr
    offered = services.stdout.splitlines()
    for name in ("/spawn", "/kill", "/turtlesim/set_parameters", "/turtlesim/get_parameters"):
        assert name in offered, offered
    assert offered == sorted(offered)
    assert not [name for name in offered if "_ros2cli_" in name]


def test_param_set_types_the_value_and_says_what_happened(
        turtlesim: Child) -> None:
    done = ros2("param set /turtlesim background_g 150")
    assert (done.returncode, done.stdout) == (0, "Set parameter successful\n"), done.stderr
    assert json.loads(turtlesim.wait_for_output("PARAM ")[len("PARAM "):]) == \
        {"name": "background_g", "value": 150}

    # "1.5" is a double by YAML's rules: turtlesim's integer parameter refuses it.
    refused = ros2("param set turtlesim background_g 1.5")
    assert refused.returncode == 1
    assert refused.stdout == ""
    assert refused.stderr.startswith("Set parameter failed: "), refused.stderr
    assert "INTEGER" in refused.stderr and "DOUBLE" in refused.stderr, refused.stderr


def test_run_stops_with_its_process_group_and_then_is_not_listed(
        turtlesim: Child) -> None:
    stop_group(turtlesim)  # returns once the node the shell started has ended too
    assert not group_members(turtlesim.pid)
    assert "STOPPED" in turtlesim.output()  # the node's clean end, not a kill
    assert "Traceback" not in turtlesim.output()
    nodes = ros2("node list")
    assert nodes.returncode == 0, nodes.stderr
    assert "/turtlesim" not in nodes.stdout.splitlines()


def test_an_unknown_executable_is_refused() -> None:
    result = ros2("run turtlesim no_such_node")
    assert (result.returncode, result.stderr) == (1, "No executable found\n")
    result = ros2("run no_such_package turtlesim_node")
    assert (result.returncode, result.stderr) == (1, "Package 'no_such_package' not found\n")
