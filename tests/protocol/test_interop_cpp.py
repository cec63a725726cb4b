"""Interop with an independent implementation: Debian's OpenIGTLink 1.11 C++ examples.

The examples (package openigtlink-examples, sources only) are built once into
.cache/igtl-examples/ (git-ignored, reused by later runs), together with a small probe
(cpp/igtl_image_probe.cxx) that prints the IMAGE geometry the C++ library decodes. Tests
skip, saying why, when the packages are absent.

Every child is started through the `processes` fixture (stopped at teardown); every socket
operation and every wait has a timeout.
"""

from __future__ import annotations

import gzip
import math
import re
import shutil
import socket
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from support import Processes, pick_free_port, wait_until

from protocol.conversions import igtl_timestamp_from_ros, ros_time_from_igtl
from protocol.framing import Decoder, encode
from protocol.messages import (
    AttributeKind,
    Image,
    Message,
    Point,
    PointElement,
    PolyData,
    PolyDataAttribute,
    RawBody,
    Status,
    StatusCode,
    String,
    Transform,
    cells_from_array,
)

pytestmark = pytest.mark.interop

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = Path("/usr/share/doc/openigtlink-examples/examples")
CONFIG_DIR = Path("/usr/lib/openigtlink")
BUILD = REPO / ".cache" / "igtl-examples"
PROBE_SOURCE = Path(__file__).resolve().parent / "cpp" / "igtl_image_probe.cxx"
TARGETS = {
    "ReceiveClient": "Receiver/ReceiveClient",
    "ReceiveServer": "Receiver/ReceiveServer",
    "TrackerServer": "Tracker/TrackerServer",
    "StringEchoServer": "String/StringEchoServer",
    "PolyDataClient": "PolyData/PolyDataClient",
}
TIMEOUT = 20.0


def _run(argv: list[str], cwd: Path, log: Path, timeout: float) -> None:
    with log.open("wb") as out:
        result = subprocess.run(argv, cwd=cwd, stdout=out, stderr=subprocess.STDOUT,
                                timeout=timeout, check=False)
    if result.returncode != 0:
        pytest.fail(f"{' '.join(argv)} failed ({result.returncode}):\n"
                    f"{log.read_text(errors='replace')[-3000:]}")


@pytest.fixture(scope="session")
def igtl_examples() -> dict[str, Path]:
    """Paths of the built C++ examples and of the probe (built once, then reused)."""
    if not EXAMPLES.is_dir() or not (CONFIG_DIR / "OpenIGTLinkConfig.cmake").exists():
        pytest.skip("Debian packages libopenigtlink-dev and openigtlink-examples are not "
                    "installed (apt-get install libopenigtlink-dev openigtlink-examples)")
    tools = {name: shutil.which(name) for name in ("cmake", "make", "c++")}
    missing = [name for name, path in tools.items() if path is None]
    if missing:
        pytest.skip(f"building the OpenIGTLink examples needs {', '.join(missing)}")
    BUILD.mkdir(parents=True, exist_ok=True)
    paths = {name: BUILD / rel for name, rel in TARGETS.items()}
    if not all(p.exists() for p in paths.values()):
        source = EXAMPLES
        if any(EXAMPLES.rglob("*.gz")):  # some Debian releases gzip the doc sources
            source = BUILD / "src"
            shutil.rmtree(source, ignore_errors=True)
            shutil.copytree(EXAMPLES, source)
            for packed in source.rglob("*.gz"):
                with gzip.open(packed, "rb") as fin:
                    packed.with_suffix("").write_bytes(fin.read())
                packed.unlink()
        _run(["cmake", str(source), f"-DOpenIGTLink_DIR={CONFIG_DIR}",
              "-DCMAKE_BUILD_TYPE=Release"], BUILD, BUILD / "cmake.log", 300)
        _run(["make", *TARGETS], BUILD, BUILD / "make.log", 1200)
    probe = BUILD / "probe" / "igtl_image_probe"
    if not probe.exists() or probe.stat().st_mtime < PROBE_SOURCE.stat().st_mtime:
        probe.parent.mkdir(exist_ok=True)
        _run(["c++", "-O1", "-I/usr/include/openigtlink", str(PROBE_SOURCE), "-o", str(probe),
              "-L/usr/lib", "-lOpenIGTLink"], BUILD, BUILD / "probe.log", 300)
    paths["probe"] = probe
    return paths


