"""The real-Slicer peer: 3D Slicer's core from PyPI (slicer-core) with Slicer's own
OpenIGTLinkIF connector, built by ../shared/peers/slicer-openigtlinkif/build.sh into
`.cache/slicer-peer` (minutes once, then seconds: its steps are cached), with the ROS2Bridge
extension's MRML library (mrml_library.py). Used by the tests
and by tools/render_scene_picture.py; the project itself never needs it."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path
from typing import Optional

from tools.slicer_core.mrml_library import LibraryBuildError, build_mrml_library

REPO = Path(__file__).resolve().parents[2]
BUILD_SCRIPT = REPO.parent / "shared" / "peers" / "slicer-openigtlinkif" / "build.sh"
# SLICER_PEER_PREFIX: an already built peer elsewhere (another checkout's).
PREFIX = Path(os.environ.get("SLICER_PEER_PREFIX") or REPO / ".cache" / "slicer-peer")


class PeerUnavailableError(Exception):
    """The peer cannot be had here: the message says why."""


def peer_python(prefix: Path = PREFIX, *, log: Optional[Path] = None,
                timeout: float = 1800.0) -> Path:
    """The peer's Python, built (or brought up to date) first; PeerUnavailableError when
    the build script is absent or the build fails (the end of its output in the message)."""
    if not BUILD_SCRIPT.exists():
        raise PeerUnavailableError(f"no {BUILD_SCRIPT} (the shared Slicer connector peer)")
    log = log or prefix.parent / "slicer-peer-build.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("wb") as out:
        try:
            code = subprocess.run(["bash", str(BUILD_SCRIPT), str(prefix)], stdout=out,
                                  stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                  timeout=timeout).returncode
        except subprocess.TimeoutExpired:
            code = -1
    python = prefix / "venv" / "bin" / "python"
    if code != 0 or not python.exists():
        tail = log.read_text(errors="replace")[-1500:]
        raise PeerUnavailableError(f"building the Slicer peer failed (exit {code}; {log}):\n"
                                   f"{tail}")
    try:
        build_mrml_library(prefix, python, log)
    except (LibraryBuildError, OSError, subprocess.SubprocessError) as error:
        raise PeerUnavailableError(f"building the ROS2Bridge MRML library failed: {error}") \
            from error
    return python
