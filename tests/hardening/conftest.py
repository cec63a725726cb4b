"""Hardening tests: security options, bad input, faults. Their helpers live beside them."""

from __future__ import annotations

import sys
from pathlib import Path

# --import-mode=importlib adds no test folder to sys.path: make hardening_tools importable.
sys.path.insert(0, str(Path(__file__).resolve().parent))
