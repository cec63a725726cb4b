"""Ctrl-C during `make setup` (tools/setup_env.py) ends it with one line, never a traceback
(issue 25, item 10), and stops the step it interrupted."""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import pytest

from support import REPO, Processes, scaled, wait_until

MESSAGE = "[setup] interrupted (Ctrl-C); run `make setup` again to finish"


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rfind(")") + 2:].split()[0] != "Z"


def test_ctrl_c_while_a_set_up_step_runs_says_one_line_and_stops_the_step(
        processes: Processes, tmp_path: Path) -> None:
    """The route `make setup` takes around each step, setup_env's own `guarded` and `run`,
    with a stand-in step that waits (not minutes of pip); SIGINT goes to the process group,
    as a terminal's Ctrl-C does."""
    pid_file = tmp_path / "step.pid"
    step = (f"import os, pathlib, time; "
            f"pathlib.Path({str(pid_file)!r}).write_text(str(os.getpid())); "
            f"time.sleep(600)")
    driver = (f"import sys; sys.path.insert(0, {str(REPO / 'tools')!r}); "
              f"from pathlib import Path; import setup_env; "
              f"sys.exit(setup_env.guarded(lambda: setup_env.run('pip install', "
              f"[sys.executable, '-c', {step!r}], Path({str(tmp_path / 'step.log')!r})) "
              f"or 0))")
    setup = processes.start("setup", [sys.executable, "-u", "-c", driver])
    setup.wait_for_output("[setup] pip install ...")
    wait_until(pid_file.exists, 20, "the step's process to start")
    step_pid = int(pid_file.read_text())
    assert _alive(step_pid)

    os.killpg(setup.pid, signal.SIGINT)
    assert setup.popen.wait(scaled(30)) == 128 + signal.SIGINT
    output = setup.output()
    assert "Traceback" not in output, output
    lines = output.splitlines()
    assert lines[-1] == MESSAGE, output
    # Before it: only the step's own lines (its start, and progress if it took a while).
    assert all(line.startswith("[setup] pip install") for line in lines[:-1]), output
    assert not _alive(step_pid)  # stopped with its process group before set-up ended


def test_set_up_s_entry_point_is_the_guarded_one(monkeypatch: pytest.MonkeyPatch) -> None:
    """`make setup` runs main(): it must go through `guarded`, or Ctrl-C is a traceback
    again."""
    monkeypatch.syspath_prepend(str(REPO / "tools"))
    import setup_env
    calls: list[object] = []

    def guarded(body: object) -> int:
        calls.append(body)
        return 7
    monkeypatch.setattr(setup_env, "guarded", guarded)
    assert setup_env.main() == 7
    assert calls == [setup_env.set_up]


def test_a_set_up_cut_short_after_pip_does_not_run_pip_again(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Issue 43, item 13: Ctrl-C in the interface build, then `make setup` again, ran pip
    (and the compiled modules' build) in full once more. The steps are stood in for by
    recorders; the stamps and the order are set_up's own."""
    monkeypatch.syspath_prepend(str(REPO / "tools"))
    import setup_env

    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "python").write_text("")
    monkeypatch.setattr(setup_env, "VENV", venv)
    monkeypatch.setattr(setup_env, "STAMP", venv / "setup-stamp")
    monkeypatch.setattr(setup_env, "PACKAGES_STAMP", venv / "packages-stamp")
    monkeypatch.setattr(setup_env, "CACHE", tmp_path / "cache")
    monkeypatch.setattr(setup_env, "BUILD", tmp_path / "build")
    ran: list[str] = []
    cut_short = [True]

    def interfaces() -> None:
        ran.append("interfaces")
        if cut_short[0]:
            raise KeyboardInterrupt
    for name in ("check_python", "check_build_tools", "create_venv", "install_project",
                 "build_compiled_modules", "ensure_cmake", "verify"):
        monkeypatch.setattr(setup_env, name, lambda name=name: ran.append(name))
    monkeypatch.setattr(setup_env, "build_shipped_interfaces", interfaces)

    assert setup_env.guarded(setup_env.set_up) == 128 + signal.SIGINT
    assert ran[-4:] == ["install_project", "build_compiled_modules", "ensure_cmake",
                        "interfaces"]
    ran.clear()
    cut_short[0] = False
    assert setup_env.guarded(setup_env.set_up) == 0
    assert "install_project" not in ran and "build_compiled_modules" not in ran, ran
    assert ran[-3:] == ["ensure_cmake", "interfaces", "verify"]
    ran.clear()
    assert setup_env.guarded(setup_env.set_up) == 0 and ran == []  # all in place
