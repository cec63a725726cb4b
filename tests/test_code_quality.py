"""The code stays lint-clean (ruff: pyflakes, pycodestyle, bugbear) and `protocol/` stays
type-clean under mypy --strict, as configured in pyproject.toml."""

from __future__ import annotations

import subprocess
import sys

from support import REPO


def run_tool(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", *argv], cwd=REPO, capture_output=True,
                          text=True, timeout=300)


def test_ruff_finds_nothing() -> None:
    result = run_tool("ruff", "check", "protocol", "bridge", "slicer_client", "tests", "bench",
                      "tools")
    assert result.returncode == 0, result.stdout + result.stderr


def test_protocol_is_mypy_strict_clean() -> None:
    result = run_tool("mypy")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Success" in result.stdout
