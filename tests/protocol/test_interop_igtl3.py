"""Interop with the OpenIGTLink library 3D Slicer links (3.1, 94244fed): texture coordinates.

Debian's OpenIGTLink 1.11 has no TCOORDS attribute (its SetType refuses 5), so the encoder
here is OpenIGTLink 3.1 as the real-Slicer tier builds it into .cache/slicer-peer/igtl
(../shared/peers/slicer-openigtlinkif/build.sh). A small program (cpp/igtl_tcoords_probe.cxx)
packs a textured cube the way OpenIGTLinkIO's converter does; our decoder reads its bytes
(header, CRC and body). The test skips, saying why, when that build is absent.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from protocol.framing import Decoder
from protocol.messages import AttributeKind, PolyData, cells_to_list
from tests.protocol.igtl3_probes import igtl3_probe
from tests.protocol.igtl_captures import CUBE_CORNERS_MM, CUBE_QUADS

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def probe() -> Path:
    return igtl3_probe("igtl_tcoords_probe")


def _decode(probe: Path, where: str) -> PolyData:
    raw = subprocess.run([str(probe), where], capture_output=True, timeout=30,
                         check=True).stdout
    decoder = Decoder()
    decoder.feed(raw)
    (message,) = list(decoder.messages())  # CRC checked
    assert message.type_name == "POLYDATA" and message.device_name == "Cube"
    assert isinstance(message.body, PolyData)
    return message.body


@pytest.mark.parametrize("where, rows", [("point", 8), ("cell", 6)])
def test_openigtlink3_textured_cube_decodes(probe: Path, where: str, rows: int) -> None:
    """Issue 42 (6): the cube Slicer sends with TCoords (TYPE 0x05 / 0x15, which the library
    packs with NCOMPONENTS 9 and 9 floats a row) decodes: points, quads, and TCoords as the
    (u, v, 0) rows OpenIGTLink 3's own reader takes."""
    body = _decode(probe, where)
    assert body.points.tolist() == CUBE_CORNERS_MM
    assert [c.tolist() for c in cells_to_list(body.polygons)] == CUBE_QUADS
    (tcoords,) = body.attributes
    assert (tcoords.name, tcoords.kind) == ("TCoords", AttributeKind.TCOORDS)
    assert tcoords.on_cells == (where == "cell")
    np.testing.assert_array_equal(tcoords.data, [[0.25 * j, 0.5, 0.0] for j in range(rows)])
