"""The daemon as a user runs it: starts, serves TCP, stops cleanly, fails clearly."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from support import REPO, Processes, assert_clean_exit, pick_free_port, start_daemon

pytestmark = pytest.mark.integration  # starts processes


def test_run_listens_and_stops_on_sigint(processes: Processes) -> None:
    daemon = start_daemon(processes)
    with socket.create_connection(("127.0.0.1", daemon.port), timeout=5):
        pass
    assert_clean_exit(daemon)


def test_sigterm_stops_with_exit_code_0(processes: Processes) -> None:
    daemon = start_daemon(processes)
    assert daemon.child.stop(signal.SIGTERM) == 0
    assert "Traceback" not in daemon.child.output()


def test_port_in_use_is_one_line_and_exit_code_2(processes: Processes) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run([sys.executable, "-m", "bridge.cli", "run", "--port", str(port)],
                                cwd=REPO, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and f"127.0.0.1:{port} is already in use" in lines[0], result.stderr
    assert "Traceback" not in result.stderr


def test_a_second_bridge_on_a_running_bridge_s_port_is_refused(processes: Processes) -> None:
    # The bridge's listener shares its port for knocks (bridge/core/knock.py); another bridge of
    # the same user must still be told the port is taken, not share its clients.
    daemon = start_daemon(processes)
    result = subprocess.run([sys.executable, "-m", "bridge.cli", "run", "--port",
                             str(daemon.port)], cwd=REPO, capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 2, result.stderr
    assert f"127.0.0.1:{daemon.port} is already in use" in result.stderr
    with socket.create_connection(("127.0.0.1", daemon.port), timeout=5):
        pass
    assert_clean_exit(daemon)


def test_a_second_daemon_on_the_same_domain_warns_that_it_is_a_namesake(
        processes: Processes) -> None:
    """Issue 43, item 13: a second daemon on the same ROS domain was /slicer_bridge too,
    with no word of it. It now says so in one warning line at start."""
    first = start_daemon(processes)
    second = start_daemon(processes)
    line = second.child.wait_for_output("another node named /slicer_bridge", timeout=30)
    domain = os.environ["ROS_DOMAIN_ID"]
    assert line.endswith(f" WARNING bridge: another node named /slicer_bridge is on "
                         f"the ROS graph (ROS_DOMAIN_ID {domain}): a second daemon? Peers "
                         f"cannot tell the two apart; start this one with --node-name, or "
                         f"on another ROS_DOMAIN_ID"), line
    assert second.child.output().count("another node named") == 1
    assert_clean_exit(second)
    assert_clean_exit(first)


def test_bad_config_file_is_refused_with_its_location(tmp_path: Path) -> None:
    config = tmp_path / "bridges.yaml"
    config.write_text("subscribers:\n  - {topic: /ok, type: String}\n"
                      "  - {topic: /bad, type: NoSuchType}\n")
    result = subprocess.run([sys.executable, "-m", "bridge.cli", "run", "--port",
                             str(pick_free_port()), "--config", str(config)],
                            cwd=REPO, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    assert "bridges.yaml: subscribers[1]" in result.stderr
    assert "NoSuchType" in result.stderr
    assert "Traceback" not in result.stderr


def test_a_misspelt_config_key_is_named(tmp_path: Path) -> None:
    config = tmp_path / "bridges.yaml"
    config.write_text("subscribers:\n  - {topic: /ok, typ: String}\n")
    result = subprocess.run([sys.executable, "-m", "bridge.cli", "run", "--port",
                             str(pick_free_port()), "--config", str(config)],
                            cwd=REPO, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "bridges.yaml: subscribers[0]" in lines[0]
    assert "type: expected a value, got nothing (but an unknown key 'typ': a typo?)" in lines[0]


def test_a_missing_urdf_is_named_once(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere" / "robot.urdf"
    config = tmp_path / "bridges.yaml"
    config.write_text(f"robots:\n  - {{name: r, source: {{kind: file, path: '{missing}'}}}}\n")
    result = subprocess.run([sys.executable, "-m", "bridge.cli", "run", "--port",
                             str(pick_free_port()), "--config", str(config)],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, result.stderr
    line = result.stderr.strip().splitlines()[-1]
    assert line.count(str(missing)) == 1, line
    assert "nothing there" in line and "Traceback" not in result.stderr


def test_unknown_config_section_names_the_sections(tmp_path: Path) -> None:
    config = tmp_path / "bridges.yaml"
    config.write_text("subscriberz: []\n")
    result = subprocess.run([sys.executable, "-m", "bridge.cli", "run", "--config", str(config)],
                            cwd=REPO, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert "unknown section 'subscriberz'" in result.stderr and "subscribers" in result.stderr


def test_help_documents_the_options() -> None:
    result = subprocess.run([sys.executable, "-m", "bridge.cli", "run", "--help"], cwd=REPO,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0
    for option in ("--host", "--port", "--config", "--node-name", "--namespace",
                   "--log-level"):
        assert option in result.stdout
