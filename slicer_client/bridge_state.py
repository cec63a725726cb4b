"""What a client created, as data: the re-sync list after a reconnect and the format a saved
3D Slicer scene keeps its bridges in.

A `BridgeSpec` is one create command (op + JSON arguments) plus the follow-up commands
that restore its state (a parameter client's observed names). A `BridgeState` is the
ordered list of them; its JSON text is versioned and every spec is validated against the
command schema when read, so a hand-edited or truncated scene fails with the field at fault.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Tuple

from protocol import commands as c

__all__ = ["CREATE_OPS", "REMOVE_OPS", "BridgeSpec", "BridgeState", "StateFormatError"]

STATE_VERSION = 1

# Ops that create something the daemon keeps, and the op (and identity fields) that removes
# it, from the ops' own declarations; bridges that die with their connection (a served
# service) are not restored.
_KINDS = [kind for kind in c.bridge_kinds().values() if not kind.bridge.per_connection]
REMOVE_OPS: Dict[str, Tuple[str, Tuple[str, ...]]] = {
    kind.create.op: (kind.remove.op, kind.bridge.identity) for kind in _KINDS}
_KIND_OF = {kind.create.op: kind.bridge.kind for kind in _KINDS}
CREATE_OPS = tuple(REMOVE_OPS)
FOLLOW_UP_OPS = tuple(follow.op for kind in _KINDS for follow in kind.follow_ups)


class StateFormatError(ValueError):
    """Saved bridge state that cannot be read; names the entry and field."""


def _validated(op: str, args: Mapping[str, Any], where: str) -> Dict[str, Any]:
    try:
        c.parse_request(op, c.dumps(dict(args)))
    except c.CommandError as error:
        raise StateFormatError(f"{where}: {op} arguments: {error}") from None
    return dict(args)


def _chosen(request: c.Op, f: dataclasses.Field[Any]) -> bool:
    if f.default is not dataclasses.MISSING:
        return bool(getattr(request, f.name) != f.default)
    if f.default_factory is not dataclasses.MISSING:
        return bool(getattr(request, f.name) != f.default_factory())
    return True  # a required field


@dataclass(frozen=True)
class BridgeSpec:
    """``kept``: the client asked the daemon to keep the bridge past the connection
    (`keep_bridge`); asked again after each re-creation."""

    op: str
    args: Dict[str, Any]
    then: Tuple[Tuple[str, Dict[str, Any]], ...] = ()
    kept: bool = False

    @classmethod
    def of(cls, request: c.Op) -> BridgeSpec:
        """The spec of a create request, built from the protocol's op class: its required
        fields and those set to other than their defaults (what a saved scene keeps)."""
        chosen = {f.name for f in dataclasses.fields(request) if _chosen(request, f)}
        args = request.to_args()
        return cls(request.op, {k: v for k, v in args.items() if k in chosen})

    @property
    def key(self) -> Tuple[str, ...]:
        """(op, identity fields...): one bridge per key, as the daemon keeps them."""
        _, fields = REMOVE_OPS[self.op]
        return (self.op, *(str(self.args[f]) for f in fields))

    def remove_command(self) -> Tuple[str, Dict[str, Any]]:
        op, fields = REMOVE_OPS[self.op]
        return op, {f: self.args[f] for f in fields}

    def keep_command(self) -> Tuple[str, Dict[str, Any]]:
        _, identity = self.remove_command()
        return c.KeepBridge.op, {"kind": _KIND_OF[self.op], **identity}

    def to_dict(self) -> Dict[str, Any]:
        out: Dict[str, Any] = {"op": self.op, "args": self.args}
        if self.then:
            out["then"] = [{"op": op, "args": args} for op, args in self.then]
        if self.kept:
            out["kept"] = True
        return out

    @classmethod
    def from_dict(cls, data: Any, where: str = "bridge") -> BridgeSpec:
        if not isinstance(data, dict):
            raise StateFormatError(f"{where}: expected an object, got {type(data).__name__}")
        op, args = data.get("op"), data.get("args", {})
        if op not in REMOVE_OPS:
            raise StateFormatError(f"{where}.op: expected one of {', '.join(CREATE_OPS)}, "
                                   f"got {op!r}")
        if not isinstance(args, dict):
            raise StateFormatError(f"{where}.args: expected an object, got "
                                   f"{type(args).__name__}")
        then: List[Tuple[str, Dict[str, Any]]] = []
        for i, item in enumerate(data.get("then", [])):
            sub = f"{where}.then[{i}]"
            if not isinstance(item, dict) or item.get("op") not in FOLLOW_UP_OPS:
                raise StateFormatError(f"{sub}: expected {{'op': one of {FOLLOW_UP_OPS}, "
                                       f"'args': ...}}, got {item!r}")
            then.append((item["op"], _validated(item["op"], item.get("args", {}), sub)))
        kept = data.get("kept", False)
        if not isinstance(kept, bool):
            raise StateFormatError(f"{where}.kept: expected true or false, got {kept!r}")
        return cls(op, _validated(op, args, where), tuple(then), kept)


@dataclass(frozen=True)
class BridgeState:
    specs: Tuple[BridgeSpec, ...] = ()
    version: int = STATE_VERSION
    extra: Dict[str, Any] = field(default_factory=dict)  # e.g. host/port of the GUI

    def to_json(self) -> str:
        return json.dumps({"version": self.version, "bridges": [s.to_dict() for s in self.specs],
                           **({"extra": self.extra} if self.extra else {})},
                          sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> BridgeState:
        if not text or not text.strip():
            return cls()
        try:
            data = json.loads(text)
        except ValueError as error:
            raise StateFormatError(f"saved bridge state: expected JSON, got {error}") from None
        if not isinstance(data, dict):
            raise StateFormatError("saved bridge state: expected a JSON object")
        version = data.get("version")
        if version != STATE_VERSION:
            raise StateFormatError(f"saved bridge state: version {STATE_VERSION} expected, "
                                   f"got {version!r} (saved by another slicer_client?)")
        bridges = data.get("bridges", [])
        if not isinstance(bridges, list):
            raise StateFormatError("saved bridge state.bridges: expected a list")
        extra = data.get("extra", {})
        specs = tuple(BridgeSpec.from_dict(b, f"bridges[{i}]") for i, b in enumerate(bridges))
        return cls(specs, version, extra if isinstance(extra, dict) else {})
