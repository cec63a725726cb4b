"""Interop with the OpenIGTLink library 3D Slicer links (3.1, 94244fed): texture coordinates,
and TDATA both ways (cpp/igtl_tdata_probe.cxx).

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

from protocol.framing import Decoder, encode
from protocol.messages import (AttributeKind, Message, PolyData, RawBody, TrackerKind,
                               TrackingData, TrackingElement, cells_to_list)
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


# ------------------------------------------------------------------ TDATA (a robot's poses)

def test_tdata_both_ways_with_the_library_slicer_links() -> None:
    """A robot's link poses go as one TDATA: the C++ library reads ours element by element
    (CRC checked), and ours reads the library's."""
    probe = igtl3_probe("igtl_tdata_probe")
    packed = subprocess.run([str(probe), "pack"], capture_output=True, timeout=30,
                            check=True).stdout
    decoder = Decoder()
    decoder.feed(packed)
    (message,) = list(decoder.messages())
    assert message.type_name == "TDATA" and message.device_name == "poses:demo"
    assert isinstance(message.body, TrackingData)
    tool, ref = message.body.elements
    assert (tool.name, tool.kind, ref.name, ref.kind) == ("tool", TrackerKind.INSTRUMENT_6D,
                                                          "ref", TrackerKind.TRACKER)
    expected = np.eye(4)
    expected[:3, 3] = (1, 2, 3)
    expected[0, 1] = 0.5
    np.testing.assert_array_equal(tool.matrix, expected)
    np.testing.assert_array_equal(ref.matrix, np.eye(4))

    moved = np.eye(4)
    moved[:3, 3] = (10.5, -20.25, 300.0)
    moved[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    ours = encode(Message("poses:demo", TrackingData([
        TrackingElement("demo:base_link", np.eye(4)), TrackingElement("demo:tool_flange", moved)
    ])), header_version=1)
    lines = subprocess.run([str(probe), "unpack"], input=ours, capture_output=True,
                           timeout=30, check=True).stdout.decode().splitlines()
    assert [line.split()[:2] for line in lines] == [["demo:base_link", "2"],
                                                    ["demo:tool_flange", "2"]]
    got = [np.array([float(v) for v in line.split()[2:]]).reshape(3, 4) for line in lines]
    np.testing.assert_array_equal(got[0], np.eye(4)[:3])
    np.testing.assert_array_equal(got[1], moved[:3])
    # Why a name has 19 bytes at most: the library reads one of 20 (no NUL) as empty.
    element = TrackingData([TrackingElement("x" * 19, moved)]).pack()
    twenty = element[:19] + b"x" + element[20:]  # its NUL padding made a 20th character
    full = encode(Message("poses:demo", RawBody("TDATA", twenty)), header_version=1)
    (line,) = subprocess.run([str(probe), "unpack"], input=full, capture_output=True,
                             timeout=30, check=True).stdout.decode().splitlines()
    assert line.startswith(" 2 ")  # the name lost, the rest read
