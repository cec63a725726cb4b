"""The RTS_COMMAND answer to a request: a JSON `Reply` with a result or an `ErrorInfo`,
and the ``Status``/``ErrorMessage`` metadata 3D Slicer reads."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, cast

from protocol.commands.errors import (CommandError, ErrorCode, MissingFieldError,
                                      OutOfRangeError, WrongTypeError)
from protocol.commands.fields import MISSING, Args
from protocol.commands.wire import (MAX_OP_NAME_BYTES, METADATA_ERROR_MESSAGE, METADATA_STATUS,
                                    SCHEMA_VERSION, STATUS_FAIL, STATUS_SUCCESS, dumps,
                                    json_type, loads)
from protocol.errors import ProtocolError

__all__ = ["ErrorInfo", "Reply", "error_reply", "reply_for_exception"]


@dataclass(frozen=True)
class ErrorInfo:
    """Why a request failed: a code, a readable message and the field at fault (or "")."""

    code: ErrorCode
    message: str
    field: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"code": int(self.code), "name": self.code.name, "message": self.message,
                "field": self.field}

    @classmethod
    def from_dict(cls, data: Any, path: str = "error") -> ErrorInfo:
        if not isinstance(data, dict):
            raise WrongTypeError(path, "an object", json_type(data))
        a = Args(data, path + ".")
        number = a.req_int("code", low=0, high=65535)
        a.opt_str("name", allow_empty=True)  # informative only
        message = cast(str, a.opt_str("message", "", max_len=1 << 16, allow_empty=True))
        fld = cast(str, a.opt_str("field", "", allow_empty=True))
        a.finish()
        try:
            code = ErrorCode(number)
        except ValueError:  # a newer daemon's code: keep the reply readable
            code = ErrorCode.INTERNAL
        return cls(code, message, fld)


@dataclass(frozen=True)
class Reply:
    """The JSON text of an RTS_COMMAND: ``{"schema", "op", "ok", "result" | "error"}``."""

    ok: bool
    op: str = ""
    result: dict[str, Any] = field(default_factory=dict)
    error: ErrorInfo | None = None
    schema: int = SCHEMA_VERSION

    def __post_init__(self) -> None:
        if self.ok and self.error is not None:
            raise OutOfRangeError("error", "no error on a successful reply", "an error")
        if not self.ok and self.error is None:
            raise MissingFieldError("error", "an error on a failed reply", "nothing")

    @classmethod
    def success(cls, op: str, result: Mapping[str, Any] | None = None) -> Reply:
        return cls(ok=True, op=op, result=dict(result or {}))

    @classmethod
    def failure(cls, op: str, code: ErrorCode, message: str, field: str = "") -> Reply:
        return cls(ok=False, op=op, error=ErrorInfo(code, message, field))

    @property
    def status(self) -> str:
        """The ``Status`` metadata value of the RTS_COMMAND."""
        return STATUS_SUCCESS if self.ok else STATUS_FAIL

    def metadata(self) -> dict[str, str]:
        """Metadata for the RTS_COMMAND header v2: Status, and ErrorMessage on failure
        (what OpenIGTLinkIO's ``igtlioCommand::GetErrorMessage`` returns)."""
        meta = {METADATA_STATUS: self.status}
        if self.error is not None:
            meta[METADATA_ERROR_MESSAGE] = self.error.message
        return meta

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"schema": self.schema, "op": self.op, "ok": self.ok}
        if self.ok:
            out["result"] = self.result
        else:
            out["error"] = cast(ErrorInfo, self.error).to_dict()
        return out

    def to_json(self) -> str:
        return dumps(self.to_dict())

    @classmethod
    def from_json(cls, text: str | bytes, *, max_bytes: int = 1 << 30) -> Reply:
        """Parse a reply (replies can be large: a last message, a parameter list)."""
        data = loads(text, max_bytes=max_bytes)
        a = Args(data)
        schema = cast(int, a.opt_int("schema", SCHEMA_VERSION, low=1, high=1 << 16))
        op = cast(str, a.opt_str("op", "", max_len=MAX_OP_NAME_BYTES, allow_empty=True))
        ok = a.raw("ok", True)
        if not isinstance(ok, bool):
            raise WrongTypeError("ok", "true or false", json_type(ok))
        if ok:
            raw = a.raw("result", False)
            result: dict[str, Any] = {} if raw is MISSING else raw
            if not isinstance(result, dict):
                raise WrongTypeError("result", "an object", json_type(result))
            a.finish()
            return cls(ok=True, op=op, result=result, schema=schema)
        error = ErrorInfo.from_dict(a.raw("error", True))
        a.finish()
        return cls(ok=False, op=op, error=error, schema=schema)


def error_reply(op: str, exc: CommandError) -> Reply:
    """The failed reply for a refused request, naming the field, expectation and value."""
    return Reply.failure(op, exc.error_code, str(exc), exc.field)


def reply_for_exception(op: str, exc: BaseException) -> Reply:
    """Any exception -> failed reply: a `CommandError` keeps its code and field, anything
    else is INTERNAL (the daemon should also log it: it is a bug)."""
    if isinstance(exc, CommandError):
        return error_reply(op, exc)
    if isinstance(exc, ProtocolError):
        return Reply.failure(op, ErrorCode.OUT_OF_RANGE, str(exc), exc.field)
    return Reply.failure(op, ErrorCode.INTERNAL, f"{type(exc).__name__}: {exc}")

