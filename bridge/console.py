"""The `slicer-ros2-bridge` command's entry point (and `ros2 run`'s executables).

Its only import is the standard library's `sys`, so a Ctrl-C that comes while the command
is still importing or starting (a second or two, more on a busy machine), before the
daemon's own signal handling is in place, ends it with one line and exit code 0, as a stop
later does, and not with a traceback.
"""

from __future__ import annotations

import sys
from typing import Optional


def main(argv: Optional[list[str]] = None) -> int:
    try:
        from bridge.cli import main as run

        return run(argv)
    except KeyboardInterrupt:
        print("slicer-ros2-bridge: stopped (Ctrl-C) while starting", file=sys.stderr)
        return 0


if __name__ == "__main__":
    sys.exit(main())
