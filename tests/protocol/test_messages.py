"""Message bodies: round trips, hand-written golden bytes, malformed content, pyigtl."""

from __future__ import annotations

import ast
import dataclasses
import random
import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.errors import BodyError, EncodeError, ProtocolError
from protocol.messages import (
    BODY_TYPES,
    AttributeKind,
    Command,
    Image,
    Json,
    Point,
    PointElement,
    PolyData,
    PolyDataAttribute,
    RawBody,
    RtsCommand,
    ScalarType,
    Status,
    StatusCode,
    String,
    TrackerKind,
    TrackingData,
    TrackingElement,
    Transform,
    cell_count,
    cells_from_array,
    cells_to_list,
    document_body,
    unpack_body,
)
from tests.protocol import igtl_strategies as strat
from tests.protocol.igtl_captures import CUBE_CORNERS_MM, CUBE_QUADS, OPENIGTLINK3_TCOORDS_CUBE

PROTOCOL = Path(__file__).resolve().parents[2] / "protocol"


def roundtrip(body: object) -> object:
    packed = body.pack()  # type: ignore[attr-defined]
    again = unpack_body(body.TYPE, packed)  # type: ignore[attr-defined]
    assert again.pack() == packed  # pack -> unpack -> pack: identical bytes
    return again


# ------------------------------------------------------------------ round trips (hypothesis)


def _decoded(type_name: str, content: object) -> tuple[str, object]:
    try:
        return "ok", unpack_body(type_name, content)  # type: ignore[arg-type]
    except BodyError as error:
        return "error", str(error)


@settings(max_examples=300, deadline=None)
@given(strat.bodies, st.randoms(use_true_random=False))
def test_a_large_body_s_read_only_view_decodes_as_its_bytes_do(body: object,
                                                               rnd: random.Random) -> None:
    """The framing hands a large body on as a read-only view (POLYDATA and IMAGE are read
    in place, the others copied): the same message, or the same error, as from bytes,
    whole or damaged."""
    raw = bytearray(body.pack())  # type: ignore[attr-defined]
    for _ in range(rnd.randint(0, 3)):
        if raw and rnd.random() < 0.7:
            raw[rnd.randrange(len(raw))] = rnd.randrange(256)
        else:
            del raw[rnd.randrange(len(raw) + 1):]
    type_name = body.TYPE if hasattr(body, "TYPE") else body.type_name  # type: ignore[attr-defined]
    assert _decoded(type_name, memoryview(bytes(raw)).toreadonly()) == \
        _decoded(type_name, bytes(raw))


@settings(max_examples=60, deadline=None)
@given(strat.transforms())
def test_transform_roundtrip(body: Transform) -> None:
    assert roundtrip(body) == body


@settings(max_examples=60, deadline=None)
@given(strat.strings())
def test_string_roundtrip(body: String) -> None:
    assert roundtrip(body) == body


@settings(max_examples=60, deadline=None)
@given(strat.statuses)
def test_status_roundtrip(body: Status) -> None:
    assert roundtrip(body) == body


@settings(max_examples=60, deadline=None)
@given(strat.polydatas())
def test_polydata_roundtrip(body: PolyData) -> None:
    assert roundtrip(body) == body


@settings(max_examples=40, deadline=None)
@given(strat.points)
def test_point_roundtrip(body: Point) -> None:
    assert roundtrip(body) == body


@settings(max_examples=40, deadline=None)
@given(strat.tracking_data)
def test_tracking_data_roundtrip(body: TrackingData) -> None:
    assert roundtrip(body) == body


@settings(max_examples=60, deadline=None)
@given(strat.images())
def test_image_pack_parts_are_pack_s_bytes_and_pixels_laid_out_as_sent_are_not_copied(
        body: Image) -> None:
    little = body.pixels.dtype.newbyteorder("<")
    pixels = np.ascontiguousarray(body.pixels, dtype=little)
    body = dataclasses.replace(body, pixels=pixels)
    head, content = body.pack_parts()
    assert content.readonly and head + bytes(content) == body.pack()
    assert np.shares_memory(np.frombuffer(content, dtype=np.uint8), pixels)
    # Big-endian and strided pixels too: packed once, little-endian, in order.
    swapped = dataclasses.replace(body, pixels=pixels.astype(pixels.dtype.newbyteorder(">")))
    strided = dataclasses.replace(body, pixels=np.repeat(pixels, 2, axis=2)[:, :, ::2])
    for other in (swapped, strided):
        other_head, other_content = other.pack_parts()
        assert other_head + bytes(other_content) == body.pack()
        assert not np.shares_memory(np.frombuffer(other_content, dtype=np.uint8), pixels)


