#!/usr/bin/env python3
"""Build the client's own wheel: `slicer_client` and `protocol`, numpy only, Python 3.9+.

    python3 tools/build_client_wheel.py [--out DIR]     # default: dist/

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
PACKAGING = REPO / "packaging" / "client"


def build(out: Path) -> Path:
    """Stage the packages beside packaging/client/pyproject.toml and build; the wheel's path."""
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="client-wheel-") as scratch:
        stage = Path(scratch)
        shutil.copy(PACKAGING / "pyproject.toml", stage)
        shutil.copy(REPO / "slicer_client" / "README.md", stage / "README.md")
        ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "slicer_module")
        for package in ("protocol", "slicer_client"):
            shutil.copytree(REPO / package, stage / package, ignore=ignore)
        before = set(out.glob("*.whl"))
        subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet",
                        "--wheel-dir", str(out), str(stage)], check=True)
    made = sorted(set(out.glob("slicer_ros2_bridge_client-*.whl")) - before) or \
        sorted(out.glob("slicer_ros2_bridge_client-*.whl"))
    return made[-1]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "dist",
                        help="folder for the wheel (default: dist/)")
    args = parser.parse_args()
    try:
        wheel = build(args.out)
    except subprocess.CalledProcessError as error:
        print(f"build_client_wheel: pip wheel failed with exit code {error.returncode}",
              file=sys.stderr)
        return 1
    print(wheel)
    return 0


if __name__ == "__main__":
    sys.exit(main())
