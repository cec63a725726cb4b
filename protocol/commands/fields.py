"""Reading one JSON object's fields: `Args` raises errors that name the field's full path
(``qos.depth``), what was expected and what came; unread fields are refused by `finish`."""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Mapping
from typing import Any, cast

from protocol.commands.errors import (MissingFieldError, OutOfRangeError, TooLargeError,
                                      UnknownFieldError, WrongTypeError)
from protocol.commands.wire import json_type

__all__ = ["MAX_NAME", "MAX_TEXT", "MISSING", "PARAM_NAME", "ROBOT_NAME", "ROS_NAME",
           "ROS_NAME_DESC", "Args", "check_float", "check_int", "check_str"]

MAX_NAME = 256  # ROS names, frames, parameter names
MAX_TEXT = 4096  # descriptions, file paths

MISSING = object()
ROS_NAME = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*\Z")
PARAM_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_./]*\Z")
ROBOT_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
ROS_NAME_DESC = "a ROS name like /ns/name (letters, digits, _ and /)"


class Args:
    """Reads one JSON object's fields, raising errors that name the field's full path."""

    def __init__(self, data: Mapping[str, Any], prefix: str = "") -> None:
        self._data = data
        self._prefix = prefix
        self._used: set[str] = set()

    def path(self, name: str) -> str:
        return f"{self._prefix}{name}"

    def raw(self, name: str, required: bool) -> Any:
        """The field's JSON value as it came, or `MISSING` (only when not required)."""
        self._used.add(name)
        if name not in self._data or (self._data[name] is None and not required):
            if required:
                raise MissingFieldError(self.path(name), "a value", self._nothing_for(name))
            return MISSING
        return self._data[name]

    def _nothing_for(self, name: str) -> str:
        # A missing field is often a misspelt one: name the key that came instead.
        close = difflib.get_close_matches(name, [k for k in self._data if isinstance(k, str)
                                                 and k not in self._used], n=1, cutoff=0.6)
        return f"nothing (but an unknown key {close[0]!r}: a typo?)" if close else "nothing"

    def keys(self) -> tuple[str, ...]:
        """The keys the object has (read or not)."""
        return tuple(k for k in self._data if isinstance(k, str))

    def allow(self, name: str) -> None:
        """Accept `name` without reading it (``schema``, read by the envelope)."""
        self._used.add(name)

    def finish(self) -> None:
        extra = sorted(set(self._data) - self._used)
        if extra:
            allowed = ", ".join(sorted(self._used)) or "no fields"
            raise UnknownFieldError(self.path(extra[0]), f"one of: {allowed}", "an unknown field")

    # strings
    def req_str(self, name: str, *, max_len: int = MAX_NAME, allow_empty: bool = False,
                pattern: re.Pattern[str] | None = None, desc: str = "") -> str:
        value = self.raw(name, True)
        return check_str(value, self.path(name), max_len, allow_empty, pattern, desc)

    def opt_str(self, name: str, default: str | None = None, *, max_len: int = MAX_NAME,
                allow_empty: bool = False, pattern: re.Pattern[str] | None = None,
                desc: str = "") -> str | None:
        value = self.raw(name, False)
        if value is MISSING:
            return default
        return check_str(value, self.path(name), max_len, allow_empty, pattern, desc)

    def ros_name(self, name: str) -> str:
        return self.req_str(name, pattern=ROS_NAME, desc=ROS_NAME_DESC)

    def frame(self, name: str) -> str:
        text = self.req_str(name)
        if "\x00" in text or text.strip() != text:
            raise OutOfRangeError(self.path(name), "a frame id without NUL or outer spaces",
                                  repr(text))
        return text

    def choice(self, name: str, choices: tuple[str, ...], default: str | None = None) -> str:
        value = self.raw(name, default is None)
        if value is MISSING:
            return cast(str, default)
        if not isinstance(value, str):
            raise WrongTypeError(self.path(name), "a string", json_type(value))
        if value not in choices:
            raise OutOfRangeError(self.path(name), "one of " + "|".join(choices), repr(value))
        return value

    # numbers
    def opt_int(self, name: str, default: int | None, *, low: int, high: int) -> int | None:
        value = self.raw(name, False)
        if value is MISSING:
            return default
        return check_int(value, self.path(name), low, high)

    def req_int(self, name: str, *, low: int, high: int) -> int:
        return check_int(self.raw(name, True), self.path(name), low, high)

    def opt_float(self, name: str, default: float | None, *, low: float, high: float,
                  low_open: bool = False) -> float | None:
        value = self.raw(name, False)
        if value is MISSING:
            return default
        return check_float(value, self.path(name), low, high, low_open)

    def rate_hz(self) -> float | None:
        """The optional ``rate_hz`` field: a positive rate cap."""
        return self.opt_float("rate_hz", None, low=0.0, high=10_000.0, low_open=True)

    def opt_bool(self, name: str, default: bool) -> bool:
        value = self.raw(name, False)
        if value is MISSING:
            return default
        if not isinstance(value, bool):
            raise WrongTypeError(self.path(name), "true or false", json_type(value))
        return value

    # containers
    def opt_obj(self, name: str) -> Args | None:
        value = self.raw(name, False)
        if value is MISSING:
            return None
        if not isinstance(value, dict):
            raise WrongTypeError(self.path(name), "an object", json_type(value))
        return Args(value, self.path(name) + ".")

    def req_obj_raw(self, name: str) -> dict[str, Any]:
        value = self.raw(name, True)
        if not isinstance(value, dict):
            raise WrongTypeError(self.path(name), "an object", json_type(value))
        return value

    def str_list(self, name: str, *, pattern: re.Pattern[str] | None = None,
                 desc: str = "", required: bool = True) -> tuple[str, ...]:
        value = self.raw(name, required)
        if value is MISSING:
            return ()
        if not isinstance(value, list):
            raise WrongTypeError(self.path(name), "an array of strings", json_type(value))
        if len(value) > 10_000:
            raise TooLargeError(self.path(name), "at most 10000 names", f"{len(value)}")
        return tuple(check_str(v, f"{self.path(name)}[{i}]", MAX_NAME, False, pattern, desc)
                     for i, v in enumerate(value))

    def any(self, name: str) -> Any:
        return self.raw(name, True)


