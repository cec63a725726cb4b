"""The daemon (`bridge.cli` with the given arguments) whose ROS teardown hangs, as Fast
DDS's participant teardown was seen to: `RosNode.stop` prints TEARDOWN HANGS, then blocks
inside C code, with the GIL released (``--hang released``, the Python watchdog's case) or
held (``--hang held``: no Python thread can run; faulthandler's case).

usage: hanging_teardown_daemon.py --hang {released,held} run --port P [daemon options]
"""

import ctypes
import sys

from bridge import cli
from bridge.ros.ros_node import RosNode


def main() -> int:
    mode = sys.argv[2] if sys.argv[1:2] == ["--hang"] else ""
    if mode not in ("released", "held"):
        print(__doc__, file=sys.stderr)
        return 2
    # CDLL calls drop the GIL, PyDLL calls keep it; libc's pause() returns only on a
    # signal whose handler returns, which a stopping daemon never installs.
    libc = ctypes.CDLL(None) if mode == "released" else ctypes.PyDLL(None)

    def stop(self: RosNode) -> None:
        print("TEARDOWN HANGS", flush=True)
        while True:
            libc.pause()

    RosNode.stop = stop  # type: ignore[method-assign]
    return cli.main(sys.argv[3:])


if __name__ == "__main__":
    sys.exit(main())