@settings(max_examples=60, deadline=None)
@given(strat.images())
def test_image_roundtrip(body: Image) -> None:
    again = roundtrip(body)
    assert isinstance(again, Image)
    np.testing.assert_array_equal(again.pixels, body.pixels)
    assert again.pixels.dtype == body.pixels.dtype
    np.testing.assert_allclose(again.spacing, body.spacing, rtol=1e-6)
    np.testing.assert_allclose(again.directions, body.directions, atol=1e-6)
    np.testing.assert_allclose(again.origin, body.origin, atol=1e-3)
    assert again.coordinate == body.coordinate


@settings(max_examples=40, deadline=None)
@given(strat.commands(), strat.commands(RtsCommand))
def test_command_roundtrip(command: Command, reply: RtsCommand) -> None:
    assert roundtrip(command) == command
    assert roundtrip(reply) == reply
    assert not isinstance(reply, Command)  # a reply is never mistaken for a command


def test_registry_lists_every_type() -> None:
    assert set(BODY_TYPES) == {"TRANSFORM", "STRING", "STATUS", "POLYDATA", "POINT", "TDATA",
                               "IMAGE", "COMMAND", "RTS_COMMAND", "JSON"}
    for name, cls in BODY_TYPES.items():
        assert cls.TYPE == name


def test_unknown_type_is_raw() -> None:
    body = unpack_body("NDARRAY", b"\x01\x02")
    assert body == RawBody("NDARRAY", b"\x01\x02")
    assert body.pack() == b"\x01\x02"


# ------------------------------------------------------------------ golden bytes from the spec


def f32be(*values: float) -> bytes:
    return struct.pack(f">{len(values)}f", *values)


def test_transform_golden() -> None:
    matrix = np.eye(4)
    matrix[:3, 3] = (1, 2, 3)
    matrix[0, 1] = 0.5  # R12: the 4th float on the wire (column-major rotation)
    expected = f32be(1, 0, 0, 0.5, 1, 0, 0, 0, 1, 1, 2, 3)
    assert Transform(matrix).pack() == expected
    np.testing.assert_array_equal(Transform.unpack(expected).matrix, matrix)


def test_string_golden() -> None:
    assert String("hi").pack() == bytes.fromhex("006a 0002 6869")
    assert String("hi", 3).pack() == bytes.fromhex("0003 0002 6869")
    assert String("é").pack() == bytes.fromhex("006a 0002 c3a9")


def test_json_golden_and_bounds() -> None:
    """The project's own JSON body: LENGTH u32, UTF-8; no 65535-byte cap as STRING has."""
    assert Json('{"a":"é"}').pack() == bytes.fromhex("0000000a") + '{"a":"é"}'.encode()
    big = Json("x" * 100_000)
    assert Json.unpack(big.pack()) == big
    with pytest.raises(BodyError, match="LENGTH"):
        Json.unpack(bytes.fromhex("00000005") + b"abc")
    with pytest.raises(BodyError):
        Json.unpack(b"\x00\x00")
    with pytest.raises(BodyError):
        Json.unpack(bytes.fromhex("00000002") + b"\xff\xfe")  # not UTF-8


def test_a_document_is_a_string_while_it_fits_one_then_json() -> None:
    """The message stream's body (document_body): STRING, which every OpenIGTLink peer
    (3D Slicer's connector too) reads, up to 65535 bytes of UTF-8; JSON beyond."""
    fits = "é" * 32767 + "x"  # 65535 bytes, 32768 characters
    body = document_body(fits)
    assert isinstance(body, String) and body.encoding == 106  # UTF-8's MIBenum
    assert String.unpack(body.pack()).text == fits
    over = "é" * 32768  # 65536 bytes
    assert document_body(over) == Json(over)


def test_status_golden() -> None:
    body = Status(StatusCode.NOT_FOUND, -2, "ENOENT", "gone")
    expected = (bytes.fromhex("0004 fffffffffffffffe") + b"ENOENT".ljust(20, b"\0")
                + b"gone\0")
    assert body.pack() == expected
    assert Status.unpack(expected) == body
    assert isinstance(Status.unpack(expected).code, StatusCode)


