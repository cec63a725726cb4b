"""The command line as a user types it wrong: bad option values, half a TLS setup, config
files that cannot be read or are not sections of lists, a key file that cannot be written.
Each is refused before the daemon starts, in the user's words, with exit code 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from support import REPO, pick_free_port

pytestmark = pytest.mark.integration  # starts processes


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "bridge.cli", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=120)


def _one_line_refusal(result: subprocess.CompletedProcess[str]) -> str:
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    return lines[-1]


@pytest.mark.parametrize("option, value, says", [
    ("--package-path", "my_msgs", "expected NAME=DIR, got 'my_msgs'"),
    ("--package-path", "=/tmp", "expected NAME=DIR, got '=/tmp'"),
    ("--stop-timeout", "soon", "expected a positive number, got 'soon'"),
    ("--stop-timeout", "-1", "expected a positive number, got '-1'"),
    ("--max-receive-buffer-bytes", "0", "expected a positive number, got '0'"),
])
def test_bad_option_values_are_named(option: str, value: str, says: str) -> None:
    line = _one_line_refusal(_cli("run", f"{option}={value}"))
    assert option in line and says in line, line


def test_half_a_tls_setup_is_refused(tmp_path: Path) -> None:
    line = _one_line_refusal(_cli("run", "--port", str(pick_free_port()),
                                  "--tls-cert", str(tmp_path / "cert.pem")))
    assert line == "slicer-ros2-bridge: --tls-cert and --tls-key: expected both, got one"


def test_a_tls_certificate_that_is_not_pem_is_refused(tmp_path: Path) -> None:
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    cert.write_text("not a certificate\n")
    key.write_text("not a key\n")
    line = _one_line_refusal(_cli("run", "--port", str(pick_free_port()),
                                  "--tls-cert", str(cert), "--tls-key", str(key)))
    assert line.startswith("slicer-ros2-bridge: --tls-cert/--tls-key: expected a PEM "
                           f"certificate chain and its private key, got {str(cert)!r} and "
                           f"{str(key)!r} ("), line


@pytest.mark.parametrize("text, says", [
    (None, "cannot read the config file {path}: No such file or directory"),
    ("subscribers: [unclosed\n", "{path} is not valid YAML: "),
    ("- topic: /a\n", "{path}: expected a mapping of sections ("),
    ("subscribers: {topic: /a}\n", "{path}: section 'subscribers' must be a list, got dict"),
    ("subscribers:\n  - /a\n", "bridges.yaml: subscribers[0]: expected a mapping of "
                               "arguments, got str"),
])
def test_config_files_that_are_not_sections_of_lists_are_refused(
        tmp_path: Path, text: str | None, says: str) -> None:
    path = tmp_path / "bridges.yaml"
    if text is not None:
        path.write_text(text)
    result = _cli("run", "--port", str(pick_free_port()), "--config", str(path))
    _one_line_refusal(result)  # (YAML's own error text spans lines: the first says it)
    first = result.stderr.splitlines()[0]
    assert first.startswith("slicer-ros2-bridge: ") and says.format(path=path) in first, first


def test_an_empty_config_file_is_no_bridges(tmp_path: Path) -> None:
    # An empty file loads (nothing to start); the next check, half a TLS setup, stops it.
    path = tmp_path / "bridges.yaml"
    path.write_text("# nothing yet\n")
    line = _one_line_refusal(_cli("run", "--config", str(path), "--tls-key", "k.pem"))
    assert line == "slicer-ros2-bridge: --tls-cert and --tls-key: expected both, got one"


def test_keygen_into_a_missing_folder_says_why(tmp_path: Path) -> None:
    target = tmp_path / "absent" / "writers.key"
    line = _one_line_refusal(_cli("keygen", str(target)))
    assert line == (f"slicer-ros2-bridge keygen: cannot write {target}: "
                    "No such file or directory")
    assert not target.parent.exists()


def test_ros_args_are_for_run_and_demo_only(tmp_path: Path) -> None:
    result = _cli("keygen", str(tmp_path / "k"), "--ros-args", "-p", "port:=1")
    line = _one_line_refusal(result)
    assert line.endswith("error: --ros-args: expected only with run or demo, got keygen"), line
    assert not (tmp_path / "k").exists()


def test_no_command_prints_the_help() -> None:
    result = _cli()
    assert result.returncode == 2
    for command in ("run", "demo", "keygen", "build-interfaces"):
        assert command in result.stdout
