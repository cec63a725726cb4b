"""Where the robot code keeps files between runs (the demo robot's package, meshes read)."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["user_cache_dir"]


def user_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/slicer-ros2-bridge`` (default ``~/.cache/slicer-ros2-bridge``)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "slicer-ros2-bridge"
