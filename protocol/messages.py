"""OpenIGTLink message contents ("bodies") with byte-exact pack/unpack.

Each body class has ``TYPE`` (the header's type name), ``pack() -> bytes`` (the content,
without v2 extended header or metadata) and ``unpack(content) -> instance``; BODY_TYPES maps
type names to classes and `unpack_body` falls back to `RawBody` for unknown types, so
nothing is dropped. pack -> unpack -> pack gives identical bytes.

Spec references ("Spec: X" below) are to the OpenIGTLink protocol description,
openigtlink.org/Documents/Protocol/<X>.md, checked against the C library igtl_<x>.c/.h.
All numbers on the wire are big-endian, except IMAGE pixels, whose byte order is a field.

Arrays decoded from the wire may be read-only views on the received bytes (IMAGE pixels):
copy them before writing into them. Decoding never runs Python loops per point or pixel.
"""

from __future__ import annotations

import struct
from array import array
from dataclasses import dataclass, field, fields
from enum import IntEnum
from typing import Any, Callable, ClassVar, Union

import numpy as np
import numpy.typing as npt

from protocol.conversions import (ConversionError, fits_float32, igtl12_to_matrix,
                                  matrix_to_igtl12)
from protocol.errors import BodyError, EncodeError
from protocol.header import (
    DEVICE_NAME_SIZE,
    ENCODING_UTF8,
    TDATA_NAME_MAX_BYTES,
    decode_name,
    decode_text,
    encode_name,
    encode_text,
)

__all__ = [
    "BODY_TYPES",
    "AttributeKind",
    "Body",
    "Command",
    "Image",
    "Json",
    "KnownBody",
    "Message",
    "Point",
    "PointElement",
    "PolyData",
    "PolyDataAttribute",
    "RawBody",
    "RtsCommand",
    "ScalarType",
    "Status",
    "StatusCode",
    "String",
    "TrackerKind",
    "TrackingData",
    "TrackingElement",
    "Transform",
    "cell_count",
    "cells_from_array",
    "cells_to_list",
    "document_body",
    "unpack_body",
]

AnyArray = npt.NDArray[Any]
FloatArray = npt.NDArray[np.float64]
U32Array = npt.NDArray[np.uint32]

_U32_MAX = 0xFFFFFFFF


# ----------------------------------------------------------------------------- helpers


