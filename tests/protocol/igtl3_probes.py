"""Small programs built against the OpenIGTLink 3.1 library 3D Slicer links, as the
real-Slicer tier builds it into .cache/slicer-peer/igtl (../shared/peers/
slicer-openigtlinkif/build.sh): each is built from tests/protocol/cpp/<name>.cxx into
.cache/igtl3-probe/ when its source is newer. A test that needs one skips, saying why,
when that build or a C++ compiler is absent."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
IGTL3 = REPO / ".cache" / "slicer-peer" / "igtl"
SOURCES = Path(__file__).resolve().parent / "cpp"
BUILT = REPO / ".cache" / "igtl3-probe"


def igtl3_probe(name: str) -> Path:
    """The probe `name` (built now if needed), or a skip saying why it cannot be."""
    lib = IGTL3 / "lib" / "igtl"
    if not (lib / "libOpenIGTLink.so").exists():
        pytest.skip(f"OpenIGTLink 3 is not built at {IGTL3} (the real-Slicer tier builds it "
                    "with ../shared/peers/slicer-openigtlinkif/build.sh .cache/slicer-peer)")
    if shutil.which("c++") is None:
        pytest.skip("building the OpenIGTLink 3 probe needs c++")
    source, probe = SOURCES / f"{name}.cxx", BUILT / name
    if not probe.exists() or probe.stat().st_mtime < source.stat().st_mtime:
        probe.parent.mkdir(parents=True, exist_ok=True)
        # The tier's libraries are built with the pre-C++11 string ABI (as the wheels are).
        result = subprocess.run(
            ["c++", "-O1", "-D_GLIBCXX_USE_CXX11_ABI=0", f"-I{IGTL3 / 'include' / 'igtl'}",
             str(source), "-o", str(probe), f"-L{lib}", "-lOpenIGTLink",
             f"-Wl,-rpath,{lib}"], capture_output=True, text=True, timeout=300, check=False)
        if result.returncode != 0:
            pytest.fail(f"building {source.name} failed:\n{result.stderr[-3000:]}")
    return probe
