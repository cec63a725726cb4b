"""The one YAML writer (protocol/yaml_text.py): PyYAML's block style on what messages hold,
and text that always loads back to the values it was made from."""

from __future__ import annotations

import math

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from protocol.yaml_text import to_yaml


def pyyaml(value: object) -> str:
    return yaml.safe_dump(value, sort_keys=False, default_flow_style=False,
                          allow_unicode=True, width=1 << 16)


TYPICAL = [
    {"data": "hello world"}, {"data": ""}, {"data": "xkcd"}, {},
    {"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "world"},
     "poses": [{"position": {"x": 1.0, "y": 2e-20, "z": -0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}]},
    {"data": [1, 2, 3]}, {"data": []}, {"layout": {"dim": [], "data_offset": 0}, "data": [1.5]},
    {"name": ["a", "b"], "position": []}, {"data": [[1, 2], [3, 4]]}, {"x": [{"a": [1, 2]}, {}]},
    {"data": 1e20}, {"data": True}, {"data": None}, {"data": "/world"},
    {"data": "PSM1/base_link"}, {"data": "true"}, {"data": "123"}, {"data": "1.5"},
    {"data": "null"}, {"data": "a: b"}, {"data": "- x"}, {"data": "it's"}, {"data": "#x"},
    {"data": "a #b"}, {"data": " lead"}, {"data": "trail "}, {"data": "x:"},
    {"data": "2001-12-14"}, {"data": "1:20"}, {"data": "-abc"}, {"data": "é ünï"},
    {"data": "tab\there"}, {"data": "\x01"}, {"data": "yes"}, {"data": "~"},
]


@pytest.mark.parametrize("value", TYPICAL, ids=range(len(TYPICAL)))
def test_what_messages_hold_is_written_as_pyyaml_writes_it(value: object) -> None:
    assert to_yaml(value) == pyyaml(value)


def test_special_floats_and_multi_line_text() -> None:
    assert to_yaml({"x": math.nan, "y": math.inf, "z": -math.inf}) == \
        "x: .nan\ny: .inf\nz: -.inf\n"
    # PyYAML folds a multi-line string in single quotes; this writer escapes it instead.
    assert to_yaml({"data": "line\nbreak"}) == 'data: "line\\nbreak"\n'
    assert yaml.safe_load(to_yaml({"data": "a\u2028b\x85"})) == {"data": "a\u2028b\x85"}


json_like = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**64), 2**64)
    | st.floats(allow_nan=False) | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=4)
    | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=20)


@given(st.dictionaries(st.text(max_size=8), json_like, max_size=5))
def test_the_text_loads_back_to_the_values(value: dict) -> None:
    assert yaml.safe_load(to_yaml(value)) == (value or {})
