"""`slicer-ros2-bridge demo` started for a tool or a bench (not a test: tests use
tests/support.py): on a free port, in the environment given, once it says it runs."""

from __future__ import annotations

import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tools.slicer_core.peer import PeerUnavailableError, peer_python

REPO = Path(__file__).resolve().parents[2]


def start_demo(env: dict[str, str],
               timeout: float = 120.0) -> tuple[subprocess.Popen[bytes], int]:
    """The demo's process (its own process group: SIGINT it to stop) and its port."""
    log = Path(tempfile.mkdtemp(prefix="slicer-ros2-bridge-demo-")) / "demo.log"
    with log.open("wb") as out:
        demo = subprocess.Popen([sys.executable, "-u", "-m", "bridge.console", "demo",
                                 "--port", "0"], stdout=out, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, cwd=str(REPO), env=env,
                                start_new_session=True)
    deadline = time.monotonic() + timeout
    while "Stop with Ctrl-C" not in log.read_text(errors="replace"):
        if demo.poll() is not None or time.monotonic() > deadline:
            raise SystemExit(f"the demo did not start:\n{log.read_text()[-3000:]}")
        time.sleep(0.1)
    line = next(ln for ln in log.read_text().splitlines() if " (OpenIGTLink); ROS node" in ln)
    return demo, int(line.split(" (OpenIGTLink)")[0].rsplit(":", 1)[1])


def ros_env(name: str) -> dict[str, str]:
    """This environment on a ROS domain picked at random, discovery on this host only."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(1, 100)),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix=f"{name}-roslog-"))
    return env


def peer_or_exit() -> Path:
    """The Slicer peer's Python, or the exit of a command that needs it, saying why."""
    try:
        return peer_python()
    except PeerUnavailableError as error:
        raise SystemExit(str(error)) from None