@contextmanager
def listening() -> Iterator[tuple[socket.socket, int]]:
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))  # port 0: the kernel picks a free one
    server.listen(1)
    server.settimeout(TIMEOUT)
    try:
        yield server, server.getsockname()[1]
    finally:
        server.close()


def connect_when_listening(port: int) -> socket.socket:
    """Connect to a C++ server that is starting up (it prints nothing when ready)."""
    holder: list[socket.socket] = []

    def attempt() -> bool:
        try:
            holder.append(socket.create_connection(("127.0.0.1", port), timeout=1.0))
            return True
        except OSError:
            return False

    wait_until(attempt, TIMEOUT, f"a server listening on port {port}")
    sock = holder[0]
    sock.settimeout(TIMEOUT)
    return sock


def receive(sock: socket.socket, decoder: Decoder, count: int) -> list[Message]:
    got: list[Message] = []
    while len(got) < count:
        data = sock.recv(65536)
        assert data, f"connection closed after {len(got)} of {count} messages"
        decoder.feed(data)
        got.extend(decoder.messages())
    return got


def wait_exit(child: object, timeout: float = TIMEOUT) -> None:
    child.popen.wait(timeout)  # type: ignore[attr-defined]


def floats(text: str) -> list[float]:
    return [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:e[-+]?\d+)?", text)]


def printed_matrices(output: str) -> list[np.ndarray]:
    """igtl::PrintMatrix blocks: '=============' then 4 rows 'a, b, c, d'."""
    rows = re.findall(r"^(-?[\d.e+-]+), (-?[\d.e+-]+), (-?[\d.e+-]+), (-?[\d.e+-]+)$",
                      output, re.MULTILINE)
    values = np.array(rows, dtype=np.float64)
    return [values[i:i + 4] for i in range(0, len(values) - len(values) % 4, 4)]


def field(output: str, label: str) -> list[str]:
    return [m.strip() for m in re.findall(rf"^\s*{re.escape(label)}\s*:(.*)$", output,
                                          re.MULTILINE)]


# ------------------------------------------------------------------ our encoder -> C++


def pose(tx: float, ty: float, tz: float) -> np.ndarray:
    angle = math.radians(30)
    matrix = np.eye(4)
    matrix[:3, :3] = [[math.cos(angle), -math.sin(angle), 0],
                      [math.sin(angle), math.cos(angle), 0], [0, 0, 1]]
    matrix[:3, 3] = (tx, ty, tz)
    return matrix


STAMP = igtl_timestamp_from_ros(1_700_000_000, 250_000_000)
IMAGE = Image(np.arange(4 * 5 * 6 * 3, dtype=np.uint8).reshape(4, 5, 6, 3),
              spacing=np.array([0.5, 0.75, 2.0]), origin=np.array([-10.0, 20.0, 5.5]))
POINTS = Point([
    PointElement("entry", "plan", (255, 0, 0, 255), np.array([1.5, -2.25, 3.0]), 4.0, "me"),
    PointElement("target", "plan", (0, 128, 255, 64), np.array([10.0, 20.0, -30.5]), 1.5, ""),
])


def outgoing() -> list[Message]:
    return [
        Message("Tool", Transform(pose(12.5, -3.0, 100.0)), STAMP),
        Message("Text", String("héllo wörld"), STAMP),
        Message("Ascii", String("plain", 3), STAMP),
        Message("State", Status(StatusCode.NOT_READY, -42, "WARMUP", "warming up"), STAMP),
        Message("Fiducials", POINTS, STAMP),
        Message("Volume", IMAGE, STAMP),
    ]


