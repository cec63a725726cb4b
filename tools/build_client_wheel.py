#!/usr/bin/env python3
"""Build the client's own wheel: `slicer_client` and `protocol`, numpy only, Python 3.9+.

    python3 tools/build_client_wheel.py [--out DIR]     # default: dist/
    python3 tools/build_client_wheel.py --player        # the player's wheel instead

`--player` builds `slicer-ros2-bridge-player`: `slicer-ros2-bridge-play BAG.mcap` without
ROS (the daemon's packages, pure Python, with the bag reader; no ROS 2 wheel).

The wheel installs into 3D Slicer's Python (`slicer.util.pip_install("/path/to.whl")`) or
any other. The daemon's wheel (`pip wheel .`) holds the same packages plus the daemon.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# name -> (packaging folder, packages, the wheel's file name prefix)
WHEELS = {
    "client": (REPO / "packaging" / "client", ("protocol", "slicer_client"),
               "slicer_ros2_bridge_client"),
    "player": (REPO / "packaging" / "player", ("protocol", "slicer_client", "bridge"),
               "slicer_ros2_bridge_player"),
}


def build(out: Path, wheel: str = "client") -> Path:
    """Stage the packages beside the wheel's pyproject.toml and build; the wheel's path."""
    packaging, packages, prefix = WHEELS[wheel]
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=f"{wheel}-wheel-") as scratch:
        stage = Path(scratch)
        shutil.copy(packaging / "pyproject.toml", stage)
        shutil.copy(REPO / "slicer_client" / "README.md", stage / "README.md")
        # Compiled modules and their sources stay out: each has a Python fallback.
        ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "slicer_module", "*.so",
                                        "*.c", "*.pyx", "*.pyi", "*.h")
        for package in packages:
            shutil.copytree(REPO / package, stage / package, ignore=ignore)
        before = set(out.glob("*.whl"))
        subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet",
                        "--wheel-dir", str(out), str(stage)], check=True)
    made = sorted(set(out.glob(f"{prefix}-*.whl")) - before) or \
        sorted(out.glob(f"{prefix}-*.whl"))
    return made[-1]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "dist",
                        help="folder for the wheel (default: dist/)")
    parser.add_argument("--player", action="store_true",
                        help="build the player's wheel (play bags without ROS) instead")
    args = parser.parse_args()
    try:
        wheel = build(args.out, "player" if args.player else "client")
    except subprocess.CalledProcessError as error:
        print(f"build_client_wheel: pip wheel failed with exit code {error.returncode}",
              file=sys.stderr)
        return 1
    print(wheel)
    return 0


if __name__ == "__main__":
    sys.exit(main())
