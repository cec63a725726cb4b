"""Coverage of the compiled modules' Cython sources (issue 44: "the .pyx files are not in
coverage"; `make coverage` measures Python only). Their traced build (tools/native_coverage.py,
cached under .cache/native-coverage/) runs the native modules' own tests under coverage with
Cython's plugin; each .pyx is held to a floor, and the rules copied into C from protocol/
(the stamp rule, CRC-64, the framing of header versions 1 and 2) must be among the lines
run."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path
from typing import Iterator

import pytest

from support import REPO, scaled
from tools import native_coverage
from tools.native_coverage import FileCoverage, Measured

pytestmark = pytest.mark.integration  # builds the traced modules, runs tests in a child

# Each file's share of traced lines run, in percent: a test that stops reaching part of the
# C fails here. Measured (2026-11-29): _native_stream 95.6, _compiled_store 92.1 to 94.4 (its
# property tests draw other examples each run), _rcl_reader 76.1; the floors leave room for
# what depends on the host (io_uring allowed or not), on timing (which thread takes a
# message, when a socket is full) or on the examples drawn.
FLOORS = {
    "bridge/core/_native_stream.pyx": 93,
    "bridge/tf/_compiled_store.pyx": 89,
    "bridge/ros/_rcl_reader.pyx": 73,
}
# The native lane's lines (found by their text, so they move with the file) that must have
# run: the rules it copies from protocol/, and what it leaves to Python.
LANE = "bridge/core/_native_stream.pyx"
RULES = [
    # protocol/conversions.py's igtl_stamp_or_now: a stamp kept, a bad one (0, negative,
    # past 2**32 - 1 s or a nanosec of a second or more) replaced by the time now.
    "return _igtl_timestamp(<uint64_t>sec, <uint64_t>nanosec)",
    "now = _now_ns(CLOCK_REALTIME)",
    # protocol/crc64.py.
    "crc = (crc << 8) ^ CRC_TABLE[((crc >> 56) ^ data[i]) & 0xFF]",
    # protocol/framing.py: the v2 frame (extended header, metadata), the v1 frame.
    "_put_u32(p + HEADER_SIZE + 8, <uint32_t>clock)",
    "p = lane.buffer + _v1_offset(lane)",
    "_put_u64(p + 50, _crc64(p + HEADER_SIZE, body))",
    # A frame a client took in part: its rest kept for the loop.
    "memcpy(slot.stash + at, <uint8_t *>parts[i].iov_base + skip, take)",
]
# Conditions whose branch (the next line) must have run: what the lane leaves to Python.
BRANCHES = [
    "if frame_size != lane.frame_size or child_size != lane.child_size:",  # other frame ids
    "if not isfinite(norm2) or norm2 < 1e-24:",  # a rotation it cannot normalise
    "if not (-_FLOAT32_BOUND < values[i] < _FLOAT32_BOUND):",  # not a finite float32 in mm
    "if fanout.hold or not lane.enabled or lane.settle:",  # values waiting for the loop
    "if not _lock(&slots[i].lock, wait):",  # a client's lock held: BUSY
    "if lane.own_slots:",  # a device limited to its audience: the lane's own clients
]


def production_modules() -> list[str]:
    """The compiled modules this install has (setup.py builds each where it can)."""
    return [name for name in native_coverage.MODULES if importlib.util.find_spec(name)]


@pytest.fixture(scope="module")
def measured(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Measured]:
    if not production_modules():
        pytest.skip("no compiled module is built here (no Cython or C compiler)")
    try:
        tree = native_coverage.build()
    except native_coverage.NativeCoverageUnavailable as error:
        pytest.skip(f"the traced modules cannot be built here: {error}")
    yield native_coverage.measure(tree, native_coverage.default_tests(),
                                  tmp_path_factory.mktemp("native-coverage"),
                                  timeout=scaled(300))


def line_of(path: str, text: str) -> int:
    """The number of the one line of ``path`` that holds ``text``."""
    found = [number for number, line in
             enumerate((REPO / path).read_text().splitlines(), start=1) if text in line]
    assert len(found) == 1, f"{text!r} in {path}: expected on one line, found on {found}"
    return found[0]


def test_the_native_tests_pass_against_the_traced_modules(measured: Measured) -> None:
    log = measured.log.read_text()
    assert measured.exit_status == 0, log[-6000:]
    summary = log.rstrip().splitlines()[-1]
    assert re.search(r"\b[1-9]\d* passed\b", summary), summary
    assert "failed" not in summary and "error" not in summary, summary


def test_the_traced_modules_were_the_ones_imported(measured: Measured) -> None:
    expected = production_modules()
    assert sorted(measured.modules) == sorted(expected)
    for name, file in measured.modules.items():
        path = Path(file)
        assert native_coverage.CACHE in path.parents, f"{name} came from {file}"
        assert path.name.endswith(native_coverage.EXT_SUFFIX)
        assert path.with_name(path.name.split(".")[0] + ".c").is_file()  # the plugin's map


@pytest.mark.parametrize("path", sorted(FLOORS))
def test_each_pyx_is_run_to_its_floor(measured: Measured, path: str) -> None:
    module = path[:-len(".pyx")].replace("/", ".")
    if module not in production_modules():
        pytest.skip(f"{module} is not built here")
    file = measured.files[path]
    # The plugin's executable lines are the .pyx's own: each holds code, not a comment
    # (but line 1, where Cython traces the module's import).
    source = (REPO / path).read_text().splitlines()
    assert len(file.statements) > 200 and 1 in file.executed
    assert all(source[line - 1].strip() and not source[line - 1].lstrip().startswith("#")
               for line in file.statements - {1})
    assert file.percent >= FLOORS[path], (
        f"{path}: {file.percent:.1f}% of {len(file.statements)} traced lines run, floor "
        f"{FLOORS[path]}%; not run: {native_coverage.ranges(file.missing)}")


@pytest.fixture(scope="module")
def lane(measured: Measured) -> FileCoverage:
    if "bridge.core._native_stream" not in production_modules():
        pytest.skip("the native lane is not built here")
    return measured.files[LANE]


@pytest.mark.parametrize("text", RULES)
def test_the_rules_copied_into_the_lane_are_run(lane: FileCoverage, text: str) -> None:
    line = line_of(LANE, text)
    assert line in lane.statements, f"{LANE}:{line} is not a traced line: {text}"
    assert line in lane.executed, f"{LANE}:{line} never ran: {text}"


@pytest.mark.parametrize("text", BRANCHES)
def test_what_the_lane_leaves_to_python_is_run(lane: FileCoverage, text: str) -> None:
    line = line_of(LANE, text)
    assert {line, line + 1} <= lane.executed, f"{LANE}:{line}'s branch never ran: {text}"
