"""The module's transport and widget, in one real scene, with no daemon (one scene run for
both: transport.py, then widget.py, which changes the parameter node)."""

from __future__ import annotations

from typing import Any

import transport
import widget


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    return {"transport": transport.main(session, args), "widget": widget.main(session, args)}
