"""The turtlesim stand-in (tests/peers/turtlesim_node.py) answers as turtlesim does, to real
rclpy clients in other processes; its interfaces come from the session's cached build."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

from interface_builds import BuiltInterfaces
from support import REPO, Processes


def spawn(processes: Processes, request: dict) -> dict:
    caller = processes.python("spawn", "service_caller.py", "/spawn", "turtlesim/srv/Spawn",
                              json.dumps(request))
    line = caller.wait_for_output("RESPONSE ", timeout=30)
    return json.loads(line[len("RESPONSE "):])


def test_spawn_names_turtles_as_turtlesim_does(turtlesim_interfaces: BuiltInterfaces,
                                               processes: Processes) -> None:
    node = processes.python("turtlesim", "turtlesim_node.py")
    node.wait_for_output("READY")
    assert spawn(processes, {"x": 4.0, "y": 4.5, "theta": 0.25}) == {"name": "turtle2"}
    assert json.loads(node.wait_for_output("CALL spawn ")[len("CALL spawn "):]) == \
        {"x": 4.0, "y": 4.5, "theta": 0.25, "name": ""}
    assert spawn(processes, {"name": "leonardo"}) == {"name": "leonardo"}
    assert spawn(processes, {"name": "leonardo"}) == {"name": ""}  # taken: refused
    assert "A turtle named [leonardo] already exists" in node.wait_for_output("already exists")

    killer = processes.python("kill", "service_caller.py", "/kill", "turtlesim/srv/Kill",
                              json.dumps({"name": "turtle2"}))
    assert killer.wait_for_output("RESPONSE ") == "RESPONSE {}"
    node.wait_for_output('CALL kill {"name": "turtle2"}')
    # The counter goes on, as turtlesim's: a killed name is not given again.
    assert spawn(processes, {}) == {"name": "turtle3"}
    assert node.stop(signal.SIGTERM) == 0, node.output()


def test_its_background_parameters_read_and_set(turtlesim_interfaces: BuiltInterfaces,
                                                processes: Processes) -> None:
    node = processes.python("turtlesim", "turtlesim_node.py")
    node.wait_for_output("READY")
    actions = [{"get": "background_r"}, {"get": "background_g"}, {"get": "background_b"},
               {"set": "background_g", "type": "integer", "value": 150},
               {"get": "background_g"}]
    caller = processes.python("params", "param_caller.py", "/turtlesim",
                              *map(json.dumps, actions))
    results = []
    for _ in actions:
        line = caller.wait_for_output("RESULT ", timeout=30)
        results.append(json.loads(line[len("RESULT "):]))
    integer = 2  # rcl_interfaces/msg/ParameterType PARAMETER_INTEGER
    assert results[:3] == [{"type": integer, "value": 69}, {"type": integer, "value": 86},
                           {"type": integer, "value": 255}]
    assert results[3]["successful"] is True
    assert results[4] == {"type": integer, "value": 150}
    assert json.loads(node.wait_for_output("PARAM ")[len("PARAM "):]) == \
        {"name": "background_g", "value": 150}
    assert node.stop(signal.SIGINT) == 0, node.output()


def test_a_second_session_reuses_the_cached_build(
        turtlesim_interfaces: BuiltInterfaces) -> None:
    started = time.monotonic()
    second = subprocess.run([sys.executable, str(REPO / "tests" / "interface_builds.py")],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    took = time.monotonic() - started
    assert second.returncode == 0, second.stderr
    assert second.stdout.startswith(f"reused {turtlesim_interfaces.prefix} in "), second.stdout
    assert took < 30, f"a reuse took {took:.1f} s: it must not rebuild"
    assert (turtlesim_interfaces.prefix / "share" / "ament_index" / "resource_index" /
            "packages" / "turtlesim").is_file()
