"""`slicer-ros2-bridge demo` supervising its two children (the state publisher, the joint
motion node): one that dies is reported with its last output and the demo serves on; one
that does not stop when asked (frozen with SIGSTOP) is killed after the grace period, and
the demo still ends cleanly."""

from __future__ import annotations

import os
import signal

import pytest

from support import (Processes, alive, children_of, pick_free_port, scaled, spare_domain,
                     wait_until)

pytestmark = pytest.mark.ros


def test_a_child_that_dies_and_one_that_will_not_stop(processes: Processes) -> None:
    port = pick_free_port()
    # A ROS domain of its own: other modules' robots are /robot_state_publisher too.
    domain = spare_domain(2)
    demo = processes.bridge("demo", "--port", str(port), env={"ROS_DOMAIN_ID": domain})
    demo.wait_for_output("Stop with Ctrl-C", timeout=90)
    helpers = {cmd: pid for pid, _, cmd in children_of(demo.pid)
               if "state_publisher" in cmd or "joint_motion" in cmd}
    motion = next(pid for cmd, pid in helpers.items() if "joint_motion" in cmd)
    publisher = next(pid for cmd, pid in helpers.items() if "state_publisher" in cmd)
    try:
        os.kill(motion, signal.SIGKILL)
        line = demo.wait_for_output("demo: the joint motion", timeout=30)
        assert f"(pid {motion}) exited with code -9; the robot stops moving" in line
        # Its last output follows: the line that said it was ready.
        demo.wait_for_output("joint motion ready")
        os.kill(publisher, signal.SIGSTOP)  # frozen: SIGINT waits, SIGKILL does not
        demo.popen.send_signal(signal.SIGINT)
        code = demo.popen.wait(scaled(40))
        wait_until(lambda: not alive(publisher), timeout=15, what="the frozen child killed")
    finally:
        for pid in filter(alive, (motion, publisher)):
            os.kill(pid, signal.SIGKILL)
    output = demo.output()
    assert code == 0, output[-3000:]
    assert "demo: the state publisher did not stop within 5 s: killed" in output
    assert "Traceback" not in output, output[-3000:]
