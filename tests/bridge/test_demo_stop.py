"""`demo` and its children die together, whatever ends the session: SIGINT, SIGTERM,
SIGHUP (the terminal closed), or the demo process killed outright (SIGKILL)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from bridge.robots._spin import PARENT_PID_ENV
from support import (Processes, alive, children_of, pick_free_port, scaled, spare_domain,
                     wait_until)

pytestmark = pytest.mark.ros


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGKILL],
                         ids=lambda sig: sig.name)
def test_the_demo_s_children_end_with_it(processes: Processes, sig: signal.Signals) -> None:
    port = pick_free_port()
    # A ROS domain of its own: other modules' robots are /robot_state_publisher too.
    domain = spare_domain(1)
    demo = processes.bridge("demo", "--port", str(port), env={"ROS_DOMAIN_ID": domain})
    demo.wait_for_output("Stop with Ctrl-C", timeout=90)
    helpers = [pid for pid, _, cmd in children_of(demo.pid)
               if "state_publisher" in cmd or "joint_motion" in cmd]
    assert len(helpers) == 2, children_of(demo.pid)
    demo.popen.send_signal(sig)
    try:
        code = demo.popen.wait(scaled(20))
        wait_until(lambda: not any(alive(pid) for pid in helpers), timeout=15,
                   what=f"the demo's children {helpers} gone after {sig.name}")
    finally:
        for pid in filter(alive, helpers):  # orphans are not the test runner's children
            os.kill(pid, signal.SIGKILL)
    output = demo.output()
    if sig == signal.SIGKILL:
        assert code == -signal.SIGKILL  # no chance to stop them: they noticed by themselves
    else:
        assert code == 0, output[-3000:]
        assert f"shutting down ({sig.name})" in output
        assert "did not stop within" not in output  # they stopped when asked, not killed
    assert "Traceback" not in output, output[-3000:]


def _has_loaded(pid: int, library: str) -> bool:
    with open(f"/proc/{pid}/maps") as maps:
        return library in maps.read()


@pytest.mark.parametrize("stage", ["numpy loaded", "rclpy loaded", "listening"])
def test_ctrl_c_while_the_demo_starts_ends_it_cleanly(processes: Processes, stage: str) -> None:
    """Issue 25, item 10: a Ctrl-C in the first seconds of `demo`, while it imports and
    starts, ends it with exit code 0 and no traceback. Each stage is an event read from
    /proc or the output: numpy's or rclpy's library loaded (the command's imports), the
    daemon listening. (Before the command's first line runs, the interpreter's own start,
    `site` included, prints its traceback: no code of the project's runs there yet.)"""
    domain = spare_domain(1)
    demo = processes.bridge("demo", "--port", str(pick_free_port()),
                            env={"ROS_DOMAIN_ID": domain})
    if stage == "listening":
        demo.wait_for_output("listening on", timeout=90)
    else:
        library = {"numpy loaded": "_multiarray_umath", "rclpy loaded": "_rclpy_pybind11"}
        wait_until(lambda: _has_loaded(demo.pid, library[stage]), timeout=90,
                   what=f"the demo at stage {stage!r}")
    demo.popen.send_signal(signal.SIGINT)
    code = demo.popen.wait(scaled(30))
    output = demo.output()
    assert code == 0, output[-3000:]
    assert "Traceback" not in output and "Exception ignored" not in output, output[-3000:]
    # Stopped while starting (one line), or, past the daemon's signal handling, as usual.
    assert output.rstrip().endswith("slicer-ros2-bridge: stopped (Ctrl-C) while starting") \
        or "shutting down (SIGINT)" in output, output[-3000:]


def test_a_child_whose_parent_is_not_there_stops_by_itself(processes: Processes) -> None:
    """The portable check (parent pid), without the kernel's death signal: a child told to
    live with a parent that is not its parent (as after re-parenting) stops at once."""
    not_my_parent = os.getpid() + 1_000_000  # no such process
    child = processes.start("joint_motion", [sys.executable, "-u", "-m",
                                             "bridge.robots.demo.joint_motion"],
                            env={PARENT_PID_ENV: str(not_my_parent)})
    try:
        assert child.popen.wait(scaled(30)) == 0, child.output()[-3000:]
    except subprocess.TimeoutExpired:
        raise AssertionError(f"still running: {child.output()[-3000:]}") from None
