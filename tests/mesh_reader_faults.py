"""Mesh reader processes that fail (tests/bridge/test_mesh_readers.py): a reader runs a
function it finds by module name, so these live outside the test module."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Optional

from bridge.robots.mesh_readers import read_mesh
from bridge.robots.meshes import MeshData

CRASH_EXIT_CODE = 70


def die_on_crash_files(path: str, scale: tuple[float, ...],
                       max_triangles: Optional[int]) -> MeshData:
    """The reader process ends at once (as a parser's crash would end it) for a file whose
    name starts with "crash"; others are read as usual."""
    if Path(path).name.startswith("crash"):
        os._exit(CRASH_EXIT_CODE)
    return read_mesh(path, scale, max_triangles)
