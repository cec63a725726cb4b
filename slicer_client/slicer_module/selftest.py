"""Self-test of the ROS2Bridge module, run INSIDE 3D Slicer:

    Slicer --no-main-window --python-script slicer_client/slicer_module/selftest.py

The module's client packages must be installed as for the module itself (the extension,
or the client wheel: see the module's docstring); without them the import below says how.
Optional: start the daemon first (`slicer-ros2-bridge run --port 18944`) and set
ROS2BRIDGE_TEST_PORT=18944 to also test the round trip through Slicer's connector.
Exit code 0 = every test passed, 1 = a failure (printed), 2 = not run inside Slicer.
"""

import os
import sys
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))


def main() -> int:
    try:
        import slicer
    except ImportError:
        slicer = None
    # Slicer's Qt-free core (slicer-core on PyPI) also imports as `slicer`: inside 3D
    # Slicer there is an application, `slicer.app`, which the module's GUI needs.
    if getattr(slicer, "app", None) is None:
        where = "slicer imports, but has no slicer.app (not 3D Slicer's application)" \
            if slicer is not None else "no slicer module"
        print(f"selftest.py runs inside 3D Slicer ({where}): Slicer --no-main-window "
              f"--python-script {os.path.abspath(__file__)}", file=sys.stderr)
        return 2
    # The module's folder, as Slicer puts it on sys.path when it loads the module itself.
    module_dir = os.path.join(HERE, "ROS2Bridge")
    sys.path.insert(0, module_dir)
    import ROS2Bridge  # noqa: E402

    try:
        ROS2Bridge.ROS2BridgeTest().runTest()
    except Exception:  # noqa: BLE001 - reported and turned into the exit code
        traceback.print_exc()
        print("ROS2Bridge self-test FAILED")
        return 1
    print("ROS2Bridge self-test passed")
    return 0


if __name__ == "__main__":
    code = main()
    try:
        import slicer
    except ImportError:
        slicer = None
    if getattr(slicer, "app", None) is not None:
        slicer.util.exit(code)  # ends 3D Slicer itself with the code
    sys.exit(code)
