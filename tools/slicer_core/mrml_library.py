"""The ROS2Bridge extension's MRML library (the reference's node classes,
slicer_client/slicer_module/ROS2BridgeMRML) built into the test peer's Python, as 3D Slicer's
extension build would make it: `import slicer` then has `slicer.vtkMRMLROS2NodeNode`... The
build is skipped when its inputs did not change (a stamp of their contents)."""

from __future__ import annotations

import hashlib
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
CLASSES = REPO / "slicer_client" / "slicer_module" / "ROS2BridgeMRML"
CMAKE_PROJECT = Path(__file__).resolve().parent / "mrml_library"
PACKAGE = "slicer_ros2bridge_mrml"

PACKAGE_INIT = '''"""The ROS2Bridge extension's MRML node classes, built for slicer-core by
tools/slicer_core/mrml_library.py. `import slicer` also gives them (slicer/{package}.py), as 3D
Slicer puts a module library's wrapped classes in its `slicer` namespace."""
import slicer_core  # noqa: F401  (the MRML classes these derive from, registered first)
from .vtkSlicerROS2BridgeModuleMRMLPython import *  # noqa: F401,F403
'''


class LibraryBuildError(Exception):
    """The library did not build: the message has the end of the build's output."""


def _stamp() -> str:
    digest = hashlib.sha256()
    for path in sorted([*CLASSES.iterdir(), *CMAKE_PROJECT.iterdir()]):
        if path.is_file():
            digest.update(path.name.encode() + path.read_bytes())
    return digest.hexdigest()


def build_mrml_library(prefix: Path, python: Path, log: Path) -> None:
    """Build and install the library into the peer at `prefix` (whose Python is `python`),
    unless the last build there had the same inputs."""
    stamp_file = prefix / "ros2bridge-mrml.stamp"
    stamp = _stamp()
    site = subprocess.run(
        [str(python), "-c", "import sysconfig as s; print(s.get_paths()['purelib']); "
         "print(s.get_paths()['include']); print(s.get_config_var('EXT_SUFFIX'))"],
        check=True, capture_output=True, text=True).stdout.split("\n")
    package_dir = Path(site[0]) / PACKAGE
    if (stamp_file.exists() and stamp_file.read_text() == stamp
            and (package_dir / "__init__.py").exists()):
        return
    # In this checkout: a peer another checkout built (SLICER_PEER_PREFIX) keeps its own.
    build = REPO / ".cache" / "build-ros2bridge-mrml"
    sdk = prefix / "vtk-sdk"
    configure = ["cmake", "-S", str(CMAKE_PROJECT), "-B", str(build),
                 "-DCMAKE_BUILD_TYPE=Release", f"-DSITE={site[0]}",
                 f"-DVTK_DIR={sdk / 'vtk-9.6.2.data' / 'headers' / 'cmake'}",
                 f"-DVTK_WRAP_BIN={sdk / 'bin'}", f"-DPYTHON_INCLUDE={site[1]}",
                 f"-DPYTHON_EXT_SUFFIX={site[2]}"]
    with log.open("ab") as out:
        for command in (configure, ["cmake", "--build", str(build), "-j", "2"],
                        ["cmake", "--install", str(build)]):
            if subprocess.run(command, stdout=out, stderr=subprocess.STDOUT,
                              stdin=subprocess.DEVNULL).returncode != 0:
                tail = log.read_text(errors="replace")[-1500:]
                raise LibraryBuildError(f"{' '.join(command[:3])} failed ({log}):\n{tail}")
    (package_dir / "__init__.py").write_text(PACKAGE_INIT.format(package=PACKAGE))
    # slicer-core's `slicer` package imports each slicer/slicer_*.py and re-exports its names
    (Path(site[0]) / "slicer" / f"{PACKAGE}.py").write_text(
        f"from {PACKAGE} import *  # noqa: F401,F403\n")
    stamp_file.write_text(stamp)
