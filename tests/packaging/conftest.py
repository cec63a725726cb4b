"""Packaging tests: the installed copies (wheels, colcon). Their helper lives beside them."""

from __future__ import annotations

import sys
from pathlib import Path

# --import-mode=importlib adds no test folder to sys.path: make installed_daemon importable.
sys.path.insert(0, str(Path(__file__).resolve().parent))