def test_polydata_golden() -> None:
    body = PolyData(
        np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32),
        vertices=cells_from_array(np.array([[0], [2]])),
        polygons=cells_from_array(np.array([[0, 1, 2]])),
        attributes=[PolyDataAttribute("s", AttributeKind.SCALAR,
                                      np.array([[1], [2], [3]], dtype=np.float32))],
    )
    expected = b"".join([
        struct.pack(">10I", 3, 2, 16, 0, 0, 1, 16, 0, 0, 1),
        f32be(0, 0, 0, 1, 0, 0, 0, 1, 0),
        struct.pack(">4I", 1, 0, 1, 2),  # vertices
        struct.pack(">4I", 3, 0, 1, 2),  # one triangle
        bytes([0x00, 1]) + struct.pack(">I", 3),  # TYPE point scalar, 1 component, N = 3
        b"s\0",  # name, already an even length
        f32be(1, 2, 3),
    ])
    assert body.pack() == expected
    assert PolyData.unpack(expected) == body


def test_polydata_cell_attribute_golden() -> None:
    body = PolyData(np.zeros((3, 3), np.float32), polygons=cells_from_array([[0, 1, 2]]),
                    attributes=[PolyDataAttribute("rgb", AttributeKind.RGBA,
                                                  np.ones((1, 4), np.float32), on_cells=True)])
    packed = body.pack()
    attr = packed[40 + 36 + 16:]
    assert attr[:6] == bytes([0x14, 4]) + struct.pack(">I", 1)  # cell RGBA, 4 components
    assert attr[6:10] == b"rgb\0"
    assert len(packed) == 40 + 36 + 16 + 6 + 4 + 16  # "rgb\0" is even: no padding


def test_polydata_tcoords_point_and_cell_golden() -> None:
    """Issue 42 (6): texture coordinates, TYPE 0x05 on points and 0x15 on cells, with the
    count of components the message gives (a vtkCubeSource's are u, v)."""
    body = PolyData(np.zeros((3, 3), np.float32), polygons=cells_from_array([[0, 1, 2]]),
                    attributes=[
                        PolyDataAttribute("TCoords", AttributeKind.TCOORDS,
                                          np.array([[0, 0], [1, 0], [0, 1]], np.float32)),
                        PolyDataAttribute("uvw", AttributeKind.TCOORDS,
                                          np.array([[0.5, 0.25, 1]], np.float32),
                                          on_cells=True)])
    packed = body.pack()
    attr = packed[40 + 36 + 16:]
    assert attr[:12] == (bytes([0x05, 2]) + struct.pack(">I", 3)
                         + bytes([0x15, 3]) + struct.pack(">I", 1))
    assert attr[12:24] == b"TCoords\0uvw\0"  # 12 bytes: even, no padding
    assert attr[24:] == f32be(0, 0, 1, 0, 0, 1) + f32be(0.5, 0.25, 1)
    again = roundtrip(body)
    assert again == body
    assert [a.kind for a in again.attributes] == [AttributeKind.TCOORDS] * 2  # type: ignore[attr-defined]




def test_polydata_openigtlink3_padded_tcoords() -> None:
    """Before: "attribute 'TCoords' TYPE: expected 0..4 ... got 5". Now the cube decodes,
    its TCoords as the (u, v, 0) rows OpenIGTLink 3.1's own reader takes from them."""
    body = unpack_body("POLYDATA", OPENIGTLINK3_TCOORDS_CUBE)
    assert isinstance(body, PolyData)
    assert body.points.tolist() == CUBE_CORNERS_MM
    assert [c.tolist() for c in cells_to_list(body.polygons)] == CUBE_QUADS
    (tcoords,) = body.attributes
    assert (tcoords.name, tcoords.kind, tcoords.on_cells) == ("TCoords", AttributeKind.TCOORDS,
                                                              False)
    assert tcoords.data.tolist() == [[0.25 * j, 0.5, 0.0] for j in range(8)]
    # Re-packed in the spec's layout (3 components, no filler), then stable.
    packed = body.pack()
    assert packed[270 - 14:270 - 8] == bytes([0x05, 3]) + struct.pack(">I", 8)
    assert len(packed) == 270 + 4 * 3 * 8
    assert roundtrip(body) == body


@pytest.mark.parametrize("kind, keep", [(AttributeKind.RGBA, 4), (AttributeKind.TCOORDS, 3),
                                        (AttributeKind.NORMAL, 3), (AttributeKind.VECTOR, 3)])