def _arrays_equal(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        x, y = np.asarray(a), np.asarray(b)
        if x.shape != y.shape:
            return False
        if x.dtype.kind == "f" and y.dtype.kind == "f":
            return bool(np.array_equal(x, y, equal_nan=True))
        return bool(np.array_equal(x, y))
    return a == b


def _dataclass_eq(a: Any, b: Any) -> Any:
    # Generated __eq__ would compare arrays with == and fail on truth value; compare by value.
    if type(a) is not type(b):
        return NotImplemented
    return all(_arrays_equal(getattr(a, f.name), getattr(b, f.name)) for f in fields(a))


def _bad(type_name: str, field_name: str, expected: str, got: object) -> BodyError:
    return BodyError(field_name, expected, got, type_name=type_name)


def _need(type_name: str, content: bytes, size: int, what: str) -> None:
    if len(content) < size:
        raise _bad(type_name, what, f"at least {size} bytes", f"{len(content)} bytes")


def _as_array(value: object, field_name: str, dtype: Any, expected: str) -> AnyArray:
    try:
        return np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise EncodeError(field_name, expected, f"{type(value).__name__} ({exc})") from None


def _element_table(type_name: str, content: bytes, dtype: np.dtype[Any]) -> AnyArray:
    """A body of fixed-size elements (POINT, TDATA) as a structured array, whole ones only."""
    if len(content) % dtype.itemsize:
        raise _bad(type_name, "body", f"a multiple of {dtype.itemsize} bytes",
                   f"{len(content)} bytes")
    return np.frombuffer(content, dtype=dtype)


def _check_shape(arr: AnyArray, shape: tuple[int, ...], field_name: str) -> None:
    if arr.shape != shape:
        raise EncodeError(field_name, f"shape {shape}", f"shape {arr.shape}")


# ----------------------------------------------------------------------------- TRANSFORM

# Where each matrix entry sits among the 12 wire floats, derived from the one conversion
# in protocol.conversions (applied to 0..11), so decoding is a single gather that also keeps
# NaN (refusing NaN is the bridge's job, not the decoder's).
_IGTL12_INDEX = igtl12_to_matrix(np.arange(12, dtype=np.float64))[:3, :].astype(np.intp)
_IGTL12_WIRE_ORDER = np.argsort(_IGTL12_INDEX.reshape(12))  # wire slot -> entry of matrix[:3]
_TWELVE_F32 = struct.Struct(">12f")


@dataclass(eq=False)
class Transform:
    """Spec: transform.md. 12 float32: R11 R21 R31 R12 R22 R32 R13 R23 R33 TX TY TZ (mm)."""

    TYPE: ClassVar[str] = "TRANSFORM"
    matrix: FloatArray  # (4, 4) float64, translation column in mm; last row 0 0 0 1

    SIZE: ClassVar[int] = 48

    def pack(self) -> bytes:
        m = self.matrix
        if isinstance(m, np.ndarray) and m.shape == (4, 4) and m.dtype.kind == "f":
            # Fast path: the same gather as conversions.matrix_to_igtl12, via the
            # index table derived from it, packed from Python floats (numpy's per-call
            # overhead is most of the cost for 12 numbers); anything unusual (NaN, a value
            # beyond float32) goes through the checked path, which says what.
            values = m[:3].reshape(12)[_IGTL12_WIRE_ORDER].tolist()
            if fits_float32(*values):
                return _TWELVE_F32.pack(*values)
        try:
            checked = matrix_to_igtl12(m)
        except ConversionError as exc:
            raise EncodeError(f"TRANSFORM {exc.field}", exc.expected, exc.got) from None
        return checked.astype(">f4").tobytes()

    @classmethod
    def unpack(cls, content: bytes) -> Transform:
        if len(content) != cls.SIZE:
            raise _bad(cls.TYPE, "body", f"{cls.SIZE} bytes", f"{len(content)} bytes")
        values = np.frombuffer(content, dtype=">f4").astype(np.float64)
        matrix = np.zeros((4, 4), dtype=np.float64)
        matrix[:3, :] = values[_IGTL12_INDEX]
        matrix[3, 3] = 1.0
        return cls(matrix)

    __eq__ = _dataclass_eq


# ----------------------------------------------------------------------------- STRING

_STRING_HEAD = struct.Struct(">HH")


@dataclass
class String:
    """Spec: string.md. ENCODING u16 (MIBenum 3 US-ASCII, 106 UTF-8), LENGTH u16, bytes."""

    TYPE: ClassVar[str] = "STRING"
    text: str
    encoding: int = ENCODING_UTF8

    def pack(self) -> bytes:
        raw = encode_text(self.text, self.encoding, "STRING text")
        if len(raw) > 0xFFFF:
            raise EncodeError("STRING text", "at most 65535 bytes", f"{len(raw)} bytes")
        return _STRING_HEAD.pack(self.encoding, len(raw)) + raw

    @classmethod
    def unpack(cls, content: bytes) -> String:
        _need(cls.TYPE, content, _STRING_HEAD.size, "header")
        encoding, length = _STRING_HEAD.unpack_from(content)
        end = _STRING_HEAD.size + length
        if end > len(content):
            raise _bad(cls.TYPE, "LENGTH", f"<= {len(content) - _STRING_HEAD.size} (bytes left)",
                       length)
        # Bytes after LENGTH are ignored, as the C library does.
        text = decode_text(content[_STRING_HEAD.size:end], encoding, "text", cls.TYPE)
        return cls(text, encoding)


# ----------------------------------------------------------------------------- STATUS


class StatusCode(IntEnum):
    """Spec: status.md, status codes."""

    INVALID = 0
    OK = 1
    UNKNOWN_ERROR = 2
    PANICK_MODE = 3
    NOT_FOUND = 4
    ACCESS_DENIED = 5
    BUSY = 6
    TIME_OUT = 7
    OVERFLOW = 8
    CHECKSUM_ERROR = 9
    CONFIG_ERROR = 10
    RESOURCE_ERROR = 11
    UNKNOWN_INSTRUCTION = 12
    NOT_READY = 13
    MANUAL_MODE = 14
    DISABLED = 15
    NOT_PRESENT = 16
    UNKNOWN_VERSION = 17
    HARDWARE_FAILURE = 18
    SHUT_DOWN = 19


_STATUS_HEAD = struct.Struct(">Hq20s")
_STATUS_CODES = {int(c) for c in StatusCode}


@dataclass
class Status:
    """Spec: status.md. CODE u16, SUB_CODE i64, ERROR_NAME char[20], STATUS_MESSAGE + NUL.

    The C++ library requires the terminating NUL (igtlStatusMessage.cxx), so pack adds it.
    ERROR_NAME is limited to 19 bytes: its C++ reader reads 20 unterminated bytes past the end.
    """

    TYPE: ClassVar[str] = "STATUS"
    code: int = StatusCode.OK
    subcode: int = 0
    error_name: str = ""
    text: str = ""

    def pack(self) -> bytes:
        if isinstance(self.code, bool) or not isinstance(self.code, int) \
                or not 0 <= self.code <= 0xFFFF:
            raise EncodeError("STATUS code", "an integer in [0, 65535]", self.code)
        if isinstance(self.subcode, bool) or not isinstance(self.subcode, int) \
                or not -(1 << 63) <= self.subcode < (1 << 63):
            raise EncodeError("STATUS subcode", "a signed 64-bit integer", self.subcode)
        name = encode_name(self.error_name, "STATUS error_name", 19)
        text = encode_text(self.text, ENCODING_UTF8, "STATUS text")
        if b"\0" in text:
            raise EncodeError("STATUS text", "no NUL character", repr(self.text))
        return _STATUS_HEAD.pack(int(self.code), self.subcode, name) + text + b"\0"

    @classmethod
    def unpack(cls, content: bytes) -> Status:
        _need(cls.TYPE, content, _STATUS_HEAD.size, "header")
        code, subcode, name_raw = _STATUS_HEAD.unpack_from(content)
        text = content[_STATUS_HEAD.size:].split(b"\0", 1)[0]
        return cls(
            StatusCode(code) if code in _STATUS_CODES else code,
            subcode,
            decode_name(name_raw, "error_name", cls.TYPE),
            decode_text(text, ENCODING_UTF8, "text", cls.TYPE),
        )


# ----------------------------------------------------------------------------- POLYDATA


class AttributeKind(IntEnum):
    """Spec: polydata.md, attribute TYPE (low nibble); 0x10 marks cell data. TCOORDS
    (texture coordinates) is not in polydata.md but in the library that defines it
    (OpenIGTLink 3's igtlPolyDataMessage.h: POINT_TCOORDS 0x05, CELL_TCOORDS 0x15); Slicer
    sends it for every textured model (a vtkCubeSource has one)."""

    SCALAR = 0
    VECTOR = 1
    NORMAL = 2
    TENSOR = 3
    RGBA = 4
    TCOORDS = 5


_KIND_COMPONENTS: dict[AttributeKind, tuple[int, int]] = {
    AttributeKind.SCALAR: (1, 255),  # any count the u8 field holds
    AttributeKind.VECTOR: (3, 3),
    AttributeKind.NORMAL: (3, 3),
    AttributeKind.TENSOR: (9, 9),
    AttributeKind.RGBA: (4, 4),
    AttributeKind.TCOORDS: (1, 3),  # VTK's texture coordinates: u, uv or uvw
}
_KIND_RANGE = "0..5, +0x10 for cell data"
_CELL_FLAG = 0x10
# OpenIGTLink 3.1's C packer (igtl_polydata.c, the one Slicer links) writes NCOMPONENTS 9
# and 9*N floats for every attribute but point scalars, vectors and normals: its size and
# header switches fall through to TENSOR. Its own reader takes the first k*N floats as N
# rows of k (PolyDataAttribute::SetType fixes k; 3 for TCOORDS); the rest is filler (seen
# with a probe built against 94244fed: TCoords of 8 points came as 0x05, 9, 8, 288 bytes).
_PADDED_COMPONENTS = 9


def _components_on_wire(kind: AttributeKind, ncomp: int) -> tuple[int, int] | None:
    """(components kept, components on the wire) of an attribute header, or None when
    ``ncomp`` is not a count ``kind`` can have. The one rule for the padded layout above."""
    low, high = _KIND_COMPONENTS[kind]
    if low <= ncomp <= high:
        return ncomp, ncomp
    if ncomp == _PADDED_COMPONENTS:
        return high, ncomp
    return None
_MAX_ATTRIBUTE_NAME = 255  # IGTL_POLY_MAX_ATTR_NAME_LEN


@dataclass(eq=False)
class PolyDataAttribute:
    """One point- or cell-data array. ``data`` is (N, components) float32; N is the number
    of points, or of cells (vertices + lines + polygons + strips) when ``on_cells``."""

    name: str
    kind: AttributeKind
    data: AnyArray
    on_cells: bool = False

    __eq__ = _dataclass_eq


class _CellError(Exception):
    def __init__(self, expected: str, got: object) -> None:
        super().__init__(expected, got)
        self.expected = expected
        self.got = got


# Mixed-size cells are walked CELL_STRIDE cells a step in Python; the cells in between are
# found by numpy gathers (which let other threads run): a 60 MB array took 1.2 s of Python
# one cell a step, holding the interpreter from every other thread.
_CELL_STRIDE_LOG2 = 5
_SCAN_WINDOW = 1 << 16


def _scan_cells(flat: AnyArray, npoints: int = -1) -> tuple[int, AnyArray]:
    """Validate a VTK-legacy cell array; return (cell count, start offsets).

    Fast path: every cell has the same size (triangles, vertices, ...), checked with one
    strided comparison. Mixed sizes: `_mixed_cell_starts`.
    """
    length = len(flat)
    if length == 0:
        return 0, np.zeros(0, dtype=np.intp)
    k = int(flat[0])
    if length % (k + 1) == 0 and bool(np.all(flat[:: k + 1] == k)):
        count = length // (k + 1)
        starts = np.arange(0, length, k + 1, dtype=np.intp)
        if npoints >= 0 and k > 0:
            top = int(flat.reshape(count, k + 1)[:, 1:].max())
            if top >= npoints:
                raise _CellError(f"point indices < NPOINTS ({npoints})", f"index {top}")
        return count, starts
    starts = _mixed_cell_starts(flat)
    if npoints >= 0:
        mask = np.ones(length, dtype=bool)
        mask[starts] = False
        if mask.any():
            top = int(flat[mask].max())
            if top >= npoints:
                raise _CellError(f"point indices < NPOINTS ({npoints})", f"index {top}")
    return len(starts), starts


def _mixed_cell_starts(flat: AnyArray) -> AnyArray:
    """The start offsets of the cells of `flat` (``[n, i0..i(n-1), ...]``), which must end
    with the array. ``step[i]`` is where the next cell starts if one starts at ``i``
    (``length``: the array's end; ``length + 1``: past it; both lead to themselves);
    squared a few times, it jumps ``2**_CELL_STRIDE_LOG2`` cells, which a Python loop
    follows from 0; the cells between those checkpoints are then gathered in one go."""
    length = len(flat)
    index = np.int32 if 2 * length + 2 < np.iinfo(np.int32).max else np.int64
    step = np.empty(length + 2, dtype=index)
    np.minimum(flat, length, out=step[:length], casting="unsafe")
    for at in range(0, length, _SCAN_WINDOW * 16):  # a slice at a time: no full-size arange
        part = step[at:min(at + _SCAN_WINDOW * 16, length)]
        part += np.arange(at + 1, at + 1 + len(part), dtype=index)
    np.minimum(step, length + 1, out=step)
    step[length], step[length + 1] = length, length + 1
    jump = step
    for _ in range(_CELL_STRIDE_LOG2):
        jump = jump[jump]
    checkpoints = array("q")
    item = jump.item
    pos = 0
    while pos < length:
        checkpoints.append(pos)
        pos = item(pos)
    rows = [np.frombuffer(checkpoints, dtype=np.int64).astype(index)]
    for _ in range((1 << _CELL_STRIDE_LOG2) - 1):
        rows.append(step[rows[-1]])
    starts = np.stack(rows, axis=1).reshape(-1)
    starts = starts[starts < length].astype(np.intp)
    if pos != length:
        last = int(starts[-1])
        raise _CellError(f"cells that end with the array ({length} values)",
                         f"last cell (at {last}) runs to {last + int(flat[last]) + 1}")
    return starts


def _flat_cells(value: object, field_name: str) -> U32Array:
    arr = np.asarray(value)
    if arr.ndim != 1 or (arr.size and arr.dtype.kind not in "ui"):
        raise EncodeError(field_name, "a flat integer cell array [n, i0..i(n-1), ...]",
                          f"dtype {arr.dtype}, shape {arr.shape}")
    if arr.size and arr.dtype.kind == "i" and int(arr.min()) < 0:
        raise EncodeError(field_name, "non-negative values", int(arr.min()))
    if arr.size and int(arr.max()) > _U32_MAX:
        raise EncodeError(field_name, "values < 2**32", int(arr.max()))
    return arr.astype(np.uint32, copy=False)


def cells_from_array(indices: npt.ArrayLike) -> U32Array:
    """(M, k) point indices (k points per cell) -> flat uint32 cell array [k, i0..ik-1, ...]."""
    arr = np.asarray(indices)
    if arr.ndim != 2 or (arr.size and arr.dtype.kind not in "ui"):
        raise EncodeError("cells", "an (M, k) integer array",
                          f"dtype {arr.dtype}, shape {arr.shape}")
    if arr.size and (int(arr.min()) < 0 or int(arr.max()) > _U32_MAX):
        raise EncodeError("cells", "indices in [0, 2**32)", f"[{arr.min()}, {arr.max()}]")
    m, k = arr.shape
    out = np.empty((m, k + 1), dtype=np.uint32)
    out[:, 0] = k
    out[:, 1:] = arr
    return out.reshape(-1)


def cells_to_list(flat: npt.ArrayLike) -> list[U32Array]:
    """Flat cell array -> one index array per cell (views for equal-sized cells)."""
    arr = _flat_cells(flat, "cells")
    try:
        count, starts = _scan_cells(arr)
    except _CellError as exc:
        raise EncodeError("cells", exc.expected, exc.got) from None
    if count == 0:
        return []
    k = int(arr[0])
    if len(arr) == count * (k + 1) and bool(np.all(arr[starts] == k)):
        return list(arr.reshape(count, k + 1)[:, 1:])
    return [arr[s + 1: s + 1 + int(arr[s])] for s in starts.tolist()]


def cell_count(flat: npt.ArrayLike) -> int:
    """Number of cells in a flat cell array (EncodeError if it is malformed)."""
    try:
        return _scan_cells(_flat_cells(flat, "cells"))[0]
    except _CellError as exc:
        raise EncodeError("cells", exc.expected, exc.got) from None


def _empty_cells() -> U32Array:
    return np.zeros(0, dtype=np.uint32)


def _empty_points() -> AnyArray:
    return np.zeros((0, 3), dtype=np.float32)


_POLY_HEAD = struct.Struct(">10I")
_ATTR_HEAD = struct.Struct(">BBI")
_CELL_SECTIONS = ("vertices", "lines", "polygons", "triangle_strips")


@dataclass(eq=False)
class PolyData:
    """Spec: polydata.md. NPOINTS, (NCELLS, SIZE in bytes) for vertices, lines, polygons,
    triangle strips, NATTRIBUTES (u32 each); points f32[3N]; the four cell arrays as u32
    ``[n, i0..i(n-1), ...]``; attribute headers (TYPE u8, NCOMPONENTS u8, N u32); names,
    NUL-terminated, padded to an even total; attribute data f32."""

    TYPE: ClassVar[str] = "POLYDATA"
    points: AnyArray = field(default_factory=_empty_points)  # (N, 3) float32, mm
    vertices: U32Array = field(default_factory=_empty_cells)
    lines: U32Array = field(default_factory=_empty_cells)
    polygons: U32Array = field(default_factory=_empty_cells)
    triangle_strips: U32Array = field(default_factory=_empty_cells)
    attributes: list[PolyDataAttribute] = field(default_factory=list)

    __eq__ = _dataclass_eq

    def pack(self) -> bytes:
        return bytes(self.pack_view())

    def pack_view(self) -> memoryview:
        """`pack`'s bytes, written into one buffer by numpy (which lets other threads run
        while a model of tens of MB is converted and copied) and returned without the
        final copy, as a read-only view."""
        points = _as_array(self.points, "POLYDATA points", np.float32, "(N, 3) numbers")
        if points.ndim != 2 or points.shape[1] != 3:
            raise EncodeError("POLYDATA points", "shape (N, 3)", f"shape {points.shape}")
        npoints = points.shape[0]
        if npoints > _U32_MAX:
            raise EncodeError("POLYDATA points", "fewer than 2**32 points", npoints)
        counts: list[int] = []
        sections: list[AnyArray] = []
        for name in _CELL_SECTIONS:
            flat = _flat_cells(getattr(self, name), f"POLYDATA {name}")
            try:
                count, _ = _scan_cells(flat, npoints)
            except _CellError as exc:
                raise EncodeError(f"POLYDATA {name}", exc.expected, exc.got) from None
            if 4 * flat.size > _U32_MAX:
                raise EncodeError(f"POLYDATA {name}", "under 4 GiB", f"{4 * flat.size} bytes")
            counts += [count, 4 * flat.size]
            sections.append(flat)
        ncells = sum(counts[0::2])
        heads: list[bytes] = []
        names: list[bytes] = []
        datas: list[AnyArray] = []
        for i, attr in enumerate(self.attributes):
            what = f"POLYDATA attributes[{i}]"
            try:
                kind = AttributeKind(attr.kind)
            except ValueError:
                raise EncodeError(f"{what}.kind", "an AttributeKind (0..5)", attr.kind) from None
            name_raw = encode_text(attr.name, ENCODING_UTF8, f"{what}.name")
            if not 0 < len(name_raw) <= _MAX_ATTRIBUTE_NAME or b"\0" in name_raw:
                raise EncodeError(f"{what}.name", "1 to 255 bytes without NUL", repr(attr.name))
            data = np.asarray(attr.data)  # cast to float32 as it is written
            if data.ndim == 1:
                data = data.reshape(-1, 1)
            low, high = _KIND_COMPONENTS[kind]
            if data.ndim != 2 or not low <= data.shape[1] <= high:
                raise EncodeError(f"{what}.data", f"shape (N, {low}..{high}) for {kind.name}",
                                  f"shape {data.shape}")
            if data.dtype.kind not in "uif":
                data = _as_array(data, f"{what}.data", np.float32, "(N, components) numbers")
            n_expected = ncells if attr.on_cells else npoints
            if data.shape[0] != n_expected:
                target = "cells" if attr.on_cells else "points"
                raise EncodeError(f"{what}.data", f"{n_expected} rows (one per {target[:-1]})",
                                  f"{data.shape[0]} rows")
            heads.append(_ATTR_HEAD.pack(int(kind) | (_CELL_FLAG if attr.on_cells else 0),
                                         data.shape[1], data.shape[0]))
            names.append(name_raw + b"\0")
            datas.append(data)
        name_blob = b"".join(names)
        if len(name_blob) % 2:
            name_blob += b"\0"
        fixed = _POLY_HEAD.pack(npoints, *counts, len(self.attributes))
        attr_block = b"".join(heads) + name_blob
        total = (len(fixed) + 12 * npoints + sum(counts[1::2]) + len(attr_block)
                 + sum(4 * d.size for d in datas))
        out = np.empty(total, dtype=np.uint8)
        pos = 0

        def put_raw(raw: bytes) -> None:
            nonlocal pos
            out[pos:pos + len(raw)] = np.frombuffer(raw, dtype=np.uint8)
            pos += len(raw)

        def put_array(values: AnyArray, wire: str) -> None:
            nonlocal pos
            size = 4 * values.size
            out[pos:pos + size].view(wire).reshape(values.shape)[...] = values
            pos += size

        put_raw(fixed)
        put_array(points, ">f4")
        for flat in sections:
            put_array(flat, ">u4")
        put_raw(attr_block)
        for data in datas:
            put_array(data, ">f4")
        return out.data.toreadonly()

    @classmethod
    def unpack(cls, content: bytes) -> PolyData:
        t = cls.TYPE
        _need(t, content, _POLY_HEAD.size, "header")
        head = _POLY_HEAD.unpack_from(content)
        npoints, nattr = head[0], head[9]
        pos = _POLY_HEAD.size
        end = pos + 12 * npoints
        if end > len(content):
            raise _bad(t, "NPOINTS", f"<= {(len(content) - pos) // 12} (bytes left)", npoints)
        points = np.frombuffer(content, ">f4", 3 * npoints, pos).astype(np.float32)
        pos = end
        cells: list[U32Array] = []
        for index, name in enumerate(_CELL_SECTIONS):
            count, size = head[1 + 2 * index], head[2 + 2 * index]
            label = f"SIZE_{name.upper()}"
            if size % 4:
                raise _bad(t, label, "a multiple of 4", size)
            if pos + size > len(content):
                raise _bad(t, label, f"<= {len(content) - pos} (bytes left)", size)
            flat = np.frombuffer(content, ">u4", size // 4, pos).astype(np.uint32)
            pos += size
            try:
                found, _ = _scan_cells(flat, npoints)
            except _CellError as exc:
                raise _bad(t, name, exc.expected, exc.got) from None
            if found != count:
                raise _bad(t, f"N{name.upper()}", f"{found} (cells in {label})", count)
            cells.append(flat)
        ncells = sum(head[1:9:2])
        if pos + nattr * _ATTR_HEAD.size > len(content):
            raise _bad(t, "NATTRIBUTES", f"<= {(len(content) - pos) // 6} (bytes left)", nattr)
        attr_heads = [_ATTR_HEAD.unpack_from(content, pos + i * _ATTR_HEAD.size)
                      for i in range(nattr)]
        pos += nattr * _ATTR_HEAD.size
        names: list[str] = []
        name_start = pos
        for i in range(nattr):
            # bytes() of the name's bytes alone: the content may be a memoryview.
            nul = bytes(content[pos:pos + _MAX_ATTRIBUTE_NAME + 1]).find(b"\0")
            nul = nul + pos if nul >= 0 else nul
            if nul < 0:
                raise _bad(t, f"attribute #{i} name", "NUL-terminated, at most 255 bytes",
                           f"{bytes(content[pos:pos + 32])!r}...")
            names.append(decode_text(content[pos:nul], ENCODING_UTF8, f"attribute #{i} name", t))
            pos = nul + 1
        if (pos - name_start) % 2:
            pos += 1  # padding to an even name-block length
        attributes: list[PolyDataAttribute] = []
        for (type_byte, ncomp, n), name in zip(attr_heads, names):
            what = f"attribute {name!r}"
            try:
                kind = AttributeKind(type_byte & 0x0F)
            except ValueError:
                raise _bad(t, f"{what} TYPE", _KIND_RANGE, type_byte) from None
            if type_byte & ~(0x0F | _CELL_FLAG):
                raise _bad(t, f"{what} TYPE", _KIND_RANGE, type_byte)
            counts = _components_on_wire(kind, ncomp)
            if counts is None:
                low, high = _KIND_COMPONENTS[kind]
                raise _bad(t, f"{what} NCOMPONENTS",
                           f"{low}..{high} for {kind.name} (or {_PADDED_COMPONENTS}, "
                           "OpenIGTLink 3's padded layout)", ncomp)
            kept, on_wire = counts
            on_cells = bool(type_byte & _CELL_FLAG)
            n_expected = ncells if on_cells else npoints
            if n != n_expected:
                target = "cells" if on_cells else "points"
                raise _bad(t, f"{what} N", f"{n_expected} ({target})", n)
            size = 4 * n * on_wire
            if pos + size > len(content):
                raise _bad(t, f"{what} data", f"{size} bytes", f"{len(content) - pos} bytes left")
            data = np.frombuffer(content, ">f4", n * kept, pos).astype(np.float32)
            pos += size
            attributes.append(PolyDataAttribute(name, kind, data.reshape(n, kept), on_cells))
        if pos != len(content):
            raise _bad(t, "body", f"{pos} bytes (from the counts)", f"{len(content)} bytes")
        vertices, lines, polygons, strips = cells
        return cls(points.reshape(npoints, 3), vertices, lines, polygons, strips, attributes)


# ----------------------------------------------------------------------------- POINT

_POINT_DTYPE = np.dtype([
    ("name", "S64"), ("group", "S32"), ("rgba", "u1", (4,)), ("position", ">f4", (3,)),
    ("diameter", ">f4"), ("owner", "S20"),
])
assert _POINT_DTYPE.itemsize == 136  # IGTL_POINT_ELEMENT_SIZE


def _zeros3() -> FloatArray:
    return np.zeros(3, dtype=np.float64)


@dataclass(eq=False)
class PointElement:
    """Spec: point.md, one element. ``diameter`` is the wire's DIAMETER field (the C++
    library calls it radius and passes it through unchanged)."""

    name: str = ""
    group: str = ""
    rgba: tuple[int, int, int, int] = (255, 255, 255, 255)
    position: FloatArray = field(default_factory=_zeros3)  # (3,) mm
    diameter: float = 0.0
    owner: str = ""

    __eq__ = _dataclass_eq


@dataclass
class Point:
    """Spec: point.md. N x 136 bytes: NAME char[64], GROUP char[32], RGBA u8[4],
    XYZ f32[3], DIAMETER f32, OWNER char[20]."""

    TYPE: ClassVar[str] = "POINT"
    points: list[PointElement] = field(default_factory=list)

    def pack(self) -> bytes:
        n = len(self.points)
        table = np.zeros(n, dtype=_POINT_DTYPE)
        if n == 0:
            return b""
        what = "POINT points"
        table["name"] = [encode_name(p.name, f"{what}[{i}].name", 64)
                         for i, p in enumerate(self.points)]
        table["group"] = [encode_name(p.group, f"{what}[{i}].group", 32)
                          for i, p in enumerate(self.points)]
        table["owner"] = [encode_name(p.owner, f"{what}[{i}].owner", DEVICE_NAME_SIZE)
                          for i, p in enumerate(self.points)]
        rgba = _as_array([p.rgba for p in self.points], f"{what} rgba", np.int64,
                         "4 integers 0..255 per point")
        _check_shape(rgba, (n, 4), f"{what} rgba")
        if rgba.size and (int(rgba.min()) < 0 or int(rgba.max()) > 255):
            raise EncodeError(f"{what} rgba", "integers in 0..255", f"[{rgba.min()}, {rgba.max()}]")
        table["rgba"] = rgba
        positions = _as_array([p.position for p in self.points], f"{what} position",
                              np.float64, "3 numbers per point")
        _check_shape(positions, (n, 3), f"{what} position")
        table["position"] = positions
        table["diameter"] = _as_array([p.diameter for p in self.points], f"{what} diameter",
                                      np.float64, "a number per point")
        return table.tobytes()

    @classmethod
    def unpack(cls, content: bytes) -> Point:
        table = _element_table(cls.TYPE, content, _POINT_DTYPE)
        positions = table["position"].astype(np.float64)
        diameters = table["diameter"].astype(np.float64).tolist()
        rgbas = table["rgba"].tolist()
        t = cls.TYPE
        elements = [
            PointElement(
                decode_name(row["name"], f"points[{i}].name", t),
                decode_name(row["group"], f"points[{i}].group", t),
                (rgbas[i][0], rgbas[i][1], rgbas[i][2], rgbas[i][3]),
                positions[i],
                diameters[i],
                decode_name(row["owner"], f"points[{i}].owner", t),
            )
            for i, row in enumerate(table)
        ]
        return cls(elements)


# ----------------------------------------------------------------------------- TDATA

_TDATA_DTYPE = np.dtype([("name", "S20"), ("kind", "u1"), ("reserved", "u1"),
                         ("matrix", ">f4", (12,))])
assert _TDATA_DTYPE.itemsize == 70  # IGTL_TDATA_ELEMENT_SIZE


class TrackerKind(IntEnum):
    """Spec: trackingdata.md, TYPE_X."""

    TRACKER = 1
    INSTRUMENT_6D = 2
    INSTRUMENT_3D = 3
    INSTRUMENT_5D = 4


def _eye4() -> FloatArray:
    return np.eye(4, dtype=np.float64)


@dataclass(eq=False)
class TrackingElement:
    """Spec: trackingdata.md, one element: a named pose, as a TRANSFORM carries it."""

    name: str
    matrix: FloatArray = field(default_factory=_eye4)  # (4, 4), translation in mm
    kind: int = TrackerKind.INSTRUMENT_6D

    __eq__ = _dataclass_eq


@dataclass
class TrackingData:
    """Spec: trackingdata.md. N x 70 bytes: NAME char[20], TYPE u8, reserved u8, MATRIX
    f32[12] (TRANSFORM's layout). Several poses in one message: 3D Slicer's connector makes
    one linear transform node per element name and updates them all at once. A name has at
    most 19 bytes (`TDATA_NAME_MAX_BYTES`: what Slicer's library reads back)."""

    TYPE: ClassVar[str] = "TDATA"
    elements: list[TrackingElement] = field(default_factory=list)

    def pack(self) -> bytes:
        parts = []
        for i, element in enumerate(self.elements):
            what = f"TDATA elements[{i}]"
            name = encode_name(element.name, f"{what}.name", TDATA_NAME_MAX_BYTES)
            if not isinstance(element.kind, int) or not 0 <= element.kind <= 255:
                raise EncodeError(f"{what}.kind", "an integer 0..255", repr(element.kind))
            try:  # the matrix as a TRANSFORM packs it: checked the same way
                matrix = Transform(element.matrix).pack()
            except EncodeError as exc:
                raise EncodeError(f"{what}.matrix", exc.expected, exc.got) from None
            parts.append(name.ljust(DEVICE_NAME_SIZE, b"\0") + bytes((element.kind, 0))
                         + matrix)
        return b"".join(parts)

    @classmethod
    def unpack(cls, content: bytes) -> TrackingData:
        table = _element_table(cls.TYPE, content, _TDATA_DTYPE)
        matrices = np.zeros((len(table), 4, 4), dtype=np.float64)
        matrices[:, :3, :] = table["matrix"].astype(np.float64)[:, _IGTL12_INDEX]
        matrices[:, 3, 3] = 1.0
        kinds = table["kind"].tolist()
        return cls([TrackingElement(decode_name(row["name"], f"elements[{i}].name", cls.TYPE),
                                    matrices[i], kinds[i])
                    for i, row in enumerate(table)])


# ----------------------------------------------------------------------------- IMAGE


class ScalarType(IntEnum):
    """Spec: image.md, SCALAR_TYPE."""

    INT8 = 2
    UINT8 = 3
    INT16 = 4
    UINT16 = 5
    INT32 = 6
    UINT32 = 7
    FLOAT32 = 10
    FLOAT64 = 11


_SCALAR_DTYPES: dict[int, str] = {
    ScalarType.INT8: "i1", ScalarType.UINT8: "u1", ScalarType.INT16: "i2",
    ScalarType.UINT16: "u2", ScalarType.INT32: "i4", ScalarType.UINT32: "u4",
    ScalarType.FLOAT32: "f4", ScalarType.FLOAT64: "f8",
}
_DTYPE_SCALARS: dict[str, int] = {v: k for k, v in _SCALAR_DTYPES.items()}
# version u16, components u8, scalar type u8, endian u8, coordinate u8, size u16[3],
# matrix f32[12] (i, j, k axes scaled by spacing, then the centre), subvolume offset u16[3],
# subvolume size u16[3] (igtl_image.h: offset comes before size).
_IMAGE_HEAD = struct.Struct(">HBBBB3H12f3H3H")
_ENDIAN_BIG, _ENDIAN_LITTLE = 1, 2
_COORDINATES = {"RAS": 1, "LPS": 2}
_COORDINATE_NAMES = {v: k for k, v in _COORDINATES.items()}


def _ones3() -> FloatArray:
    return np.ones(3, dtype=np.float64)


def _eye3() -> FloatArray:
    return np.eye(3, dtype=np.float64)


@dataclass(eq=False)
class Image:
    """Spec: image.md. 72-byte image header, then the pixels, i fastest.

    ``pixels`` is (slices, rows, columns, components) = (k, j, i, c). ``directions`` holds
    the unit vectors of the i, j, k axes as columns; ``origin`` is the centre of the FIRST
    voxel, like Slicer's IJKToRAS. The wire carries the centre of the whole volume instead
    (image.md: "position of the center of the image"; pyigtl and OpenIGTLinkIO's image
    converter shift by (size - 1) / 2 voxels): pack and unpack convert. Pixels go out
    little-endian (ENDIAN = 2), which every current host uses natively: no byte swap.
    """

    TYPE: ClassVar[str] = "IMAGE"
    pixels: AnyArray
    spacing: FloatArray = field(default_factory=_ones3)
    directions: FloatArray = field(default_factory=_eye3)
    origin: FloatArray = field(default_factory=_zeros3)
    coordinate: str = "RAS"

    __eq__ = _dataclass_eq

    def _head_and_pixels(self) -> tuple[bytes, AnyArray]:
        """The IMAGE header's bytes and the pixels (as given), checked."""
        pixels = np.asarray(self.pixels)
        if pixels.ndim != 4:
            raise EncodeError("IMAGE pixels", "4 dimensions (slices, rows, columns, components)",
                              f"shape {pixels.shape}")
        scalar = _DTYPE_SCALARS.get(pixels.dtype.str[1:])
        if scalar is None:
            raise EncodeError("IMAGE pixels dtype", "one of " + ", ".join(_DTYPE_SCALARS),
                              str(pixels.dtype))
        k, j, i, c = pixels.shape
        if not 1 <= c <= 255:
            raise EncodeError("IMAGE pixels components", "1..255", c)
        if not all(1 <= s <= 0xFFFF for s in (i, j, k)):
            raise EncodeError("IMAGE pixels size", "1..65535 per axis", f"shape {pixels.shape}")
        coordinate = _COORDINATES.get(self.coordinate)
        if coordinate is None:
            raise EncodeError("IMAGE coordinate", "'RAS' or 'LPS'", self.coordinate)
        spacing = _as_array(self.spacing, "IMAGE spacing", np.float64, "3 numbers")
        _check_shape(spacing, (3,), "IMAGE spacing")
        directions = _as_array(self.directions, "IMAGE directions", np.float64, "3x3 numbers")
        _check_shape(directions, (3, 3), "IMAGE directions")
        origin = _as_array(self.origin, "IMAGE origin", np.float64, "3 numbers")
        _check_shape(origin, (3,), "IMAGE origin")
        axes = directions * spacing  # column a = unit axis a times its spacing
        centre = origin + axes @ ((np.array([i, j, k], dtype=np.float64) - 1.0) / 2.0)
        geometry = np.concatenate([axes.T.ravel(), centre])
        # The header holds float32: finite values beyond its range cannot be written.
        if not fits_float32(*geometry.tolist()):
            raise EncodeError("IMAGE geometry", "spacing, directions and origin whose "
                              "products fit float32", f"axes and centre {geometry.tolist()}")
        head = _IMAGE_HEAD.pack(
            1, c, scalar, _ENDIAN_LITTLE, coordinate, i, j, k,
            *axes[:, 0], *axes[:, 1], *axes[:, 2], *centre,
            0, 0, 0, i, j, k,
        )
        return head, pixels

    def pack(self) -> bytes:
        head, pixels = self.pack_parts()
        return head + bytes(pixels)

    def pack_parts(self) -> tuple[bytes, memoryview]:
        """`pack`'s bytes as the image header and the pixels. Pixels already laid out as
        sent (contiguous rows, little-endian) are not copied: a video frame read where it
        lies in its ROS message goes from there to the socket. Others are packed once."""
        head, pixels = self._head_and_pixels()
        little = pixels.dtype.newbyteorder("<")
        if pixels.dtype != little or not pixels.flags.c_contiguous:
            pixels = np.ascontiguousarray(pixels, dtype=little)
        return head, pixels.reshape(-1).view(np.uint8).data.toreadonly()

    @classmethod
    def unpack(cls, content: bytes) -> Image:
        t = cls.TYPE
        _need(t, content, _IMAGE_HEAD.size, "image header")
        values = _IMAGE_HEAD.unpack_from(content)
        _version, c, scalar, endian, coordinate = values[:5]
        size = values[5:8]
        matrix = np.array(values[8:20], dtype=np.float64).reshape(4, 3).T  # columns t, s, n, p
        offset, sub = values[20:23], values[23:26]
        base = _SCALAR_DTYPES.get(scalar)
        if base is None:
            raise _bad(t, "SCALAR_TYPE", "2..7, 10 or 11", scalar)
        if endian not in (_ENDIAN_BIG, _ENDIAN_LITTLE):
            raise _bad(t, "ENDIAN", "1 (big) or 2 (little)", endian)
        name = _COORDINATE_NAMES.get(coordinate)
        if name is None:
            raise _bad(t, "COORD", "1 (RAS) or 2 (LPS)", coordinate)
        if c == 0 or 0 in size or 0 in sub:
            raise _bad(t, "size", "components and sizes >= 1",
                       f"components {c}, size {size}, subvolume {sub}")
        if any(o + s > full for o, s, full in zip(offset, sub, size)):
            raise _bad(t, "subvolume", f"offset + size <= size {size}",
                       f"offset {offset}, size {sub}")
        dtype = np.dtype(("<" if endian == _ENDIAN_LITTLE else ">") + base)
        count = sub[0] * sub[1] * sub[2] * c
        if len(content) - _IMAGE_HEAD.size != count * dtype.itemsize:
            raise _bad(t, "pixel data", f"{count * dtype.itemsize} bytes "
                       f"({sub[0]}x{sub[1]}x{sub[2]}x{c} {dtype.name})",
                       f"{len(content) - _IMAGE_HEAD.size} bytes")
        pixels = np.frombuffer(content, dtype, count, _IMAGE_HEAD.size)
        if not dtype.isnative:
            pixels = pixels.astype(dtype.newbyteorder("="))
        axes = matrix[:, :3]
        spacing = np.linalg.norm(axes, axis=0)
        if not np.all(spacing > 0):
            raise _bad(t, "matrix", "non-zero i, j, k axis vectors", f"lengths {spacing}")
        directions = axes / spacing
        # Wire position = centre of the whole volume; a subvolume starts `offset` voxels in.
        first = matrix[:, 3] - axes @ ((np.array(size, dtype=np.float64) - 1.0) / 2.0)
        origin = first + axes @ np.array(offset, dtype=np.float64)
        return cls(pixels.reshape(sub[2], sub[1], sub[0], c), spacing, directions, origin, name)


# ----------------------------------------------------------------------------- COMMAND

_COMMAND_HEAD = struct.Struct(">I128sHI")


@dataclass
class _CommandLayout:
    # Shared by COMMAND and RTS_COMMAND; not a public base, so isinstance(x, Command) does
    # not match replies.
    TYPE: ClassVar[str] = ""
    command_id: int
    name: str
    text: str
    encoding: int = ENCODING_UTF8

    def pack(self) -> bytes:
        if isinstance(self.command_id, bool) or not isinstance(self.command_id, int) \
                or not 0 <= self.command_id <= _U32_MAX:
            raise EncodeError(f"{self.TYPE} command_id", "an integer in [0, 2**32)",
                              self.command_id)
        name = encode_name(self.name, f"{self.TYPE} name", 128)
        text = encode_text(self.text, self.encoding, f"{self.TYPE} text")
        if len(text) > _U32_MAX:
            raise EncodeError(f"{self.TYPE} text", "under 4 GiB", f"{len(text)} bytes")
        return _COMMAND_HEAD.pack(self.command_id, name, self.encoding, len(text)) + text

    @classmethod
    def _fields_from(cls, content: bytes) -> tuple[int, str, str, int]:
        t = cls.TYPE
        _need(t, content, _COMMAND_HEAD.size, "header")
        command_id, name_raw, encoding, length = _COMMAND_HEAD.unpack_from(content)
        end = _COMMAND_HEAD.size + length
        if end > len(content):
            raise _bad(t, "LENGTH", f"<= {len(content) - _COMMAND_HEAD.size} (bytes left)",
                       length)
        name = decode_name(name_raw, "name", t)
        text = decode_text(content[_COMMAND_HEAD.size:end], encoding, "text", t)
        return command_id, name, text, encoding


@dataclass
class Command(_CommandLayout):
    """Spec: command.md (protocol 3). COMMAND_ID u32, COMMAND_NAME char[128],
    ENCODING u16 (MIBenum), LENGTH u32, COMMAND text (usually XML)."""

    TYPE: ClassVar[str] = "COMMAND"

    @classmethod
    def unpack(cls, content: bytes) -> Command:
        return cls(*cls._fields_from(content))


@dataclass
class RtsCommand(_CommandLayout):
    """Spec: command.md. The reply to a COMMAND; same layout and fields."""

    TYPE: ClassVar[str] = "RTS_COMMAND"

    @classmethod
    def unpack(cls, content: bytes) -> RtsCommand:
        return cls(*cls._fields_from(content))


# ----------------------------------------------------------------------------- JSON

_JSON_HEAD = struct.Struct(">I")


@dataclass
class Json:
    """This project's own type, not in the OpenIGTLink spec: one JSON document, LENGTH u32
    then UTF-8 text. The daemon sends it only to its own clients that ask for it (a
    subscriber's message stream, `create_subscriber` with ``messages``): STRING stops at
    65535 bytes, and an OpenIGTLink peer that did not ask never sees this type."""

    TYPE: ClassVar[str] = "JSON"
    text: str

    def pack(self) -> bytes:
        raw = encode_text(self.text, ENCODING_UTF8, "JSON text")
        if len(raw) > _U32_MAX:
            raise EncodeError("JSON text", "under 4 GiB", f"{len(raw)} bytes")
        return _JSON_HEAD.pack(len(raw)) + raw

    @classmethod
    def unpack(cls, content: bytes) -> Json:
        _need(cls.TYPE, content, _JSON_HEAD.size, "header")
        (length,) = _JSON_HEAD.unpack_from(content)
        end = _JSON_HEAD.size + length
        if end > len(content):
            raise _bad(cls.TYPE, "LENGTH", f"<= {len(content) - _JSON_HEAD.size} (bytes left)",
                       length)
        return cls(decode_text(content[_JSON_HEAD.size:end], ENCODING_UTF8, "text", cls.TYPE))


def document_body(text: str) -> String | Json:
    """A JSON document as the body that carries it: a STRING (UTF-8) when it fits one
    (65535 bytes), since every OpenIGTLink peer reads STRING (3D Slicer's connector imports
    it as a text node); a JSON message beyond."""
    if len(text.encode("utf-8")) <= 0xFFFF:
        return String(text, ENCODING_UTF8)
    return Json(text)


# ----------------------------------------------------------------------------- others


@dataclass
class RawBody:
    """A message of a type this module does not decode (or a GET_/STT_/STP_ query),
    passed through unchanged."""

    type_name: str
    data: Union[bytes, bytearray, memoryview]  # a packed model: a view of its one buffer

    def pack(self) -> bytes:
        return bytes(self.data)


KnownBody = Union[Transform, String, Status, PolyData, Point, TrackingData, Image, Command,
                  RtsCommand, Json]
Body = Union[Transform, String, Status, PolyData, Point, TrackingData, Image, Command,
             RtsCommand, Json, RawBody]

BODY_TYPES: dict[str, type[KnownBody]] = {
    cls.TYPE: cls
    for cls in (Transform, String, Status, PolyData, Point, TrackingData, Image, Command,
                RtsCommand, Json)
}

_UNPACKERS: dict[str, Callable[[bytes], Body]] = {
    name: cls.unpack for name, cls in BODY_TYPES.items()
}


# Bodies whose unpackers read only with struct and numpy, so a large body (a read-only view
# on its own buffer, protocol/framing.py) is decoded in place: copying a 60 MB POLYDATA
# first held the interpreter from every other thread. The others get bytes.
_READ_IN_PLACE = frozenset({PolyData.TYPE, Image.TYPE})


def unpack_body(type_name: str, content: bytes) -> Body:
    """Decode ``content`` by type name; unknown types become `RawBody`. Only `BodyError`
    leaves this function: stray low-level errors are wrapped, naming the type."""
    unpack = _UNPACKERS.get(type_name)
    if unpack is None:
        return RawBody(type_name, bytes(content))
    try:
        return unpack(content if type_name in _READ_IN_PLACE else bytes(content))
    except BodyError:
        raise
    except (struct.error, ValueError, IndexError, TypeError, OverflowError,
            UnicodeDecodeError) as exc:  # a safety net; the unpackers check before reading
        raise BodyError("body", f"a well-formed {type_name} body",
                        f"{type(exc).__name__}: {exc}", type_name=type_name) from exc


@dataclass
class Message:
    """One OpenIGTLink message: header fields plus a decoded body.

    ``timestamp`` is the raw 32.32 fixed-point u64 (0 = unset; the sender sets it).
    ``metadata`` and ``message_id`` only travel with header version 2; ``header_version``
    records the version the message arrived with.
    """

    device_name: str
    body: Body
    timestamp: int = 0
    metadata: dict[str, str] = field(default_factory=dict)
    message_id: int = 0
    header_version: int = 1

    @property
    def type_name(self) -> str:
        if isinstance(self.body, RawBody):
            return self.body.type_name
        return self.body.TYPE
