"""The JSON text of commands and replies, and the wire constants around it: the COMMAND's
device name and size limits, the RTS_COMMAND's ``Status``/``ErrorMessage`` metadata.

Parsing refuses anything odd (NaN, duplicate keys, deep nesting, over-long text), so a
hostile text costs the daemon no more than its size."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any, NewType

from protocol.commands.errors import (BadJsonError, CommandError, CommandFailedError, ErrorCode,
                                      OutOfRangeError, TooLargeError)

__all__ = ["COMMAND_DEVICE_NAME", "MAX_COMMAND_TEXT_BYTES", "MAX_JSON_DEPTH",
           "MAX_OP_NAME_BYTES", "METADATA_ERROR_MESSAGE", "METADATA_STATUS", "SCHEMA_VERSION",
           "SLICER_MAX_COMMAND_TEXT_BYTES", "STATUS_FAIL", "STATUS_SUCCESS", "CommandId",
           "JSON_NUMBERS", "dumps", "json_type", "jsonable", "loads", "not_json_number",
           "status_is_success"]

SCHEMA_VERSION = 1
# What 3D Slicer's OpenIGTLinkIO puts in the header of every COMMAND it sends.
COMMAND_DEVICE_NAME = "command"
# NAME is char[128]; OpenIGTLink's reader needs a NUL inside it.
MAX_OP_NAME_BYTES = 127
# Our own limit on a request's text; Slicer's sender refuses anything over 65535 bytes.
MAX_COMMAND_TEXT_BYTES = 1 << 20
SLICER_MAX_COMMAND_TEXT_BYTES = 0xFFFF
MAX_JSON_DEPTH = 32

METADATA_STATUS = "Status"
METADATA_ERROR_MESSAGE = "ErrorMessage"
STATUS_SUCCESS = "SUCCESS"
STATUS_FAIL = "FAIL"

CommandId = NewType("CommandId", int)  # u32 from the COMMAND body, unique per connection

def status_is_success(value: str | None) -> bool:
    """True if an RTS_COMMAND ``Status`` metadata value means success.

    OpenIGTLinkIO writes ``SUCCESS``; its converter also reads ``TRUE``; accept both.
    """
    return value is not None and value.strip().upper() in ("SUCCESS", "TRUE")



def _reject_constant(name: str) -> Any:
    raise BadJsonError("text", "standard JSON numbers", name)


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):  # the rare case: find the key, to name it
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                raise BadJsonError(key, "each key once", "a duplicate key")
            seen.add(key)
    return out


def _depth_ok(value: Any, limit: int) -> bool:
    # Only containers go on the stack: a list of 70,000 numbers is one look at each.
    containers = (dict, list)
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if depth > limit:
            return False
        children = item.values() if isinstance(item, dict) else item
        stack.extend([(child, depth + 1) for child in children
                      if isinstance(child, containers)])
    return True


def loads(text: str | bytes, *, max_bytes: int = MAX_COMMAND_TEXT_BYTES) -> dict[str, Any]:
    """Parse a command or reply text into a JSON object, refusing anything odd.

    Bytes are decoded as UTF-8 whatever the COMMAND's ENCODING says (Slicer labels every
    command US-ASCII). Empty text means ``{}`` so argument-less ops can be sent bare.
    """
    size = len(text.encode("utf-8")) if isinstance(text, str) else len(text)
    if size > max_bytes:
        raise TooLargeError("text", f"at most {max_bytes} bytes", f"{size} bytes")
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise BadJsonError("text", "UTF-8 text", f"invalid byte at {exc.start}") from None
    if not text.strip():
        return {}
    try:
        value = json.loads(text, parse_constant=_reject_constant,
                           object_pairs_hook=_no_duplicates)
    except CommandError:
        raise
    except RecursionError:
        raise BadJsonError("text", f"JSON nested at most {MAX_JSON_DEPTH} deep",
                           "deeper nesting") from None
    except ValueError as exc:  # JSONDecodeError, or an over-long integer literal
        raise BadJsonError("text", "a JSON object", str(exc)) from None
    if not isinstance(value, dict):
        raise BadJsonError("text", "a JSON object", json_type(value))
    if not _depth_ok(value, MAX_JSON_DEPTH):
        raise BadJsonError("text", f"JSON nested at most {MAX_JSON_DEPTH} deep",
                           "deeper nesting")
    return value


JSON_NUMBERS = "finite doubles (JSON has no NaN or infinity)"


def not_json_number(path: str, got: object) -> CommandFailedError:
    """The one refusal of a number JSON cannot carry (a NaN or an infinity, from ROS or a
    client): NOT_SUPPORTED, naming where it is. `dumps` raises it; so do the checks that
    look at values before a text is made (parameters)."""
    return CommandFailedError(path, JSON_NUMBERS, got, code=ErrorCode.NOT_SUPPORTED)


def _first_non_finite(value: Any, path: str) -> tuple[str, float] | None:
    # Only after json.dumps refused the value: the rare path, to say where.
    stack: list[tuple[Any, str]] = [(value, path)]
    seen: set[int] = set()  # json refuses a circular value with ValueError too
    while stack:
        item, where = stack.pop()
        if isinstance(item, float) and not math.isfinite(item):
            return where, item
        if id(item) in seen:
            continue
        seen.add(id(item))
        if isinstance(item, Mapping):
            pairs = [(v, f"{where}.{k}" if where else str(k)) for k, v in item.items()]
        elif isinstance(item, (list, tuple)):
            pairs = [(v, f"{where}[{i}]") for i, v in enumerate(item)]
        else:
            continue
        stack.extend(reversed(pairs))  # depth first, in document order
    return None


def dumps(value: Mapping[str, Any]) -> str:
    """Compact, ASCII-only JSON (matches the US-ASCII encoding Slicer labels commands with);
    NaN and infinity are refused (`not_json_number`, naming the first one) rather than
    written as non-standard tokens: the one place a text refuses them."""
    try:
        return json.dumps(value, ensure_ascii=True, allow_nan=False, separators=(",", ":"))
    except ValueError as exc:
        found = _first_non_finite(value, "")
        if found is None:
            raise OutOfRangeError("value", "JSON values", str(exc)) from None
        raise not_json_number(*found) from None


_SCALARS = (str, int, float, bool, type(None))


def jsonable(value: Any) -> Any:
    """A request's or result's value as JSON holds it: what has ``to_dict`` (a value
    class, a nested result) by it, tuples as arrays, objects item by item."""
    if type(value) in _SCALARS:  # most of a listing: checked first (25% faster)
        return value
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [jsonable(v) for v in value]
    if hasattr(value, "to_dict"):
        return value.to_dict()
    return value


def json_type(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"boolean {value!r}".lower()
    if isinstance(value, (int, float)):
        return f"number {value!r}"
    if isinstance(value, str):
        shown = value if len(value) <= 40 else value[:37] + "..."
        return f"string {shown!r}"
    if isinstance(value, list):
        return "array"
    if isinstance(value, dict):
        return "object"
    return type(value).__name__


