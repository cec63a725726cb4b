"""SlicerROS2's ROS2Tests.py in a real MRML scene: run by run.py --real-slicer in the Slicer
peer's Python (tools/slicer_core), as `real_scene.py SUITE PORT`.

The ROS2Bridge module is loaded as Slicer loads it (open_session: its entry points are
installed at startupCompleted), connected to the daemon at 127.0.0.1:PORT as a user's
Connect does; then the suite file is imported as it is, with the real `slicer` and `vtk`,
and its five classes run (run.run_suite_file). Exit code 0 only if every case passed.

One more imitation than tools/slicer_core's: ``slicer.util.pip_install`` (the suite calls it
when ``import psutil`` fails) needs Slicer's ``slicer.packaging``, which slicer-core lacks;
here it installs with pip into .cache/reference-suite-site, on sys.path, as Slicer installs
into its own Python.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from tools.reference_suite.run import run_suite_file  # noqa: E402
from tools.slicer_core.session import open_session  # noqa: E402

CONNECT_WAIT_S = 30.0
SITE = REPO / ".cache" / "reference-suite-site"


def pip_install(requirements: str) -> None:
    """Slicer's slicer.util.pip_install, into SITE (see above)."""
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--target", str(SITE),
                    *requirements.split()], check=True)


def main() -> int:
    suite, port = Path(sys.argv[1]), int(sys.argv[2])
    session = open_session()
    import slicer
    sys.path.append(str(SITE))
    slicer.util.pip_install = pip_install
    try:
        logic = session.logic
        logic.connect("127.0.0.1", port)
        session.pump(CONNECT_WAIT_S, until=lambda: logic.client is not None,
                     what="the module's client")
        return run_suite_file(suite, "slicer-ros2-bridge in a real MRML scene")
    finally:
        session.close()


if __name__ == "__main__":
    sys.exit(main())
