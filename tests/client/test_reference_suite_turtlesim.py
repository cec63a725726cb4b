"""SlicerROS2's own unit tests, the cases that need turtlesim (TestTurtlesimNode,
TestParameterNode, TestServiceClient of its Testing/Python/ROS2Tests.py), written here with
the same calls and assertions: turtlesim is tests/peers/turtlesim_node.py with its
interfaces built from tests/interfaces/turtlesim, started, listed and set with `ros2` run
exactly as the suite runs it (its shell line; tools/reference_suite/ros2_cli.py). Where the
suite spins a fixed 100 ms, these wait for what it waits for (a busy machine)."""

from __future__ import annotations

from typing import Iterator

import pytest

import slicer_client
from reference_suite import ros2, slicer_standin, spin_some, spin_until, stop_group
from support import TIME_SCALE, Child, RunningDaemon

pytestmark = pytest.mark.ros


@pytest.fixture
def slicer(turtle_daemon: RunningDaemon) -> Iterator[object]:
    client = slicer_client.connect("127.0.0.1", turtle_daemon.port)
    try:
        yield slicer_standin(client.logic)
    finally:
        client.close()


def check_ros2_node_running(node_name: str) -> bool:
    """The suite's check: is the node in `ros2 node list`?"""
    listed = ros2("node list")
    assert listed.returncode == 0, listed.stderr
    return node_name in listed.stdout.split("\n")


def kill_subprocess(node: Child) -> None:
    """The suite's kill_subprocess: SIGTERM to the group (then its 1 s wait: here, the exit)."""
    stop_group(node)


def test_turtlesim_node_create_and_destroy(slicer, turtlesim: Child) -> None:
    spin_some(slicer)
    assert check_ros2_node_running("/turtlesim"), "Turtlesim node not running"
    kill_subprocess(turtlesim)
    assert not check_ros2_node_running("/turtlesim"), "Turtlesim node still running"


def test_parameter_monitoring(slicer, turtlesim: Child) -> None:
    ros2Node = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLROS2NodeNode")  # noqa: N806
    ros2Node.Create("testNodeParameter")
    spin_some(slicer)
    assert check_ros2_node_running("/turtlesim"), "Turtlesim node not running"

    testParam = ros2Node.CreateAndAddParameterNode("/turtlesim")  # noqa: N806
    spin_some(slicer)
    # Not added yet, absent, and present but not added: no type.
    for name in ("background_r", "background_y", "background_g"):
        assert testParam.GetParameterType(name) == ""
        assert testParam.GetParameterType(name) == ""
    testParam.AddParameter("background_r")
    testParam.AddParameter("background_y")
    spin_until(slicer, lambda: testParam.IsParameterSet("background_r"), "background_r set")
    assert testParam.GetParameterType("background_r") == "integer"
    assert not testParam.IsParameterSet("background_y", True)
    assert testParam.GetParameterType("background_y") == ""
    # Changed by another node: known without AddParameter, as in the reference.
    changed = ros2("param set /turtlesim background_g 150")
    assert changed.returncode == 0, changed.stdout + changed.stderr
    spin_until(slicer, lambda: testParam.IsParameterSet("background_g", True),
               "background_g set by ros2 param set")
    assert testParam.IsParameterSet("background_g")
    assert testParam.GetParameterType("background_g") == "integer"
    assert testParam.GetParameterAsInteger("background_g") == 150
    assert ros2Node.RemoveAndDeleteParameterNode("/turtlesim")

    # The suite's deletion checks (its "temporary hack" runs them in this same test).
    testParam = ros2Node.CreateAndAddParameterNode("/turtlesim")  # noqa: N806
    spin_some(slicer)
    assert ros2Node.RemoveAndDeleteParameterNode("/turtlesim"), \
        "Failed to delete parameter node which exists"
    spin_some(slicer)
    assert not ros2Node.RemoveAndDeleteParameterNode("/turtlesim"), \
        "Deleted parameter node which used to exist"
    spin_some(slicer)
    assert not ros2Node.RemoveAndDeleteParameterNode("/random_name"), \
        "Deleted parameter node which never existed"
    spin_some(slicer)

    kill_subprocess(turtlesim)
    spin_some(slicer)
    assert not check_ros2_node_running("/turtlesim"), "Turtlesim node running"
    ros2Node.Destroy()


def test_service_client(slicer, turtlesim: Child) -> None:
    ros2Node = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLROS2NodeNode")  # noqa: N806
    ros2Node.Create("testNodeServiceClient")
    spin_some(slicer)
    assert check_ros2_node_running("/turtlesim"), "Turtlesim node not running"
    spawn1 = ros2Node.CreateAndAddServiceClientNode("vtkMRMLROS2ServiceClientSpawnNode",
                                                    "/spawn")
    req = spawn1.CreateBlankRequest()
    req.SetX(4.0)
    req.SetY(4.0)
    spawn1.SendAsyncRequest(req)
    spin_until(slicer, lambda: spawn1.GetLastResponse() is not None, "the spawn response")
    res = spawn1.GetLastResponse()
    assert res.GetName() == "turtle2"
    assert type(res).__name__ == "vtkTurtlesimSpawnResponse"
    assert spawn1.GetLastResponseStatus() and spawn1.PreRequestCheck()
    kill_subprocess(turtlesim)
    spin_some(slicer)
    ros2Node.Destroy()


def test_an_async_reply_in_flight_is_there_when_the_script_reads_it(slicer,
                                                                    turtlesim: Child) -> None:
    """The issue's failure under load: `GetLastResponse()` was None after SendAsyncRequest
    and the suite's spins. A request in flight is waited for, up to its timeout: read at
    once, with no spin at all, the response is this request's."""
    ros2Node = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLROS2NodeNode")  # noqa: N806
    spawn = ros2Node.CreateAndAddServiceClientNode("vtkMRMLROS2ServiceClientSpawnNode",
                                                   "/spawn")
    for name in ("first", "second"):
        req = spawn.CreateBlankRequest()
        req.SetX(2.0)
        req.SetName(name)
        spawn.SendAsyncRequest(req, 4.0 * TIME_SCALE)
        res = spawn.GetLastResponse()
        assert res is not None and res.GetName() == name  # the one just sent, not the last
        assert spawn.GetLastResponseStatus()
    # A request that cannot be answered: the wait ends at its timeout, the status says so.
    stopped = spawn.GetLastResponse()
    kill_subprocess(turtlesim)
    spawn.SendAsyncRequest(spawn.CreateBlankRequest(), 0.5)
    assert spawn.GetLastResponse() is stopped and not spawn.GetLastResponseStatus()
    ros2Node.Destroy()
