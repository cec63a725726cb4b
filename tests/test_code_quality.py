"""The code stays lint-clean (ruff: pyflakes, pycodestyle, bugbear) and type-clean under
mypy --strict (protocol/, bridge/ and slicer_client/, as configured in pyproject.toml)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from support import REPO

pytestmark = pytest.mark.integration  # starts processes


def run_tool(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", *argv], cwd=REPO, capture_output=True,
                          text=True, timeout=300)


def test_ruff_finds_nothing() -> None:
    result = run_tool("ruff", "check", "protocol", "bridge", "slicer_client", "tests", "bench",
                      "tools")
    assert result.returncode == 0, result.stdout + result.stderr


def test_the_packages_are_mypy_strict_clean() -> None:
    result = run_tool("mypy")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Success" in result.stdout


def test_the_daemon_starts_without_the_mesh_libraries() -> None:
    """yourdfpy and trimesh (about 80 MB of RSS) load with the first robot or marker mesh,
    pinocchio and coal (about 50 MB) when the first robot loads, not at start: a daemon
    that only streams topics stays small."""
    code = ("import sys; import bridge.daemon; print(sorted(m for m in ('trimesh', "
            "'yourdfpy', 'pinocchio', 'coal') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                         text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]", out.stderr


# Shared machinery, and the player (bridge/playback), which like bridge/daemon.py wires
# capabilities together into a server of its own.
CAPABILITIES = sorted(p.parent.name for p in (REPO / "bridge").glob("*/__init__.py")
                      if p.parent.name not in ("core", "ros", "codecs", "interfaces",
                                               "playback"))


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return names


def _is_handler_module(module: str) -> bool:
    """A module that serves ops: it takes `Handler` from the dispatcher."""
    path = REPO / (module.replace(".", "/") + ".py")
    if not path.exists():
        path = REPO / module.replace(".", "/") / "__init__.py"  # a package: its __init__
        if not path.exists():
            return False
    return any(isinstance(node, ast.ImportFrom) and node.module == "bridge.core.dispatch"
               and any(alias.name == "Handler" for alias in node.names)
               for node in ast.walk(ast.parse(path.read_text())))


def test_no_capability_imports_another_capabilitys_handlers() -> None:
    """Capabilities are peers: what one offers another lives in an interface module
    (bridge/tf/lookups.py's LookupStreams, bridge/parameters/watch.py) or in core/ and ros/,
    and the daemon wires them together."""
    assert {"actions", "markers", "parameters", "robots", "services", "tf",
            "topics"} <= set(CAPABILITIES)
    crossing = []
    for capability in CAPABILITIES:
        for path in (REPO / "bridge" / capability).rglob("*.py"):
            for module in _imports(path):
                parts = module.split(".")
                if (len(parts) >= 2 and parts[0] == "bridge" and parts[1] in CAPABILITIES
                        and parts[1] != capability and _is_handler_module(module)):
                    crossing.append(f"{path.relative_to(REPO)} imports {module}")
    assert crossing == []
