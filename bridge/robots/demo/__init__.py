"""The built-in demo robot: a 6-axis arm with a gripper (see `bridge.robots.demo.urdf`).

`demo_urdf_path()` writes, at first use, a small ROS-style package into a cache folder::

    <cache>/slicer_ros2_bridge_demo/package.xml
    <cache>/slicer_ros2_bridge_demo/urdf/demo_arm.urdf
    <cache>/slicer_ros2_bridge_demo/meshes/{shoulder.stl, upper_arm.obj, forearm.dae, wrist_2.stl}

and returns the URDF path with the ``package_paths`` that resolve its
``package://slicer_ros2_bridge_demo/...`` URIs. The default cache is
``$XDG_CACHE_HOME/slicer-ros2-bridge/demo-<hash>`` (``~/.cache/...``); the hash covers the
URDF text and the generator, so a changed robot lands in a new folder. A folder is written
under a temporary name and renamed into place, so two processes starting at once are safe.
"""

from __future__ import annotations

import hashlib
import inspect
import os
import shutil
import tempfile
from pathlib import Path
from typing import Optional

from bridge.robots.cache_folder import user_cache_dir
from bridge.robots.demo import meshgen
from bridge.robots.demo.urdf import DEMO_PACKAGE, DEMO_URDF

__all__ = ["DEMO_PACKAGE", "DEMO_URDF", "demo_urdf_path"]

_URDF_NAME = "demo_arm.urdf"
_PACKAGE_XML = f"""<?xml version="1.0"?>
<package format="3">
  <name>{DEMO_PACKAGE}</name>
  <version>0.1.0</version>
  <description>Demo arm of slicer-ros2-bridge (generated; safe to delete).</description>
  <maintainer email="noreply@example.com">slicer-ros2-bridge</maintainer>
  <license>MIT</license>
</package>
"""


def _content_hash() -> str:
    digest = hashlib.sha256(DEMO_URDF.encode())
    digest.update(inspect.getsource(meshgen).encode())
    return digest.hexdigest()[:12]


def _write_package(root: Path) -> None:
    package = root / DEMO_PACKAGE
    (package / "urdf").mkdir(parents=True)
    (package / "package.xml").write_text(_PACKAGE_XML)
    (package / "urdf" / _URDF_NAME).write_text(DEMO_URDF)
    meshgen.write_meshes(package / "meshes")


def demo_urdf_path(cache_dir: Optional[Path] = None) -> tuple[Path, dict[str, Path]]:
    """(path of the demo URDF, package_paths for it); generates the files on first use.

    ``cache_dir``: where to keep them (default `user_cache_dir()`); a folder
    ``demo-<hash>`` is made inside it.
    """
    base = Path(cache_dir) if cache_dir is not None else user_cache_dir()
    target = base / f"demo-{_content_hash()}"
    package = target / DEMO_PACKAGE
    urdf = package / "urdf" / _URDF_NAME
    if not urdf.is_file():
        base.mkdir(parents=True, exist_ok=True)
        scratch = Path(tempfile.mkdtemp(prefix=".demo-", dir=base))
        try:
            _write_package(scratch)
            try:
                os.rename(scratch, target)  # atomic: readers never see half a package
            except OSError:
                if not urdf.is_file():  # not a lost race: a real failure
                    raise
        finally:
            shutil.rmtree(scratch, ignore_errors=True)
    return urdf, {DEMO_PACKAGE: package}