def check_receiver_output(output: str) -> None:
    sec, nanosec = ros_time_from_igtl(STAMP)
    assert sec == 1_700_000_000 and abs(nanosec - 250_000_000) <= 1
    stamps = re.findall(r"Time stamp: (\d+)\.(\d+)", output)
    assert len(stamps) == 6, output
    assert all(int(s) == sec and abs(int(ns) - nanosec) <= 1 for s, ns in stamps)

    (matrix,) = printed_matrices(output)
    np.testing.assert_allclose(matrix, pose(12.5, -3.0, 100.0), atol=2e-5)

    assert "Encoding: 106; String: héllo wörld" in output
    assert "Encoding: 3; String: plain" in output

    assert field(output, "Code") == ["13"]
    assert field(output, "SubCode") == ["-42"]
    assert field(output, "Error Name") == ["WARMUP"]
    assert field(output, "Status") == ["warming up"]

    assert field(output, "Name") == ["entry", "target"]
    assert field(output, "GroupName") == ["plan", "plan"]
    assert [floats(v) for v in field(output, "RGBA")] == [[255, 0, 0, 255], [0, 128, 255, 64]]
    positions = [floats(v) for v in field(output, "Position")]
    np.testing.assert_allclose(positions, [[1.5, -2.25, 3.0], [10.0, 20.0, -30.5]])
    # The C++ library calls the wire's DIAMETER "radius" and passes it through.
    assert [float(v) for v in field(output, "Radius")] == [4.0, 1.5]
    assert field(output, "Owner") == ["me", ""]

    assert field(output, "Device Name") == ["Volume"]
    assert field(output, "Scalar Type") == ["3"]  # UINT8
    assert floats(field(output, "Dimensions")[0]) == [6, 5, 4]  # i, j, k
    assert floats(field(output, "Spacing")[0]) == [0.5, 0.75, 2.0]
    assert floats(field(output, "Sub-Volume dimensions")[0]) == [6, 5, 4]
    assert floats(field(output, "Sub-Volume offset")[0]) == [0, 0, 0]


def test_receive_client_prints_our_messages(igtl_examples: dict[str, Path],
                                            processes: Processes) -> None:
    with listening() as (server, port):
        child = processes.start("ReceiveClient",
                                [str(igtl_examples["ReceiveClient"]), "127.0.0.1", str(port)])
        conn, _ = server.accept()
        with conn:
            conn.settimeout(TIMEOUT)
            conn.sendall(b"".join(encode(m) for m in outgoing()))
        wait_exit(child)  # it exits when we close the connection
    check_receiver_output(child.output())


def test_receive_server_prints_our_messages(igtl_examples: dict[str, Path],
                                            processes: Processes) -> None:
    port = pick_free_port()
    child = processes.start("ReceiveServer", [str(igtl_examples["ReceiveServer"]), str(port)])
    with connect_when_listening(port) as sock:
        for message in outgoing():  # one at a time, in separate writes
            sock.sendall(encode(message))
        child.wait_for_output("Sub-Volume offset", TIMEOUT)
    check_receiver_output(child.output())


def test_image_geometry_as_the_cpp_library_decodes_it(igtl_examples: dict[str, Path]) -> None:
    # Rotated axes, anisotropic spacing, 3 components, LPS: the C++ library must report the
    # volume's centre = our first-voxel origin + directions * spacing * (size - 1) / 2.
    angle = math.radians(20)
    directions = np.array([[math.cos(angle), 0, math.sin(angle)], [0, 1, 0],
                           [-math.sin(angle), 0, math.cos(angle)]])
    image = Image(np.arange(3 * 4 * 5 * 2, dtype=np.int16).reshape(3, 4, 5, 2) - 60,
                  np.array([0.5, 1.25, 3.0]), directions, np.array([7.0, -8.0, 9.0]), "LPS")
    data = encode(Message("Volume", image))
    result = subprocess.run([str(igtl_examples["probe"])], input=data, capture_output=True,
                            timeout=TIMEOUT, check=True)
    seen = dict(line.split(": ", 1) for line in result.stdout.decode().splitlines())
    assert seen["crc_ok"] == "1"
    assert floats(seen["size"]) == [5, 4, 3]
    np.testing.assert_allclose(floats(seen["spacing"]), [0.5, 1.25, 3.0], rtol=1e-6)
    for key, column in (("t", 0), ("s", 1), ("n", 2)):
        np.testing.assert_allclose(floats(seen[key]), directions[:, column], atol=1e-6)
    centre = image.origin + (directions * image.spacing) @ ((np.array([5, 4, 3]) - 1) / 2)
    np.testing.assert_allclose(floats(seen["origin"]), centre, atol=1e-5)
    assert seen["scalar_type"] == "4" and seen["components"] == "2"
    assert seen["coordinate"] == "2" and seen["endian"] == "2"
    expected_hash = 0
    for byte in image.pixels.astype("<i2").tobytes():
        expected_hash = (expected_hash * 31 + byte) % (1 << 64)
    assert int(seen["pixel_hash"]) == expected_hash
    # And back: our decoder recovers the first-voxel origin from the wire's centre.
    decoder = Decoder()
    decoder.feed(data)
    decoded = decoder.next_message()
    assert decoded is not None and isinstance(decoded.body, Image)
    np.testing.assert_allclose(decoded.body.origin, image.origin, atol=1e-5)