def test_polydata_padded_cell_attribute(kind: AttributeKind, keep: int) -> None:
    """OpenIGTLink 3.1 packs every cell attribute, and point RGBA, as 9 floats a row:
    the first ``keep`` * N floats are the values, N rows of ``keep``."""
    values = np.arange(2 * keep, dtype=np.float32).reshape(2, keep) / 8
    fixed = struct.pack(">10I", 3, 0, 0, 0, 0, 2, 32, 0, 0, 1)
    content = b"".join([
        fixed, f32be(*[0.0] * 9), struct.pack(">8I", 3, 0, 1, 2, 3, 2, 1, 0),
        bytes([0x10 | kind, 9]) + struct.pack(">I", 2), b"a\0",
        f32be(*values.reshape(-1)), f32be(*[-1.0] * (18 - 2 * keep))])
    body = unpack_body("POLYDATA", content)
    assert isinstance(body, PolyData)
    (attr,) = body.attributes
    assert (attr.kind, attr.on_cells) == (kind, True)
    assert attr.data.tolist() == values.tolist()


def test_polydata_tcoords_of_four_components_refused() -> None:
    body = PolyData(np.zeros((1, 3), np.float32), attributes=[
        PolyDataAttribute("t", AttributeKind.TCOORDS, np.zeros((1, 4), np.float32))])
    with pytest.raises(EncodeError) as info:
        body.pack()
    assert info.value.field == "POLYDATA attributes[0].data"
    assert "(N, 1..3) for TCOORDS" in str(info.value)


def test_point_golden() -> None:
    body = Point([PointElement("p1", "Fiducial", (255, 0, 0, 128), np.array([1.0, 2, 3]),
                               4.0, "owner")])
    expected = (b"p1".ljust(64, b"\0") + b"Fiducial".ljust(32, b"\0") + bytes([255, 0, 0, 128])
                + f32be(1, 2, 3, 4) + b"owner".ljust(20, b"\0"))
    assert body.pack() == expected
    assert Point.unpack(expected) == body


def test_tracking_data_golden() -> None:
    matrix = np.eye(4)
    matrix[:3, 3] = (1, 2, 3)
    matrix[0, 1] = 0.5  # as in TRANSFORM: R12 is the 4th float
    body = TrackingData([TrackingElement("demo:base_link", matrix),
                         TrackingElement("tip", np.eye(4), TrackerKind.TRACKER)])
    expected = (b"demo:base_link".ljust(20, b"\0") + bytes([2, 0])
                + f32be(1, 0, 0, 0.5, 1, 0, 0, 0, 1, 1, 2, 3)
                + b"tip".ljust(20, b"\0") + bytes([1, 0])
                + f32be(1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0))
    assert body.pack() == expected
    assert TrackingData.unpack(expected) == body


def test_tracking_data_refuses_what_a_transform_refuses() -> None:
    beyond = np.eye(4)
    beyond[0, 3] = 1e39  # finite in float64, infinite in float32
    with pytest.raises(EncodeError) as info:
        TrackingData([TrackingElement("a", np.eye(4)), TrackingElement("b", beyond)]).pack()
    assert info.value.field == "TDATA elements[1].matrix"
    with pytest.raises(EncodeError) as info:  # 20 bytes: Slicer's library reads it as ""
        TrackingData([TrackingElement("x" * 20)]).pack()
    assert info.value.field == "TDATA elements[0].name"
    assert info.value.expected == "at most 19 bytes in UTF-8"


def test_image_golden_centre_of_volume() -> None:
    # 2 slices x 3 rows x 4 columns, spacing (0.5, 1, 2), origin = first voxel at (10, 20, 30).
    pixels = np.arange(24, dtype=np.uint16).reshape(2, 3, 4, 1)
    body = Image(pixels, np.array([0.5, 1, 2]), np.eye(3), np.array([10.0, 20, 30]), "LPS")
    centre = (10 + 0.5 * 1.5, 20 + 1 * 1.0, 30 + 2 * 0.5)  # (size - 1) / 2 voxels further
    expected = (
        struct.pack(">HBBBB3H", 1, 1, ScalarType.UINT16, 2, 2, 4, 3, 2)
        + f32be(0.5, 0, 0, 0, 1, 0, 0, 0, 2, *centre)
        + struct.pack(">6H", 0, 0, 0, 4, 3, 2)
        + pixels.astype("<u2").tobytes()
    )
    assert body.pack() == expected
    assert Image.unpack(expected) == body


