"""std_msgs: Empty, String, Bool, Int64, Float64 (STRING text) and Int64MultiArray /
Float64MultiArray, 1-D arrays and 2-D tables (STRING holding JSON, shape preserved)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from bridge.codecs.base import (
    KEY_FORMAT,
    KEY_LABELS,
    KEY_SHAPE,
    Body,
    TypeCodec,
    json_body,
    parse_json_text,
    string_text,
    text_body,
)
from bridge.codecs.errors import CodecError
from bridge.codecs.generic import check_float, check_int, numeric_array

__all__ = [
    "BoolCodec",
    "EmptyCodec",
    "Float64Codec",
    "Int64Codec",
    "MultiArrayCodec",
    "StringCodec",
    "multiarray_to_ndarray",
]

_TRUE = ("true", "1", "yes", "on")
_FALSE = ("false", "0", "no", "off")


def _text_meta() -> dict[str, str]:
    return {KEY_FORMAT: "text"}


@dataclass(frozen=True)
class EmptyCodec(TypeCodec):
    """std_msgs/Empty <-> STRING "" ; value ``None``."""

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        return text_body(""), _text_meta()

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        string_text(body, self.ros_type)  # any text: the message carries nothing
        return self.message_class()

    def _to_value(self, msg: Any) -> Any:
        return None

    def _from_value(self, value: Any) -> Any:
        if value not in (None, {}, [], ""):
            raise CodecError(field="value", expected="null (std_msgs/Empty carries nothing)",
                             got=repr(value)[:60])
        return self.message_class()


@dataclass(frozen=True)
class StringCodec(TypeCodec):
    """std_msgs/String <-> STRING text (UTF-8); value ``str``."""

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        return text_body(msg.data), _text_meta()

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        return self.message_class(data=string_text(body, self.ros_type))

    def _to_value(self, msg: Any) -> Any:
        return msg.data

    def _from_value(self, value: Any) -> Any:
        if not isinstance(value, str):
            raise CodecError(field="value", expected="a string", got=type(value).__name__)
        return self.message_class(data=value)


def parse_bool(text: str, field: str = "text") -> bool:
    norm = text.strip().lower()
    if norm in _TRUE:
        return True
    if norm in _FALSE:
        return False
    raise CodecError(field=field, expected="true/false (or 1/0, yes/no, on/off)",
                     got=repr(text[:60]))


@dataclass(frozen=True)
class BoolCodec(TypeCodec):
    """std_msgs/Bool <-> STRING "true"/"false"; value ``bool``."""

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        return text_body("true" if msg.data else "false"), _text_meta()

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        return self.message_class(data=parse_bool(string_text(body, self.ros_type)))

    def _to_value(self, msg: Any) -> Any:
        return bool(msg.data)

    def _from_value(self, value: Any) -> Any:
        if not isinstance(value, bool):
            raise CodecError(field="value", expected="true or false", got=repr(value)[:60])
        return self.message_class(data=value)


@dataclass(frozen=True)
class Int64Codec(TypeCodec):
    """std_msgs/Int64 <-> STRING decimal text; value ``int`` (int64 range checked)."""

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        return text_body(str(int(msg.data))), _text_meta()

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        text = string_text(body, self.ros_type).strip()
        try:
            value = int(text, 10)
        except ValueError:
            raise CodecError(field="text", expected="a decimal integer",
                             got=repr(text[:60])) from None
        return self.message_class(data=check_int(value, "text", "int64"))

    def _to_value(self, msg: Any) -> Any:
        return int(msg.data)

    def _from_value(self, value: Any) -> Any:
        return self.message_class(data=check_int(value, "value", "int64"))


@dataclass(frozen=True)
class Float64Codec(TypeCodec):
    """std_msgs/Float64 <-> STRING text (``repr``: shortest exact form, ``nan``/``inf``);
    value ``float``."""

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        return text_body(repr(float(msg.data))), _text_meta()

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        text = string_text(body, self.ros_type).strip()
        try:
            value = float(text)
        except ValueError:
            raise CodecError(field="text", expected="a number", got=repr(text[:60])) from None
        return self.message_class(data=value)

    def _to_value(self, msg: Any) -> Any:
        return float(msg.data)

    def _from_value(self, value: Any) -> Any:
        return self.message_class(data=check_float(value, "value"))


# --------------------------------------------------------------------------- multi-arrays

def multiarray_to_ndarray(msg: Any) -> np.ndarray:
    """The N-D array a std_msgs MultiArray describes (layout.dim sizes and strides,
    data_offset), as a fresh numpy array. With no dims: 1-D over all of ``data``.

    Strides follow std_msgs/MultiArrayLayout: element (i, j, ...) is at
    ``data_offset + i * dim[1].stride + j * dim[2].stride + ...`` (the last index steps by 1),
    so padded rows are honoured. Publishers that fill only sizes (all strides 0) are read as
    contiguous row-major.
    """
    dtype = np.int64 if msg.data.typecode == "q" else np.float64
    flat = np.frombuffer(msg.data, dtype=dtype) if len(msg.data) else np.zeros(0, dtype)
    dims = list(msg.layout.dim)
    offset = int(msg.layout.data_offset)
    if not dims:
        whole: np.ndarray = flat[offset:].copy()  # mypy reads numpy's ndarray.copy() as Any
        return whole
    shape = tuple(int(d.size) for d in dims)
    strides_el = [int(d.stride) for d in dims[1:]] + [1]
    if all(int(d.stride) == 0 for d in dims):
        strides_el = [int(np.prod(shape[i + 1:], dtype=np.int64)) for i in range(len(shape))]
    count = int(np.prod(shape, dtype=np.int64))
    if count == 0:
        return np.zeros(shape, dtype=dtype)
    last = offset + sum((n - 1) * s for n, s in zip(shape, strides_el))
    if last >= flat.size:
        raise CodecError(field="layout", expected=f"dims and data_offset within the "
                         f"{flat.size} data elements", got=f"shape {shape}, strides {strides_el},"
                         f" offset {offset} (needs {last + 1})")
    view = np.lib.stride_tricks.as_strided(flat[offset:], shape=shape,
                                           strides=[s * flat.itemsize for s in strides_el],
                                           writeable=False)
    return np.array(view)


def _shape_text(shape: tuple[int, ...]) -> str:
    return "x".join(str(n) for n in shape)


@dataclass(frozen=True)
class MultiArrayCodec(TypeCodec):
    """Int64MultiArray / Float64MultiArray <-> STRING holding the JSON nested list.

    A 1-D array is ``[1, 2, 3]``, a 2-D table ``[[1, 2], [3, 4]]`` (rows of columns). The
    shape also travels as metadata ``ros2.shape`` ("2x3", keeps an empty table's shape) and
    dim labels as ``ros2.labels``. Back, the JSON may also be an object
    ``{"data": ..., "shape": [...], "labels": [...]}`` with flat or nested data.
    """

    base: str = "double"  # "int64" or "double"

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        arr = multiarray_to_ndarray(msg)
        meta = {KEY_FORMAT: "json", KEY_SHAPE: _shape_text(arr.shape)}
        labels = [d.label for d in msg.layout.dim]
        if any(labels):
            meta[KEY_LABELS] = json.dumps(labels)
        return json_body(arr.tolist()), meta

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        value = parse_json_text(string_text(body, self.ros_type))
        if not isinstance(value, dict):
            shape_text = metadata.get(KEY_SHAPE)
            labels_text = metadata.get(KEY_LABELS)
            value = {"data": value}
            if shape_text:
                try:
                    value["shape"] = [int(n) for n in shape_text.split("x")]
                except ValueError:
                    raise CodecError(field=f"metadata.{KEY_SHAPE}", expected="sizes like '2x3'",
                                     got=repr(shape_text)) from None
            if labels_text:
                value["labels"] = parse_json_text(labels_text, f"metadata.{KEY_LABELS}")
        return self._build(value, "text")

    def _to_value(self, msg: Any) -> Any:
        return multiarray_to_ndarray(msg).tolist()

    def _from_value(self, value: Any) -> Any:
        return self._build(value if isinstance(value, dict) else {"data": value}, "value")

    def _build(self, spec: dict[str, Any], where: str) -> Any:
        unknown = sorted(set(spec) - {"data", "shape", "labels"})
        if unknown:
            raise CodecError(field=f"{where}.{unknown[0]}", expected="data, shape or labels",
                             got="an unknown key")
        data_field = f"{where}.data" if where != "text" or "shape" in spec else where
        arr = numeric_array(spec.get("data", []), data_field, self.base, ndim=None)
        shape_value = spec.get("shape")
        if shape_value is not None:
            if not isinstance(shape_value, list):
                raise CodecError(field=f"{where}.shape", expected="a list of sizes",
                                 got=type(shape_value).__name__)
            shape = tuple(check_int(n, f"{where}.shape[{i}]", "uint32")
                          for i, n in enumerate(shape_value))
            if int(np.prod(shape, dtype=np.int64)) != arr.size:
                raise CodecError(field=f"{where}.shape", expected=f"sizes whose product is "
                                 f"{arr.size} (the number of data elements)",
                                 got=_shape_text(shape))
            arr = arr.reshape(shape)
        labels: list[str] = []
        if spec.get("labels") is not None:
            raw = spec["labels"]
            if not (isinstance(raw, list) and all(isinstance(x, str) for x in raw)
                    and len(raw) == arr.ndim):
                raise CodecError(field=f"{where}.labels",
                                 expected=f"{arr.ndim} strings (one per dimension)",
                                 got=repr(raw)[:60])
            labels = raw
        return self._message(arr, labels)

    def _message(self, arr: np.ndarray, labels: list[str]) -> Any:
        from std_msgs.msg import MultiArrayDimension

        msg = self.message_class()
        flat = np.ascontiguousarray(arr, dtype=np.int64 if self.base == "int64" else np.float64)
        msg.data.frombytes(flat.tobytes())
        # A plain 1-D array needs no layout; tables (and labelled arrays) get row-major dims.
        if arr.ndim > 1 or labels:
            shape = arr.shape
            msg.layout.dim = [
                MultiArrayDimension(label=labels[i] if labels else "", size=int(n),
                                    stride=int(np.prod(shape[i:], dtype=np.int64)))
                for i, n in enumerate(shape)
            ]
        return msg
