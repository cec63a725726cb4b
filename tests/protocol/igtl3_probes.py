"""Small programs built against the OpenIGTLink 3.1 library 3D Slicer links, as the
real-Slicer tier builds it into .cache/slicer-peer/igtl (../shared/peers/
slicer-openigtlinkif/build.sh; SLICER_PEER_PREFIX: another checkout's): each is built from
tests/protocol/cpp/<source>.cxx into .cache/igtl3-probe/ when its source is newer; with
``igtlio``, also against OpenIGTLinkIO's converters and VTK as the tier builds them
(build-igtlio, vtk-sdk); the build is made here first when these tests come before the tier.
A test that needs one skips, saying why, when that build or a C++ compiler is absent."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from tools.slicer_core.peer import PREFIX as PEER  # .cache/slicer-peer, or SLICER_PEER_PREFIX
from tools.slicer_core.peer import PeerUnavailableError, peer_python

REPO = Path(__file__).resolve().parents[2]
IGTL3 = PEER / "igtl"
IGTLIO_SOURCES = PEER / "src" / "OpenIGTLinkIO" / "Converter"
IGTLIO_BUILD = PEER / "build-igtlio"
VTK_SDK = PEER / "vtk-sdk"
SOURCES = Path(__file__).resolve().parent / "cpp"
BUILT = REPO / ".cache" / "igtl3-probe"


def _igtlio_flags() -> list[str]:
    """Compiler flags for OpenIGTLinkIO's converters and VTK, or a skip saying why not."""
    headers = sorted(VTK_SDK.glob("vtk-*.data/headers/vtk-*"))
    libs = sorted(VTK_SDK.glob("build/lib.*/vtkmodules"))
    if not ((IGTLIO_BUILD / "lib" / "libigtlioConverter.so").exists() and headers and libs
            and (IGTLIO_SOURCES / "igtlioPolyDataConverter.h").exists()):
        pytest.skip(f"OpenIGTLinkIO and VTK are not built in {PEER} (the real-Slicer tier "
                    "builds them)")
    igtlio_lib = IGTLIO_BUILD / "lib"
    return ["-DIGTLIO_CONVERTER", f"-I{headers[-1]}", f"-I{IGTLIO_SOURCES}",
            f"-I{IGTLIO_BUILD / 'Converter'}", f"-L{igtlio_lib}", "-ligtlioConverter",
            f"-L{libs[-1]}", "-lvtkCommonDataModel", "-lvtkCommonCore", "-lvtksys",
            f"-Wl,-rpath,{igtlio_lib}:{libs[-1]}"]


def igtl3_probe(source_name: str, *, igtlio: bool = False) -> Path:
    """The probe built from `source_name` (now if needed), with OpenIGTLinkIO's converters
    if `igtlio`, or a skip saying why it cannot be."""
    lib = IGTL3 / "lib" / "igtl"
    if not (lib / "libOpenIGTLink.so").exists():
        try:  # built here when these tests run before the real-Slicer tier (a fresh clone)
            peer_python()
        except PeerUnavailableError as error:
            pytest.skip(str(error))
    if not (lib / "libOpenIGTLink.so").exists():
        pytest.skip(f"OpenIGTLink 3 is not built at {IGTL3} (the real-Slicer tier builds it "
                    "with ../shared/peers/slicer-openigtlinkif/build.sh .cache/slicer-peer)")
    if shutil.which("c++") is None:
        pytest.skip("building the OpenIGTLink 3 probe needs c++")
    extra = _igtlio_flags() if igtlio else []
    source = SOURCES / f"{source_name}.cxx"
    probe = BUILT / (source_name + ("_igtlio" if igtlio else ""))
    if not probe.exists() or probe.stat().st_mtime < source.stat().st_mtime:
        probe.parent.mkdir(parents=True, exist_ok=True)
        # The tier's libraries are built with the pre-C++11 string ABI (as the wheels are).
        result = subprocess.run(
            ["c++", "-O1", "-D_GLIBCXX_USE_CXX11_ABI=0", f"-I{IGTL3 / 'include' / 'igtl'}",
             str(source), "-o", str(probe), f"-L{lib}", "-lOpenIGTLink",
             f"-Wl,-rpath,{lib}", *extra], capture_output=True, text=True, timeout=300,
            check=False)
        if result.returncode != 0:
            pytest.fail(f"building {source.name} failed:\n{result.stderr[-3000:]}")
    return probe