def test_image_big_endian_and_subvolume_decode() -> None:
    # A 4x3x2 volume of which the sender ships the 2x2x1 subvolume at offset (1, 1, 1).
    sub = np.array([[[[1], [2]], [[3], [4]]]], dtype=">i2")  # (k=1, j=2, i=2, c=1)
    content = (
        struct.pack(">HBBBB3H", 1, 1, ScalarType.INT16, 1, 1, 4, 3, 2)
        + f32be(1, 0, 0, 0, 1, 0, 0, 0, 1, 1.5, 1.0, 0.5)  # centre of 4x3x2 at origin 0
        + struct.pack(">6H", 1, 1, 1, 2, 2, 1)
        + sub.tobytes()
    )
    image = Image.unpack(content)
    assert image.pixels.dtype == np.dtype("int16") and image.pixels.dtype.isnative
    np.testing.assert_array_equal(image.pixels, sub.astype(np.int16))
    np.testing.assert_allclose(image.origin, [1, 1, 1])  # first voxel of the subvolume


def test_command_golden() -> None:
    body = Command(7, "GetStatus", "<x/>")
    expected = (struct.pack(">I", 7) + b"GetStatus".ljust(128, b"\0")
                + struct.pack(">HI", 106, 4) + b"<x/>")
    assert body.pack() == expected
    assert Command.unpack(expected) == body
    assert RtsCommand.unpack(expected) == RtsCommand(7, "GetStatus", "<x/>")


# ------------------------------------------------------------------ helpers


def test_cell_helpers() -> None:
    tri = cells_from_array(np.array([[0, 1, 2], [2, 3, 0]]))
    assert tri.dtype == np.uint32
    assert tri.tolist() == [3, 0, 1, 2, 3, 2, 3, 0]
    assert cell_count(tri) == 2
    assert [c.tolist() for c in cells_to_list(tri)] == [[0, 1, 2], [2, 3, 0]]
    mixed = np.array([3, 0, 1, 2, 4, 0, 1, 2, 3, 1, 5], dtype=np.uint32)
    assert cell_count(mixed) == 3
    assert [c.tolist() for c in cells_to_list(mixed)] == [[0, 1, 2], [0, 1, 2, 3], [5]]
    assert cell_count(np.zeros(0, np.uint32)) == 0 and cells_to_list([]) == []
    with pytest.raises(EncodeError, match="cells"):
        cell_count(np.array([3, 0, 1], np.uint32))  # the cell runs past the end
    with pytest.raises(EncodeError):
        cells_from_array(np.array([[-1, 0]]))


def _walked_starts(flat: list[int]) -> tuple[list[int], int]:
    """The cell starts one cell a step, and where the walk ended (the plain definition)."""
    starts, pos = [], 0
    while pos < len(flat):
        starts.append(pos)
        pos += flat[pos] + 1
    return starts, pos


@pytest.mark.parametrize("seed", range(40))
def test_mixed_size_cells_are_found_as_a_walk_one_cell_a_step_finds_them(seed: int) -> None:
    """Cells of 0 to 40 indices (and up to 300: a long polyline), some arrays cut short
    or run long, against the plain walk: the same starts, or the same error."""
    rng = np.random.default_rng(seed)
    top = 300 if seed % 5 == 0 else 40
    sizes = rng.integers(0, top + 1, size=int(rng.integers(1, 3000)))
    flat = np.concatenate([np.concatenate(([k], rng.integers(0, 9, size=k)))
                           for k in sizes]).astype(np.uint32)
    if seed % 4 == 1:
        flat = flat[:-int(rng.integers(1, min(len(flat), 50) + 1))]  # the last cell cut
    elif seed % 4 == 2:
        flat = np.concatenate((flat, np.array([2**32 - 1], np.uint32)))  # one runs far out
    expected, end = _walked_starts(flat.tolist())
    if end == len(flat):
        assert cell_count(flat) == len(expected)
        assert [c.tolist() for c in cells_to_list(flat)] == [
            flat[s + 1:s + 1 + int(flat[s])].tolist() for s in expected]
    else:
        with pytest.raises(EncodeError, match=rf"last cell \(at {expected[-1]}\) runs to"):
            cell_count(flat)


# ------------------------------------------------------------------ invalid values to encode


