"""Hypothesis strategies for every OpenIGTLink body type and for whole messages."""

from __future__ import annotations

from typing import Any

import numpy as np
from hypothesis import strategies as st

from protocol.messages import (
    AttributeKind,
    Command,
    Image,
    Message,
    Point,
    PointElement,
    PolyData,
    PolyDataAttribute,
    RawBody,
    RtsCommand,
    Status,
    String,
    TrackingData,
    TrackingElement,
    Transform,
    cells_from_array,
)

# Values exactly representable in float32, so equality after a round trip is exact.
f32 = st.floats(-1e6, 1e6, allow_nan=False, width=32)


def utf8_max(size: int, *, alphabet: Any = None) -> st.SearchStrategy[str]:
    """Text of at most ``size`` UTF-8 bytes, no NUL, no lone surrogates."""
    chars = alphabet if alphabet is not None else st.characters(
        blacklist_categories=("Cs",), blacklist_characters="\0")
    return st.text(chars, max_size=size).filter(lambda s: len(s.encode("utf-8")) <= size)


ascii_text = st.characters(min_codepoint=1, max_codepoint=127)


@st.composite
def transforms(draw: st.DrawFn) -> Transform:
    values = draw(st.lists(f32, min_size=12, max_size=12))
    matrix = np.eye(4)
    matrix[:3, :] = np.array(values, dtype=np.float64).reshape(3, 4)
    return Transform(matrix)


@st.composite
def strings(draw: st.DrawFn) -> String:
    if draw(st.booleans()):
        return String(draw(st.text(ascii_text | st.just("\0"), max_size=300)), 3)
    return String(draw(utf8_max(300, alphabet=st.characters(blacklist_categories=("Cs",)))), 106)


statuses = st.builds(
    Status,
    code=st.integers(0, 0xFFFF),
    subcode=st.integers(-(1 << 63), (1 << 63) - 1),
    error_name=utf8_max(19),
    text=utf8_max(200),
)


@st.composite
def cell_arrays(draw: st.DrawFn, npoints: int) -> np.ndarray:
    if npoints == 0 or draw(st.booleans()):
        return np.zeros(0, dtype=np.uint32)
    if draw(st.booleans()):  # equal-sized cells: the vectorised path
        k = draw(st.integers(1, 4))
        m = draw(st.integers(1, 20))
        idx = draw(st.lists(st.integers(0, npoints - 1), min_size=m * k, max_size=m * k))
        return cells_from_array(np.array(idx).reshape(m, k))
    cells = draw(st.lists(st.lists(st.integers(0, npoints - 1), max_size=6), min_size=1,
                          max_size=12))
    flat: list[int] = []
    for cell in cells:
        flat += [len(cell), *cell]
    return np.array(flat, dtype=np.uint32)


_COMPONENTS = {AttributeKind.SCALAR: st.integers(1, 4), AttributeKind.VECTOR: st.just(3),
               AttributeKind.NORMAL: st.just(3), AttributeKind.TENSOR: st.just(9),
               AttributeKind.RGBA: st.just(4), AttributeKind.TCOORDS: st.integers(1, 3)}


@st.composite
def polydatas(draw: st.DrawFn) -> PolyData:
    n = draw(st.integers(0, 30))
    points = np.array(draw(st.lists(f32, min_size=3 * n, max_size=3 * n)),
                      dtype=np.float32).reshape(n, 3)
    poly = PolyData(points, *(draw(cell_arrays(n)) for _ in range(4)))
    from protocol.messages import cell_count

    ncells = sum(cell_count(c) for c in (poly.vertices, poly.lines, poly.polygons,
                                         poly.triangle_strips))
    for _ in range(draw(st.integers(0, 3))):
        kind = draw(st.sampled_from(list(AttributeKind)))
        comps = draw(_COMPONENTS[kind])
        on_cells = draw(st.booleans())
        rows = ncells if on_cells else n
        data = np.array(draw(st.lists(f32, min_size=rows * comps, max_size=rows * comps)),
                        dtype=np.float32).reshape(rows, comps)
        name = draw(utf8_max(40).filter(lambda s: len(s) > 0))
        poly.attributes.append(PolyDataAttribute(name, kind, data, on_cells))
    return poly


point_elements = st.builds(
    PointElement,
    name=utf8_max(64),
    group=utf8_max(32),
    rgba=st.tuples(*(st.integers(0, 255),) * 4),
    position=st.lists(f32, min_size=3, max_size=3).map(lambda v: np.array(v, dtype=np.float64)),
    diameter=f32.map(float),
    owner=utf8_max(20),
)
points = st.builds(Point, st.lists(point_elements, max_size=8))
tracking_data = st.builds(TrackingData, st.lists(st.builds(
    TrackingElement, utf8_max(19), transforms().map(lambda t: t.matrix), st.integers(0, 255)),
    max_size=8))

_DTYPES = ["u1", "i1", "u2", "i2", "u4", "i4", "f4", "f8"]


@st.composite
def images(draw: st.DrawFn) -> Image:
    shape = tuple(draw(st.integers(1, 5)) for _ in range(3)) + (draw(st.integers(1, 4)),)
    dtype = np.dtype(draw(st.sampled_from(_DTYPES)))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    if dtype.kind == "f":
        pixels = rng.normal(size=shape).astype(dtype)
    else:
        info = np.iinfo(dtype)
        pixels = rng.integers(info.min, info.max, size=shape, endpoint=True, dtype=dtype)
    # Unit directions and spacings that are exact in float32 keep the geometry exact.
    directions = np.eye(3)[:, draw(st.permutations([0, 1, 2]))] * np.array(
        draw(st.lists(st.sampled_from([-1.0, 1.0]), min_size=3, max_size=3)))
    spacing = np.array(draw(st.lists(st.sampled_from([0.25, 0.5, 1.0, 2.0, 3.0]),
                                     min_size=3, max_size=3)))
    origin = np.array(draw(st.lists(st.integers(-1000, 1000), min_size=3, max_size=3)),
                      dtype=np.float64) / 4
    return Image(pixels, spacing, directions, origin, draw(st.sampled_from(["RAS", "LPS"])))


@st.composite
def commands(draw: st.DrawFn, cls: type = Command) -> Any:
    encoding = draw(st.sampled_from([3, 106]))
    text = draw(st.text(ascii_text, max_size=200)) if encoding == 3 else draw(utf8_max(200))
    return cls(draw(st.integers(0, 2**32 - 1)), draw(utf8_max(128)), text, encoding)


raw_bodies = st.builds(RawBody, st.sampled_from(["GET_POLYDATA", "NDARRAY", "STT_TDATA", "X"]),
                       st.binary(max_size=64))

bodies = st.one_of(transforms(), strings(), statuses, polydatas(), points, tracking_data,
                   images(), commands(), commands(RtsCommand), raw_bodies)


@st.composite
def messages(draw: st.DrawFn, header_version: int | None = None) -> Message:
    version = header_version or draw(st.sampled_from([1, 2]))
    metadata: dict[str, str] = {}
    message_id = 0
    if version == 2:
        metadata = draw(st.dictionaries(utf8_max(30).filter(bool), utf8_max(60), max_size=4))
        message_id = draw(st.integers(0, 2**32 - 1))
    return Message(draw(utf8_max(20)), draw(bodies), draw(st.integers(0, 2**64 - 1)),
                   metadata, message_id, version)
