"""A message as YAML text, in the style of ``ros2 topic echo``: the one writer the daemon and
its clients share (a client in 3D Slicer has no PyYAML).

`to_yaml` takes the plain values a message becomes (dicts in field order, lists, str, int,
float, bool, None) and writes block style as PyYAML's ``safe_dump(sort_keys=False,
default_flow_style=False, allow_unicode=True)`` does: ``key: value`` lines, nested mappings
indented by two, sequences as ``- item`` lines at their key's indentation, ``[]`` and ``{}``
for empty ones. Strings are plain when YAML would read them back as the same string,
single-quoted when they are printable on one line without tabs, and double-quoted with
escapes otherwise (PyYAML folds a multi-line string inside single quotes instead), so the
text always loads back to the values it was made from.
"""

from __future__ import annotations

import math
import re
from typing import Any, Dict, List, Optional

__all__ = ["to_yaml"]

# Plain text that YAML 1.1 (PyYAML's resolver) reads as something other than a string.
_IMPLICIT = re.compile(r"""\A(?:
    yes|Yes|YES|no|No|NO|true|True|TRUE|false|False|FALSE|on|On|ON|off|Off|OFF
  | ~|null|Null|NULL
  | [-+]?0b[0-1_]+ | [-+]?0[0-7_]+ | [-+]?(?:0|[1-9][0-9_]*) | [-+]?0x[0-9a-fA-F_]+
  | [-+]?[1-9][0-9_]*(?::[0-5]?[0-9])+
  | [-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+][0-9]+)? | \.[0-9][0-9_]*(?:[eE][-+][0-9]+)?
  | [-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+\.[0-9_]* | [-+]?\.(?:inf|Inf|INF) | \.(?:nan|NaN|NAN)
  | [0-9]{4}-[0-9]{2}-[0-9]{2}
  | [0-9]{4}-[0-9]{1,2}-[0-9]{1,2}(?:[Tt]|[\ \t]+)[0-9]{1,2}:[0-9]{2}:[0-9]{2}(?:\.[0-9]*)?
    (?:[\ \t]*(?:Z|[-+][0-9]{1,2}(?::[0-9]{2})?))?
  | << | =
)\Z""", re.VERBOSE)
# Characters YAML may carry unescaped (its c-printable set, without the byte order mark).
_UNPRINTABLE = re.compile("[^\x09\x0a\x0d\x20-\x7e\x85\xa0-\ud7ff\ue000-\ufefe\uff00-\ufffd"
                          "\U00010000-\U0010ffff]")
_LINE_BREAKS = re.compile("[\n\r\x85\u2028\u2029]")
_STARTS_AN_INDICATOR = set("#,[]{}&*!|>'\"%@`")
_ESCAPES = {"\0": "\\0", "\x07": "\\a", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\x0b": "\\v",
            "\x0c": "\\f", "\r": "\\r", "\x1b": "\\e", '"': '\\"', "\\": "\\\\",
            "\x85": "\\N", "\xa0": "\\_", "\u2028": "\\L", "\u2029": "\\P"}


def to_yaml(value: Any) -> str:
    """`value` (a dict, or any plain value) as block-style YAML text ending in a newline."""
    lines: List[str] = []
    if isinstance(value, dict) and value:
        _mapping(value, 0, lines)
    elif isinstance(value, list) and value:
        _sequence(value, 0, lines)
    else:
        lines.append(_scalar(value))
    return "\n".join(lines) + "\n"


def _mapping(data: Dict[Any, Any], indent: int, lines: List[str],
             first: Optional[str] = None) -> None:
    """Lines of a non-empty mapping; `first` prefixes its first line (``- `` in a list)."""
    pad = " " * indent
    for i, (key, item) in enumerate(data.items()):
        head = (first if i == 0 and first is not None else pad) + _scalar(key) + ":"
        if isinstance(item, dict) and item:
            lines.append(head)
            _mapping(item, indent + 2, lines)
        elif isinstance(item, list) and item:
            lines.append(head)
            _sequence(item, indent, lines)  # PyYAML indents no list under a key
        else:
            lines.append(head + " " + _scalar(item))


def _sequence(data: List[Any], indent: int, lines: List[str],
              first: Optional[str] = None) -> None:
    pad = " " * indent
    for i, item in enumerate(data):
        head = (first if i == 0 and first is not None else pad) + "- "
        if isinstance(item, dict) and item:
            _mapping(item, indent + 2, lines, head)
        elif isinstance(item, list) and item:
            _sequence(item, indent + 2, lines, head)
        else:
            lines.append(head + _scalar(item))


def _scalar(value: Any) -> str:
    if value is None:
        return "null"
    if value is True:
        return "true"
    if value is False:
        return "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return _float(value)
    if isinstance(value, dict):
        return "{}"
    if isinstance(value, list):
        return "[]"
    return _string(str(value))


def _float(value: float) -> str:
    if math.isnan(value):
        return ".nan"
    if math.isinf(value):
        return ".inf" if value > 0 else "-.inf"
    text = repr(value).lower()
    if "." not in text and "e" in text:
        text = text.replace("e", ".0e", 1)  # 1e+20 would read back as a string
    return text


def _string(text: str) -> str:
    if _plain(text):
        return text
    if not _UNPRINTABLE.search(text) and not _LINE_BREAKS.search(text) and "\t" not in text:
        return "'" + text.replace("'", "''") + "'"
    return '"' + "".join(_ESCAPES.get(ch) or (_hex(ch) if _UNPRINTABLE.match(ch) else ch)
                         for ch in text) + '"'


def _hex(ch: str) -> str:
    code = ord(ch)
    if code <= 0xFF:
        return f"\\x{code:02X}"
    if code <= 0xFFFF:
        return f"\\u{code:04X}"
    return f"\\U{code:08X}"


def _plain(text: str) -> bool:
    if not text or text != text.strip(" ") or _IMPLICIT.match(text):
        return False
    if _UNPRINTABLE.search(text) or _LINE_BREAKS.search(text) or "\t" in text:
        return False
    first = text[0]
    if first in _STARTS_AN_INDICATOR:
        return False
    if first in "-?:" and (len(text) == 1 or text[1] == " "):
        return False
    if ": " in text or " #" in text or text.endswith(":"):
        return False
    return True