@pytest.mark.parametrize("body, field", [
    (String("x" * 65536), "STRING text"),
    (String("é", 3), "STRING text"),
    (String("x", 4), "STRING text encoding"),
    (Status(error_name="x" * 20), "STATUS error_name"),
    (Status(code=70000), "STATUS code"),
    (Status(text="a\0b"), "STATUS text"),
    (Transform(np.eye(3)), "TRANSFORM matrix"),
    (Transform(np.full((4, 4), np.nan)), "TRANSFORM matrix"),
    (PolyData(np.zeros((2, 2), np.float32)), "POLYDATA points"),
    (PolyData(np.zeros((2, 3), np.float32), polygons=np.array([3, 0, 1, 2], np.uint32)),
     "POLYDATA polygons"),
    (PolyData(np.zeros((2, 3), np.float32),
              attributes=[PolyDataAttribute("n", AttributeKind.NORMAL, np.zeros((2, 2)))]),
     "POLYDATA attributes[0].data"),
    (PolyData(np.zeros((2, 3), np.float32),
              attributes=[PolyDataAttribute("s", AttributeKind.SCALAR, np.zeros((3, 1)))]),
     "POLYDATA attributes[0].data"),
    (Point([PointElement(name="n" * 65)]), "POINT points[0].name"),
    (Point([PointElement(rgba=(0, 0, 0, 256))]), "POINT points rgba"),
    (Image(np.zeros((2, 2, 2), np.uint8)), "IMAGE pixels"),
    (Image(np.zeros((1, 1, 1, 1), np.int64)), "IMAGE pixels dtype"),
    (Image(np.zeros((1, 1, 1, 1), np.uint8), coordinate="XYZ"), "IMAGE coordinate"),
    (Image(np.zeros((1, 1, 1, 1), np.uint8), spacing=np.ones(2)), "IMAGE spacing"),
    (Command(-1, "x", ""), "COMMAND command_id"),
    (Command(1, "x" * 129, ""), "COMMAND name"),
])
def test_encode_errors_name_the_field(body: object, field: str) -> None:
    with pytest.raises(EncodeError) as info:
        body.pack()  # type: ignore[attr-defined]
    assert info.value.field == field
    assert "expected" in str(info.value) and "got" in str(info.value)


# ------------------------------------------------------------------ malformed content


def _poly(**kw: object) -> bytes:
    base = {"points": np.zeros((3, 3), np.float32), "polygons": cells_from_array([[0, 1, 2]])}
    base.update(kw)
    return PolyData(**base).pack()  # type: ignore[arg-type]


def _patch(data: bytes, offset: int, fmt: str, *values: int) -> bytes:
    out = bytearray(data)
    struct.pack_into(fmt, out, offset, *values)
    return bytes(out)


GOOD_IMAGE = Image(np.zeros((2, 3, 4, 1), np.uint8)).pack()

