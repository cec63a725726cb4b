"""What building interface packages can raise; each message says what was expected and what
came. The command line exits with 2 for `InputError`s (nothing was built) and 1 for the
others."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence


class InterfaceBuildError(Exception):
    """A build could not start or did not finish; the text says which and what to do."""


class InputError(InterfaceBuildError):
    """The packages given cannot be built as they are; found before anything is built."""


class PackageError(InputError):
    """A path is not an interface package, or its package.xml is unreadable."""


class NotAnInterfacePackage(PackageError):
    """A package folder whose CMakeLists.txt generates no interfaces."""


class MissingDependencyError(InputError):
    def __init__(self, missing: Sequence[tuple[str, str]]) -> None:
        self.missing = list(missing)
        listed = "; ".join(f"{package} depends on {dependency}"
                           for package, dependency in self.missing)
        super().__init__(f"expected every dependency to be given or installed in this "
                         f"environment (importable, or in its ament index), got: {listed}. "
                         f"Give the dependency's folder too, or install it first.")


class DependencyCycleError(InputError):
    def __init__(self, cycle: Sequence[str]) -> None:
        self.cycle = list(cycle)
        super().__init__(f"expected package dependencies without a cycle, got "
                         f"{' -> '.join(self.cycle)}")


class ToolMissingError(InterfaceBuildError):
    """cmake, a compiler, make or the ROS interface generators are missing."""


class StepFailedError(InterfaceBuildError):
    def __init__(self, label: str, argv: Sequence[str], returncode: int, log: Path,
                 tail: str) -> None:
        self.label, self.returncode, self.log = label, returncode, log
        # A script given inline (python -c) is too long to repeat.
        command = " ".join("<script>" if "\n" in arg else arg for arg in argv)
        super().__init__(f"{label} failed: expected exit code 0 from {command}, got "
                         f"{returncode}; the last lines of its log ({log}):\n{tail}")