def test_polydata_client_prints_our_mesh(igtl_examples: dict[str, Path],
                                         processes: Processes) -> None:
    points = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10], [5.5, 5.5, -2.25]],
                      dtype=np.float32)
    mesh = PolyData(
        points,
        vertices=cells_from_array(np.arange(5).reshape(5, 1)),
        polygons=np.concatenate([cells_from_array([[0, 1, 2], [0, 2, 3]]),
                                 cells_from_array([[1, 2, 3, 4]])]),
        attributes=[
            PolyDataAttribute("temperature", AttributeKind.SCALAR,
                              np.array([[1.0], [2.0], [3.0], [4.0], [5.5]], np.float32)),
            PolyDataAttribute("normals", AttributeKind.NORMAL,
                              np.tile(np.array([0, 0, 1], np.float32), (5, 1))),
        ],
    )
    with listening() as (server, port):
        child = processes.start("PolyDataClient",
                                [str(igtl_examples["PolyDataClient"]), "127.0.0.1", str(port)])
        conn, _ = server.accept()
        with conn:
            conn.settimeout(TIMEOUT)
            (request,) = receive(conn, Decoder(), 1)
            assert request.type_name == "GET_POLYDATA" and request.device_name == "Client"
            assert request.body == RawBody("GET_POLYDATA", b"")
            conn.sendall(encode(Message("Mesh", mesh)))
            child.wait_for_output("================================", TIMEOUT)
        wait_exit(child)  # its next request finds the connection closed
    output = child.output()
    printed_points = [floats(v) for v in re.findall(r"point\[\d+\] = \((.*)\)", output)]
    np.testing.assert_allclose(printed_points, points)
    # The example prints a cell's first index twice (its loop restarts at begin()): drop one.
    printed_cells = re.findall(r"cell\[\d+\] = \((.*)\)", output)
    cells = [[int(x) for x in floats(v)][1:] for v in printed_cells]
    assert cells == [[0], [1], [2], [3], [4], [0, 1, 2], [0, 2, 3], [1, 2, 3, 4]]
    assert re.findall(r"^\s*Name = (.*)$", output, re.MULTILINE) == ["temperature", "normals"]
    assert re.findall(r"^\s*Type = (.*)$", output, re.MULTILINE) == ["POINT_SCALAR",
                                                                     "POINT_NORMAL"]
    data = [floats(v) for v in re.findall(r"data\[\d+\] = \((.*)\)", output)]
    assert data[:5] == [[1.0], [2.0], [3.0], [4.0], [5.5]]
    assert data[5:] == [[0, 0, 1]] * 5


# ------------------------------------------------------------------ C++ -> our decoder


def test_tracker_server_to_our_decoder(igtl_examples: dict[str, Path],
                                       processes: Processes) -> None:
    port = pick_free_port()
    child = processes.start("TrackerServer",
                            [str(igtl_examples["TrackerServer"]), str(port), "100"])
    with connect_when_listening(port) as sock:
        messages = receive(sock, Decoder(), 5)  # CRC verified by the decoder
    printed = printed_matrices(child.output())
    assert len(printed) >= 5
    for index, message in enumerate(messages):
        assert message.device_name == "Tracker" and message.header_version == 1
        assert isinstance(message.body, Transform)
        np.testing.assert_allclose(message.body.matrix, printed[index], rtol=1e-5, atol=1e-4)
        phi = 0.2 * index  # GetRandomTestMatrix's position on a circle
        np.testing.assert_allclose(message.body.matrix[:3, 3],
                                   50 * np.array([math.cos(phi), math.sin(phi), math.cos(phi)]),
                                   atol=1e-3)


def test_string_echo_server_round_trip(igtl_examples: dict[str, Path],
                                       processes: Processes) -> None:
    port = pick_free_port()
    child = processes.start("StringEchoServer",
                            [str(igtl_examples["StringEchoServer"]), str(port)])
    texts = ["hello", "ünïcødé ✓", "x" * 5000, ""]
    decoder = Decoder()
    with connect_when_listening(port) as sock:
        for text in texts:
            sock.sendall(encode(Message("Ask", String(text))))
            (reply,) = receive(sock, decoder, 1)
            assert reply.device_name == "StringEchoServer"
            assert reply.body == String(text, 106)
    assert "Echoing: hello" in child.output()
