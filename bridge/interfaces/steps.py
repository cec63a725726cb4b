"""Run long commands (cmake, make, pip) without going silent: a line when each starts, one
every few seconds while it runs (elapsed time and where it is, read from its output), one
when it ends; on failure the tail of its log and the log's path.

The one progress reporter of the project's builds: `slicer-ros2-bridge build-interfaces`
and tools/setup_env.py both run their steps here. Standard library only.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

from bridge.interfaces.errors import StepFailedError

Say = Callable[[str], None]
# How often a running step says that it still runs.
REPORT_EVERY_S = 5.0
_POLL_S = 0.2
_PIP_DOING = re.compile(r"\s*(Collecting|Downloading|Using cached|Processing|Obtaining|"
                        r"Preparing|Building|Created wheel|Installing|Successfully) ")
_MAKE_LINE = re.compile(r"^\[\s*(\d+)%\](.*)$", re.MULTILINE)
_MAKE_OBJECT = re.compile(r"Building \w+ object CMakeFiles/([^/]+?)\.dir/")
_MAKE_LINKING = re.compile(r"Linking \w+ (?:shared |static )?(?:library|module|executable) (\S+)")


_COMPILING = re.compile(r"^(\S+\.(?:c|cc|cpp|cxx)):", re.MULTILINE)
# What a tool prints that says nothing of where it is: a compiler's excerpt of the source a
# diagnostic is about (`15209 |   x = (a > b);`, `      |   ^~`), and the source line
# Python echoes under a warning (`  warnings.warn(msg, _BetaConfiguration)`).
_EXCERPT = re.compile(r"\s*\d*\s*\|")
_PY_WARNING = re.compile(r"\S+\.py:\d+: \w+: ")


def last_line(output: str) -> str | None:
    """What a tool last said (pip: `Collecting ...`, `Installing collected packages ...`),
    its source excerpts and echoed warning lines left out."""
    lines: list[str] = []
    echo_next = False
    for raw in output.splitlines():
        echo, echo_next = echo_next and raw[:1].isspace(), bool(_PY_WARNING.match(raw))
        line = raw.strip()
        if line and not echo and not _EXCERPT.match(raw) and any(c.isalpha() for c in line):
            lines.append(line)
    if not lines:
        return None
    line = lines[-1]
    return line if len(line) <= 90 else line[:87] + "..."


def compile_progress(output: str) -> str | None:
    """Where a quiet compile (`setup.py -q build_ext`) is: the last source file its
    compiler named (`compiling bridge/ros/_rcl_reader.c`); None while it has named none
    (its diagnostics, and setuptools' warnings, are in the log)."""
    found = _COMPILING.findall(output)
    return f"compiling {found[-1]}" if found else None


def pip_progress(output: str) -> str | None:
    """What pip last said it does (`Collecting ...`, `Downloading ...`, `Installing collected
    packages ...`), its warnings and progress bars left out."""
    lines = [line.strip() for line in output.splitlines() if _PIP_DOING.match(line)]
    return last_line(lines[-1]) if lines else None


def make_progress(output: str) -> str | None:
    """Where a CMake-generated Makefile is, from its last `[ NN%] ...` line: `45%, compiling
    turtlesim__rosidl_typesupport_c` (the target, not the file: those names are long)."""
    found = _MAKE_LINE.findall(output)
    if not found:
        return None
    percent, doing = found[-1]
    compiling = _MAKE_OBJECT.search(doing)
    if compiling:
        return f"{percent}%, compiling {compiling.group(1)}"
    linking = _MAKE_LINKING.search(doing)
    if linking:
        return f"{percent}%, linking {Path(linking.group(1)).name}"
    return f"{percent}%, {doing.strip()[:60]}"


@dataclass(frozen=True)
class Step:
    label: str  # "[2/3] turtlesim: building (make -j2 install)"
    argv: Sequence[str]
    cwd: Path
    log: Path
    env: Mapping[str, str] | None = None
    where: Callable[[str], str | None] = last_line  # the output so far -> where the step is


@dataclass
class RunningStep:
    """One started step; `check()` it often, it reports and tells when it has ended."""

    step: Step
    say: Say
    started: float = field(default_factory=time.monotonic)
    _popen: subprocess.Popen[bytes] | None = None
    _next_report: float = 0.0
    _status: str | None = None
    _read: int = 0

    def start(self) -> RunningStep:
        self.step.log.parent.mkdir(parents=True, exist_ok=True)
        self.say(f"{self.step.label} ...")
        env = None if self.step.env is None else dict(self.step.env)
        with self.step.log.open("wb") as out:
            self._popen = subprocess.Popen(
                list(self.step.argv), cwd=self.step.cwd, stdout=out, stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL, env=env,
                start_new_session=True)  # stopped as a group (make's compilers too)
        self.started = time.monotonic()
        self._next_report = self.started + REPORT_EVERY_S
        return self

    def check(self) -> float | None:
        """None while it runs (reporting every `REPORT_EVERY_S`); its duration once it has
        ended well; `StepFailedError` with its log's tail if it failed."""
        assert self._popen is not None, "start() first"
        now = time.monotonic()
        code = self._popen.poll()
        if code is None:
            if now >= self._next_report:
                while self._next_report <= now:  # one line, even after a long stall
                    self._next_report += REPORT_EVERY_S
                self._update_status()
                status = f", {self._status}" if self._status else ""
                self.say(f"{self.step.label}: {now - self.started:.0f} s{status}")
            return None
        took = now - self.started
        if code != 0:
            lines = self.step.log.read_text(errors="replace").splitlines()
            raise StepFailedError(self.step.label, self.step.argv, code, self.step.log,
                                  "\n".join(lines[-25:]))
        self.say(f"{self.step.label}: done in {took:.1f} s")
        return took

    def stop(self) -> None:
        """End it and everything it started (an interrupted build)."""
        if self._popen is None or self._popen.poll() is not None:
            return
        for sig, wait_s in ((signal.SIGTERM, 10.0), (signal.SIGKILL, None)):
            try:
                os.killpg(self._popen.pid, sig)
            except ProcessLookupError:
                pass
            try:
                self._popen.wait(wait_s)
                return
            except subprocess.TimeoutExpired:
                continue

    def _update_status(self) -> None:
        # Only what was written since the last report (the log may be long), up to its last
        # complete line (a partial one is read again next time).
        with self.step.log.open("rb") as log:
            log.seek(self._read)
            fresh = log.read()
        end = fresh.rfind(b"\n") + 1
        if end:
            self._read += end
            status = self.step.where(fresh[:end].decode(errors="replace"))
            if status:
                self._status = status


def run_step(step: Step, say: Say) -> float:
    """Run one step to its end, reporting; its duration, or `StepFailedError`."""
    running = RunningStep(step, say).start()
    try:
        while True:
            took = running.check()
            if took is not None:
                return took
            time.sleep(_POLL_S)
    finally:
        running.stop()


def wait_a_moment() -> None:
    """The pause between two checks of running steps."""
    time.sleep(_POLL_S)
