"""The environment set-up builds real ROS 2: rclpy processes talk, tf2_msgs exists."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import pytest

from support import DOMAIN_BLOCK, DOMAIN_LOCKS, REPO, Processes, spare_domain


def read_message(line: str) -> dict:
    assert line.startswith("MSG "), line
    return json.loads(line[4:])


def test_session_is_isolated() -> None:
    domain = int(os.environ["ROS_DOMAIN_ID"])
    assert 1 <= domain and int(spare_domain(DOMAIN_BLOCK - 1)) <= 99
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert os.path.isdir(os.environ["ROS_LOG_DIR"])


def test_no_other_session_can_take_this_sessions_domains() -> None:
    """The session holds the lock of its block of domains: another process trying it, as a
    concurrent `make test` on this host would, finds it taken."""
    lock = DOMAIN_LOCKS / f"{os.environ['ROS_DOMAIN_ID']}.lock"
    probe = subprocess.run([sys.executable, "-c", (
        "import fcntl, sys\n"
        "handle = open(sys.argv[1], 'w')\n"
        "try:\n    fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)\n"
        "except OSError:\n    print('taken')\n"
        "else:\n    print('free')\n"), str(lock)], capture_output=True, text=True, timeout=60)
    assert (probe.returncode, probe.stdout) == (0, "taken\n"), probe.stderr


def test_two_rclpy_processes_exchange_pose_stamped(processes: Processes) -> None:
    subscriber = processes.python("echo", "echo_subscriber.py", "/foundation_pose",
                                  "geometry_msgs/msg/PoseStamped", "--count", "1")
    subscriber.wait_for_output("READY")
    half = math.sqrt(0.5)
    processes.python("pose", "pose_publisher.py", "/foundation_pose",
                     "0.0031415", "-2.5", "7", "0", "0", str(half), str(half), "base_link")
    msg = read_message(subscriber.wait_for_output("MSG "))
    position = msg["pose"]["position"]
    assert (position["x"], position["y"], position["z"]) == (0.0031415, -2.5, 7.0)
    orientation = msg["pose"]["orientation"]
    assert orientation["z"] == pytest.approx(half) and orientation["w"] == pytest.approx(half)
    assert msg["header"]["frame_id"] == "base_link"
    assert msg["header"]["stamp"]["sec"] > 1_600_000_000


def test_tf_static_is_latched_and_tf_streams(processes: Processes) -> None:
    publisher = processes.python("tf", "tf_publisher.py")
    publisher.wait_for_output("READY")
    # Started after the one static publish: only transient-local durability delivers it.
    static = processes.python("static", "echo_subscriber.py", "/tf_static",
                              "tf2_msgs/msg/TFMessage", "--transient-local", "--count", "1")
    dynamic = processes.python("dynamic", "echo_subscriber.py", "/tf",
                               "tf2_msgs/msg/TFMessage", "--count", "1")
    static_msg = read_message(static.wait_for_output("MSG "))
    (world_base,) = static_msg["transforms"]
    assert (world_base["header"]["frame_id"], world_base["child_frame_id"]) == ("world", "base")
    translation = world_base["transform"]["translation"]
    assert (translation["x"], translation["y"], translation["z"]) == (0.1, 0.2, 0.3)

    dynamic_msg = read_message(dynamic.wait_for_output("MSG "))
    (base_tool,) = dynamic_msg["transforms"]
    assert (base_tool["header"]["frame_id"], base_tool["child_frame_id"]) == ("base", "tool")
    assert base_tool["transform"]["translation"]["z"] == 0.5
    assert base_tool["transform"]["rotation"]["z"] == pytest.approx(math.sqrt(0.5))


def test_tf2_msgs_error_constants_match_upstream() -> None:
    from tf2_msgs.msg import TF2Error

    assert (TF2Error.NO_ERROR, TF2Error.LOOKUP_ERROR, TF2Error.EXTRAPOLATION_ERROR,
            TF2Error.TRANSFORM_ERROR) == (0, 1, 3, 6)
    error = TF2Error(error=TF2Error.CONNECTIVITY_ERROR, error_string="no path")
    assert error.error == 2 and error.error_string == "no path"


@pytest.mark.integration
def test_cli_help_lists_the_commands() -> None:
    result = subprocess.run([sys.executable, "-m", "bridge.cli", "--help"], cwd=REPO,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "usage: slicer-ros2-bridge" in result.stdout
    assert "run" in result.stdout


def test_the_install_built_the_compiled_tf_store() -> None:
    """`make setup` (pip install -e) builds bridge/tf/_compiled_store.pyx wherever a C
    compiler is found; the daemon then runs it, not the pure Python fallback."""
    import shutil
    import sysconfig

    from bridge.tf import buffer

    if shutil.which(sysconfig.get_config_var("CC").split()[0] or "cc") is None:
        pytest.skip("no C compiler here: the pure Python tf store is the one installed")
    assert buffer.CompiledFrameStore is not None, (
        "the compiled tf store was not built, or is from an older build: see "
        ".cache/pip-install.log")
    assert buffer.TfBuffer().compiled
