"""std_msgs scalars (STRING text) and multi-arrays / tables (STRING JSON, shape kept)."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from std_msgs.msg import (
    Bool,
    Empty,
    Float64,
    Float64MultiArray,
    Int64,
    Int64MultiArray,
    MultiArrayDimension,
)
from std_msgs.msg import String as RosString

from bridge.codecs import CodecError, codec_for
from protocol.messages import String, Transform, unpack_body


def _wire(body: Any) -> Any:
    return unpack_body(body.TYPE, body.pack())


@pytest.mark.parametrize("type_name, msg, text, value", [
    ("Empty", Empty(), "", None),
    ("String", RosString(data="hello ✓"), "hello ✓", "hello ✓"),
    ("Bool", Bool(data=True), "true", True),
    ("Bool", Bool(data=False), "false", False),
    ("Int64", Int64(data=-(2**63)), str(-(2**63)), -(2**63)),
    ("Float64", Float64(data=3.1415), "3.1415", 3.1415),
])
def test_scalar_round_trips(type_name: str, msg: Any, text: str, value: Any) -> None:
    codec = codec_for(type_name)
    enc = codec.encode(msg)
    assert isinstance(enc.body, String) and enc.body.text == text
    assert enc.metadata["ros2.format"] == "text"
    assert codec.from_igtl(_wire(enc.body)) == msg
    assert codec.to_value(msg) == value
    assert codec.from_value(json.loads(json.dumps(value))) == msg


def test_float64_special_values() -> None:
    codec = codec_for("Float64")
    assert math.isinf(codec.from_igtl(codec.to_igtl(Float64(data=-math.inf))).data)
    assert math.isnan(codec.from_igtl(String(text=" nan ")).data)


def test_text_from_slicer_is_parsed_leniently() -> None:
    assert codec_for("Bool").from_igtl(String(text=" Yes\n")).data is True
    assert codec_for("Int64").from_igtl(String(text=" 42 ")).data == 42


@pytest.mark.parametrize("type_name, text, field", [
    ("Bool", "maybe", "text"),
    ("Int64", "4.5", "text"),
    ("Int64", str(2**63), "text"),
    ("Float64", "pi", "text"),
])
def test_bad_text_names_the_field(type_name: str, text: str, field: str) -> None:
    with pytest.raises(CodecError) as err:
        codec_for(type_name).from_igtl(String(text=text))
    assert err.value.field == field


@pytest.mark.parametrize("type_name, value", [
    ("Bool", 1), ("Bool", "true"), ("Int64", "42"), ("Int64", 2**63), ("Int64", 1.5),
    ("Int64", True), ("Float64", "1.0"), ("Float64", None), ("String", 5), ("Empty", 0),
])
def test_bad_values_name_the_value(type_name: str, value: Any) -> None:
    with pytest.raises(CodecError) as err:
        codec_for(type_name).from_value(value)
    assert err.value.field == "value"


def test_wrong_body_type() -> None:
    with pytest.raises(CodecError) as err:
        codec_for("String").from_igtl(Transform(np.eye(4)))
    assert err.value.field == "body"


# --------------------------------------------------------------------------- multi-arrays

def _table() -> Float64MultiArray:
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label="rows", size=2, stride=6),
                      MultiArrayDimension(label="cols", size=3, stride=3)]
    msg.data = [0.5, 1.5, 2.5, 3.5, 4.5, 5.5]
    return msg


def test_2d_table_round_trips_with_its_shape() -> None:
    codec = codec_for("DoubleTable")
    msg = _table()
    enc = codec.encode(msg)
    assert json.loads(enc.body.text) == [[0.5, 1.5, 2.5], [3.5, 4.5, 5.5]]
    assert enc.metadata["ros2.shape"] == "2x3"
    assert json.loads(enc.metadata["ros2.labels"]) == ["rows", "cols"]
    back = codec.from_igtl(_wire(enc.body), metadata=enc.metadata)
    assert back == msg
    assert codec.to_value(msg) == [[0.5, 1.5, 2.5], [3.5, 4.5, 5.5]]
    # from a client's value: shape kept, row-major strides
    v = codec.from_value([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    assert [(d.size, d.stride) for d in v.layout.dim] == [(2, 6), (3, 3)]
    assert list(v.data) == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]


def test_empty_table_keeps_its_shape_through_metadata() -> None:
    codec = codec_for("Float64MultiArray")
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label="", size=0, stride=0),
                      MultiArrayDimension(label="", size=4, stride=4)]
    enc = codec.encode(msg)
    assert enc.body.text == "[]" and enc.metadata["ros2.shape"] == "0x4"
    back = codec.from_igtl(enc.body, metadata=enc.metadata)
    assert [d.size for d in back.layout.dim] == [0, 4]


def test_padded_strides_and_offset_are_honoured() -> None:
    # 2 x 2 view into a 3-wide buffer, starting at element 1.
    msg = Int64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label="r", size=2, stride=6),
                      MultiArrayDimension(label="c", size=2, stride=3)]
    msg.layout.data_offset = 1
    msg.data = [9, 1, 2, 9, 3, 4, 9]
    assert codec_for("IntTable").to_value(msg) == [[1, 2], [3, 4]]


def test_sizes_without_strides_read_row_major() -> None:
    msg = Int64MultiArray()
    msg.layout.dim = [MultiArrayDimension(size=2), MultiArrayDimension(size=2)]
    msg.data = [1, 2, 3, 4]
    assert codec_for("IntTable").to_value(msg) == [[1, 2], [3, 4]]


def test_1d_int_array_round_trips() -> None:
    codec = codec_for("IntArray")
    msg = Int64MultiArray(data=[1, -2, 2**62])
    enc = codec.encode(msg)
    assert json.loads(enc.body.text) == [1, -2, 2**62]
    assert codec.from_igtl(_wire(enc.body), metadata=enc.metadata) == msg
    assert codec.from_value([1, -2, 2**62]) == msg


def test_dict_form_with_flat_data_and_shape() -> None:
    back = codec_for("IntTable").from_value({"data": [1, 2, 3, 4, 5, 6], "shape": [3, 2],
                                             "labels": ["a", "b"]})
    assert [(d.label, d.size, d.stride) for d in back.layout.dim] == [("a", 3, 6), ("b", 2, 2)]


@pytest.mark.parametrize("type_name, value, field", [
    ("IntTable", [[1, 2], [3]], "value.data"),
    ("IntTable", [[1, 2], [3, 2**63]], "value.data[1][1]"),
    ("IntTable", [[1, 2], [3, 4.5]], "value.data[1][1]"),
    ("IntTable", [[1, 2], [3, "4"]], "value.data[1][1]"),
    ("DoubleTable", [[1.0, None]], "value.data[0][1]"),
    ("DoubleTable", {"data": [1.0, 2.0], "shape": [3]}, "value.shape"),
    ("DoubleTable", {"data": [1.0], "labels": ["a", "b"]}, "value.labels"),
    ("DoubleTable", {"rows": []}, "value.rows"),
    ("DoubleArray", "1,2,3", "value.data"),
])
def test_bad_tables_name_the_element(type_name: str, value: Any, field: str) -> None:
    with pytest.raises(CodecError) as err:
        codec_for(type_name).from_value(value)
    assert err.value.field == field


def test_layout_beyond_data_is_a_codec_error() -> None:
    msg = Float64MultiArray(data=[1.0, 2.0])
    msg.layout.dim = [MultiArrayDimension(size=2, stride=4), MultiArrayDimension(size=2, stride=2)]
    with pytest.raises(CodecError) as err:
        codec_for("DoubleTable").to_igtl(msg)
    assert err.value.field == "layout"


def test_bad_json_text_from_slicer() -> None:
    with pytest.raises(CodecError) as err:
        codec_for("DoubleTable").from_igtl(String(text="[[1, 2], [3"))
    assert err.value.field == "text"



@settings(max_examples=40, deadline=None)
@given(table=arrays(np.int64, st.tuples(st.integers(1, 6), st.integers(1, 6))))
def test_any_int_table_round_trips(table: np.ndarray) -> None:
    codec = codec_for("IntTable")
    msg = codec.from_value(table.tolist())
    enc = codec.encode(msg)
    assert enc.metadata["ros2.shape"] == f"{table.shape[0]}x{table.shape[1]}"
    back = codec.from_igtl(_wire(enc.body), metadata=enc.metadata)
    assert codec.to_value(back) == table.tolist()