MALFORMED = [
    ("TRANSFORM", b"\0" * 47, "body"),
    ("STRING", b"\0\x6a", "header"),
    ("STRING", bytes.fromhex("006a 0005 6869"), "LENGTH"),
    ("STRING", bytes.fromhex("006a 0002 c328"), "text"),  # invalid UTF-8
    ("STRING", bytes.fromhex("0003 0002 c3a9"), "text"),  # not ASCII though encoding 3
    ("STRING", bytes.fromhex("0004 0001 41"), "text encoding"),
    ("STATUS", b"\0" * 10, "header"),
    ("STATUS", b"\0\1" + b"\0" * 28 + b"\xff\xfe\0", "text"),
    ("POLYDATA", b"\0" * 39, "header"),
    ("POLYDATA", _patch(_poly(), 0, ">I", 1000), "NPOINTS"),
    ("POLYDATA", _patch(_poly(), 20, ">I", 2), "NPOLYGONS"),  # count disagrees with the cells
    ("POLYDATA", _patch(_poly(), 24, ">I", 15), "SIZE_POLYGONS"),  # not a multiple of 4
    ("POLYDATA", _patch(_poly(), 24, ">I", 400), "SIZE_POLYGONS"),  # beyond the body
    ("POLYDATA", _patch(_poly(), 40 + 36 + 4, ">I", 7), "polygons"),  # index >= NPOINTS
    ("POLYDATA", _patch(_poly(), 40 + 36, ">I", 9), "polygons"),  # cell runs past the end
    ("POLYDATA", _patch(_poly(), 36, ">I", 0xFFFFFFFF), "NATTRIBUTES"),
    ("POLYDATA", _poly() + b"\0\0", "body"),  # trailing bytes
    ("POLYDATA", _patch(_poly(attributes=[PolyDataAttribute(
        "a", AttributeKind.VECTOR, np.zeros((3, 3), np.float32))]), 40 + 36 + 16, ">B", 9),
     "attribute 'a' TYPE"),
    ("POLYDATA", _patch(_poly(attributes=[PolyDataAttribute(
        "a", AttributeKind.VECTOR, np.zeros((3, 3), np.float32))]), 40 + 36 + 17, ">B", 2),
     "attribute 'a' NCOMPONENTS"),
    ("POLYDATA", _patch(_poly(attributes=[PolyDataAttribute(
        "a", AttributeKind.VECTOR, np.zeros((3, 3), np.float32))]), 40 + 36 + 18, ">I", 4),
     "attribute 'a' N"),
    ("POLYDATA", _patch(_poly(attributes=[PolyDataAttribute(  # kind 6: beyond the spec
        "a", AttributeKind.TCOORDS, np.zeros((3, 2), np.float32))]), 40 + 36 + 16, ">B", 0x16),
     "attribute 'a' TYPE"),
    ("POLYDATA", _patch(_poly(attributes=[PolyDataAttribute(
        "a", AttributeKind.TCOORDS, np.zeros((3, 2), np.float32))]), 40 + 36 + 17, ">B", 4),
     "attribute 'a' NCOMPONENTS"),
    ("POLYDATA", _patch(_poly(attributes=[PolyDataAttribute(  # 9: padded, but no filler
        "a", AttributeKind.TCOORDS, np.zeros((3, 3), np.float32))]), 40 + 36 + 17, ">B", 9),
     "attribute 'a' data"),
    ("POINT", b"\0" * 135, "body"),
    ("POINT", b"\xff" * 136, "points[0].name"),
    ("TDATA", b"\0" * 69, "body"),
    ("TDATA", b"\0" * 70 + b"\xff" * 70, "elements[1].name"),
    ("IMAGE", GOOD_IMAGE[:-1], "pixel data"),  # size disagrees with the buffer
    ("IMAGE", GOOD_IMAGE + b"\0", "pixel data"),
    ("IMAGE", _patch(GOOD_IMAGE, 3, ">B", 9), "SCALAR_TYPE"),
    ("IMAGE", _patch(GOOD_IMAGE, 4, ">B", 3), "ENDIAN"),
    ("IMAGE", _patch(GOOD_IMAGE, 5, ">B", 0), "COORD"),
    ("IMAGE", _patch(GOOD_IMAGE, 6, ">H", 0), "size"),
    ("IMAGE", _patch(GOOD_IMAGE, 60, ">H", 3), "subvolume"),
    ("IMAGE", _patch(GOOD_IMAGE, 12, ">3f", 0, 0, 0), "matrix"),
    ("IMAGE", GOOD_IMAGE[:71], "image header"),
    ("COMMAND", b"\0" * 137, "header"),
    ("COMMAND", Command(1, "a", "xyz").pack()[:-1], "LENGTH"),
    ("RTS_COMMAND", _patch(RtsCommand(1, "a", "x").pack(), 132, ">H", 5), "text encoding"),
]


@pytest.mark.parametrize("type_name, content, field", MALFORMED,
                         ids=[f"{t}-{f}-{i}" for i, (t, _, f) in enumerate(MALFORMED)])
def test_malformed_bodies_raise_body_error(type_name: str, content: bytes, field: str) -> None:
    with pytest.raises(BodyError) as info:
        unpack_body(type_name, content)
    assert info.value.type_name == type_name
    assert info.value.field == field, str(info.value)
    assert str(info.value).startswith(type_name)


def test_nan_transform_decodes() -> None:
    content = f32be(*([float("nan")] + [0.0] * 11))
    body = Transform.unpack(content)
    assert np.isnan(body.matrix[0, 0]) and body.matrix[3, 3] == 1.0
    with pytest.raises(EncodeError):  # re-encoding refuses it, with a typed error
        body.pack()


def test_error_tree() -> None:
    from protocol import errors

    assert issubclass(errors.HeaderError, errors.FramingError)
    assert issubclass(errors.BodyTooLargeError, errors.FramingError)
    assert issubclass(errors.CrcMismatchError, errors.MessageError)
    assert issubclass(errors.BodyError, errors.MessageError)
    for cls in (errors.FramingError, errors.MessageError, errors.EncodeError):
        assert issubclass(cls, ProtocolError)
    err = BodyError("N", "3", 4, type_name="POLYDATA")
    assert str(err) == "POLYDATA N: expected 3, got 4"
    import pickle

    again = pickle.loads(pickle.dumps(err))
    assert type(again) is BodyError and str(again) == str(err) and again.type_name == "POLYDATA"


