"""A stop always ends: whatever ROS's teardown does, SIGTERM/SIGINT/SIGHUP end the daemon
within --stop-timeout (logged), and a second signal ends it at once."""

from __future__ import annotations

import signal
import subprocess
import time

import pytest

from support import Processes, assert_clean_exit, pick_free_port, scaled, start_daemon

HANGING = "hanging_teardown_daemon.py"


def start_hanging(processes: Processes, mode: str, *args: str):  # type: ignore[no-untyped-def]
    port = pick_free_port()
    child = processes.python("hanging", HANGING, "--hang", mode, "run", "--port", str(port),
                             *args)
    child.wait_for_output("listening on", timeout=30)
    return child


def wait_exit(child, timeout: float) -> int:  # type: ignore[no-untyped-def]
    try:
        return child.popen.wait(timeout)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"still running {timeout} s later; output:\n"
                             f"{child.output()[-3000:]}") from None


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=lambda sig: sig.name)
def test_a_hung_teardown_is_cut_short_at_the_stop_timeout(processes: Processes,
                                                          sig: signal.Signals) -> None:
    child = start_hanging(processes, "released", "--stop-timeout", "2")
    start = time.monotonic()
    child.popen.send_signal(sig)
    child.wait_for_output("TEARDOWN HANGS", timeout=10)
    code = wait_exit(child, scaled(10))
    took = time.monotonic() - start
    output = child.output()
    print(f"\n{sig.name} with a hung ROS teardown: exit {code} after {took:.1f} s")
    assert code == 0, output[-3000:]
    assert took >= 2.0  # it waited for the teardown as long as it was told to
    assert f"shutting down ({sig.name})" in output
    assert "did not finish within 2 s of the stop request" in output
    assert "cut short, exiting now" in output
    assert "Traceback" not in output


def test_a_teardown_hung_holding_the_gil_still_ends(processes: Processes) -> None:
    """No Python thread can run: faulthandler's C watchdog dumps the stacks and exits."""
    child = start_hanging(processes, "held", "--stop-timeout", "1")
    child.popen.send_signal(signal.SIGTERM)
    child.wait_for_output("TEARDOWN HANGS", timeout=10)
    code = wait_exit(child, scaled(10))
    output = child.output()
    assert code == 1, output[-3000:]
    assert "Timeout (0:00:03)!" in output  # 1 s, then the 2 s the Python watchdog had
    assert "in stop" in output  # the dump shows where it hung: our hanging RosNode.stop


def test_a_second_signal_ends_a_hung_stop_at_once(processes: Processes) -> None:
    child = start_hanging(processes, "held", "--stop-timeout", "600")
    child.popen.send_signal(signal.SIGTERM)
    child.wait_for_output("TEARDOWN HANGS", timeout=10)
    child.popen.send_signal(signal.SIGTERM)
    assert wait_exit(child, scaled(5)) == -signal.SIGTERM


def test_sighup_stops_the_daemon_cleanly(processes: Processes) -> None:
    daemon = start_daemon(processes)
    daemon.child.popen.send_signal(signal.SIGHUP)
    assert wait_exit(daemon.child, scaled(10)) == 0
    assert "shutting down (SIGHUP)" in daemon.child.output()
    assert_clean_exit(daemon)