def check_str(value: Any, path: str, max_len: int, allow_empty: bool,
               pattern: re.Pattern[str] | None, desc: str) -> str:
    if not isinstance(value, str):
        raise WrongTypeError(path, "a string", json_type(value))
    if not value and not allow_empty:
        raise OutOfRangeError(path, "a non-empty string", "an empty string")
    if len(value) > max_len:
        raise TooLargeError(path, f"at most {max_len} characters", f"{len(value)} characters")
    if pattern is not None and value and not pattern.match(value):
        raise OutOfRangeError(path, desc or f"text matching {pattern.pattern}", repr(value))
    return value


def check_int(value: Any, path: str, low: int, high: int) -> int:
    # JSON has no int/float split; accept 3.0 for an integer field only when exact.
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise WrongTypeError(path, "an integer", json_type(value))
    if isinstance(value, float):
        if not value.is_integer():
            raise WrongTypeError(path, "an integer", json_type(value))
        value = int(value)
    if not low <= value <= high:
        raise OutOfRangeError(path, f"an integer in [{low}, {high}]", str(value))
    return int(value)


def check_float(value: Any, path: str, low: float, high: float, low_open: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise WrongTypeError(path, "a number", json_type(value))
    number = float(value)
    too_low = number <= low if low_open else number < low
    if not math.isfinite(number) or too_low or number > high:
        bracket = "(" if low_open else "["
        raise OutOfRangeError(path, f"a number in {bracket}{low:g}, {high:g}]", repr(value))
    return number