# ------------------------------------------------------------------ against pyigtl


def test_pyigtl_reads_our_image_origin_as_first_voxel() -> None:
    pyigtl = pytest.importorskip("pyigtl")
    pixels = np.arange(2 * 3 * 4, dtype=np.uint8).reshape(2, 3, 4, 1)
    directions = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    body = Image(pixels, np.array([0.5, 1.5, 2.0]), directions, np.array([5.0, -7, 11]))
    theirs = pyigtl.ImageMessage()
    theirs._unpack_content(body.pack())
    np.testing.assert_allclose(theirs.ijk_to_world_matrix[:3, 3], body.origin, atol=1e-5)
    np.testing.assert_allclose(theirs.ijk_to_world_matrix[:3, :3], directions * body.spacing,
                               atol=1e-6)
    np.testing.assert_array_equal(theirs.image, pixels[..., 0])


def test_pyigtl_bodies_decode_here() -> None:
    pyigtl = pytest.importorskip("pyigtl")
    matrix = np.array([[0, -1, 0, 10], [1, 0, 0, 20], [0, 0, 1, 30], [0, 0, 0, 1]], float)
    tf = pyigtl.TransformMessage(matrix, device_name="T")
    np.testing.assert_array_equal(Transform.unpack(tf._pack_content()).matrix, matrix)
    assert Transform(matrix).pack() == tf._pack_content()
    s = pyigtl.StringMessage("hello", device_name="S")
    assert String.unpack(s._pack_content()) == String("hello", 3)
    ijk = np.diag([0.5, 1.0, 2.0, 1.0])
    ijk[:3, 3] = (1, 2, 3)
    im = pyigtl.ImageMessage(np.arange(24, dtype=np.uint16).reshape(2, 3, 4),
                             ijk_to_world_matrix=ijk, device_name="I")
    ours = Image.unpack(im._pack_content())
    np.testing.assert_allclose(ours.origin, [1, 2, 3], atol=1e-5)
    np.testing.assert_allclose(ours.spacing, [0.5, 1, 2])
    assert ours.coordinate == "LPS"  # pyigtl's default
    pts = pyigtl.PointMessage(positions=[[1, 2, 3], [4, 5, 6]], names=["a", "b"])
    decoded = Point.unpack(pts._pack_content())
    assert [p.name for p in decoded.points] == ["a", "b"]
    np.testing.assert_array_equal(decoded.points[1].position, [4, 5, 6])


def test_protocol_sources_parse_as_python39() -> None:
    # protocol/ must run inside 3D Slicer's Python 3.9.
    for path in sorted(PROTOCOL.glob("*.py")):
        ast.parse(path.read_text(), str(path), feature_version=(3, 9))


@settings(max_examples=60, deadline=None)
@given(strat.transforms())
def test_transform_fast_path_matches_conversions(body: Transform) -> None:
    from protocol.conversions import matrix_to_igtl12

    expected = matrix_to_igtl12(body.matrix).astype(">f4").tobytes()
    assert body.pack() == expected
    assert Transform(np.asfortranarray(body.matrix)).pack() == expected
    assert Transform(body.matrix.astype(np.float32)).pack() == expected
    assert Transform(body.matrix.tolist()).pack() == expected  # type: ignore[arg-type]


def test_image_whose_geometry_overflows_float32_is_an_encode_error() -> None:
    """Found by the atheris campaign (bench/fuzz_decoder.py): an IMAGE that decodes, with
    spacing x directions beyond float32, must not re-encode with a bare OverflowError."""
    import base64

    from protocol.errors import EncodeError
    from protocol.framing import Decoder, encode

    wire = base64.b64decode(
        "AQcAAUlNQUdFAAAAAAAAAGltZwAAAAAAAAAAAAAAACkAAAAAAAAAAAAAAAAAAAAAAAAAYEpV4H94ra5dAAEE"
        "AwIBAAMA/v/3P4YAAAAD////AAAAAAAAAD+AAAAAAAAAAAAAAAAAAAB/eQAAP4AAAD8AAAAAAAAAAAAAAACA"
        "AAMAAgABAAECAwEAAAAAAAAhBAUGBwgJCgsMDQ4PEBESExQVFhc=")[2:]
    decoder = Decoder(verify_crc=False)
    decoder.feed(wire)
    message = decoder.next_message()
    assert message is not None and message.type_name == "IMAGE"
    with pytest.raises(EncodeError) as error:
        encode(message)
    assert error.value.field == "IMAGE geometry"
