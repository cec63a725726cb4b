"""The code stays lint-clean (ruff: pyflakes, pycodestyle, bugbear) and type-clean under
mypy --strict (protocol/, bridge/ and slicer_client/, as configured in pyproject.toml)."""

from __future__ import annotations

import subprocess
import sys

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
    pinocchio and coal (about 50 MB) with the first motion query, not at start: a daemon
    that only streams topics stays small."""
    code = ("import sys; import bridge.daemon; print(sorted(m for m in ('trimesh', "
            "'yourdfpy', 'pinocchio', 'coal') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                         text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]", out.stderr
