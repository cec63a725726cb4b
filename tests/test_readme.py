"""The READMEs' code runs as written against `make demo` (issue 25, item 6): README.md and
slicer_client/README.md.

Every fenced block of each README names its language, and the language says what the test
does with it:

- ``python``: run, on its own, with the venv's Python in the repository (as a reader pastes
  it into `.venv/bin/python`), against the demo; it must exit 0;
- ``sh``: run with bash in the repository, against the demo; it must exit 0;
- ``yaml``: a `--config` file: a second daemon starts with it, beside the demo, and must
  list every bridge it names;
- ``text``: output or a drawing, never run.

A block for 3D Slicer's Python console says so after the language: ```` ```python
slicer-console ````; the real-Slicer tier runs it in a real Slicer scene fed by Slicer's own
connector (tests/slicer_real/test_readme_in_slicer.py). A block that cannot run here says so
and why in its info string, after the language:
```` ```sh no-run: a synopsis ````. (GitHub highlights by the first word
alone.) The demo is `make demo` on the README's port, 18944; where that port is taken (a 3D
Slicer, another demo), the demo gets a free port and the blocks get that port in its place,
which the test prints.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import pytest
import yaml

from protocol.commands import REQUEST_TYPES, bridge_kinds
from slicer_client.connection import CommandRefusedError
from support import (REPO, Child, Processes, assert_clean_exit, pick_free_port, scaled,
                     start_daemon)

pytestmark = pytest.mark.ros

# Each README checked, with how many runnable blocks it has at least (so they cannot go
# missing unnoticed).
READMES = {"README.md": 5, "slicer_client/README.md": 2}
README_PORT = 18944
RUNNERS = ("python", "sh", "yaml")
NOT_RUN = ("text",)
SLICER_CONSOLE = "slicer-console"
_FENCE = re.compile(r"^(?P<indent> *)```(?P<info>[^`]*)$")


@dataclass(frozen=True)
class Block:
    """One fenced block: its README, its language, why it is not run ("" if it is), its
    text, and the README line its fence opens on."""

    readme: str
    language: str
    no_run: str
    text: str
    line: int
    in_slicer: bool = False  # `python slicer-console`: run in a real Slicer scene

    @property
    def name(self) -> str:
        return f"{self.readme}:{self.line}:{self.language}"


class ReadmeFormatError(ValueError):
    """A fence the test cannot take: it says which line, what was expected and what came."""


def blocks(markdown: str, readme: str = "README.md") -> list[Block]:
    """Every fenced block of ``markdown`` (the text of ``readme``), its indentation removed
    (a block in a list item is indented)."""
    found: list[Block] = []
    lines = markdown.splitlines()
    i = 0
    while i < len(lines):
        opening = _FENCE.match(lines[i])
        if opening is None:
            i += 1
            continue
        indent, info = opening["indent"], opening["info"].strip()
        language, _, rest = info.partition(" ")
        rest = rest.strip()
        in_slicer = rest == SLICER_CONSOLE
        if rest and not in_slicer and not rest.startswith("no-run:"):
            raise ReadmeFormatError(f"{readme}:{i + 1}: expected 'no-run: <why>' or "
                                    f"'{SLICER_CONSOLE}' after the language, got {rest!r}")
        body: list[str] = []
        i += 1
        while i < len(lines) and lines[i].strip() != "```":
            body.append(lines[i][len(indent):] if lines[i].startswith(indent) else lines[i])
            i += 1
        if i == len(lines):
            raise ReadmeFormatError(f"{readme}:{len(found)}: a fence opened and never closed")
        no_run = "" if in_slicer else rest.removeprefix("no-run:").strip()
        found.append(Block(readme, language, no_run, "\n".join(body) + "\n", i - len(body),
                           in_slicer))
        i += 1
    return found


README_BLOCKS = [block for readme in READMES
                 for block in blocks((REPO / readme).read_text(), readme)]


@pytest.mark.parametrize("readme", list(READMES))
def test_every_block_says_what_it_is(readme: str) -> None:
    """A language the test knows, and a reason wherever a runnable one is not run."""
    found = [b for b in README_BLOCKS if b.readme == readme]
    for block in found:
        assert block.language in RUNNERS + NOT_RUN, (
            f"{block.name}: expected a language among {RUNNERS + NOT_RUN}, got "
            f"{block.language!r}")
        if block.language in NOT_RUN:
            assert not block.no_run, f"{block.name}: text is never run; no reason needed"
    ran = [b for b in found if b.language in RUNNERS and not b.no_run]
    assert len(ran) >= READMES[readme], f"{readme}'s runnable examples went missing"


def test_a_fence_names_its_readme_when_it_is_wrong() -> None:
    with pytest.raises(ReadmeFormatError, match=r"^slicer_client/README\.md:3: expected "
                                                r"'no-run: <why>'"):
        blocks("text\n\n```python later\nx = 1\n```\n", "slicer_client/README.md")


def _port_free(port: int) -> bool:
    with socket.socket() as sock:
        try:
            sock.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


@dataclass
class Demo:
    child: Child
    port: int

    def as_written(self, text: str) -> str:
        return text if self.port == README_PORT else text.replace(str(README_PORT),
                                                                  str(self.port))


@pytest.fixture(scope="module")
def demo(module_processes: Processes) -> Iterator[Demo]:
    """`make demo` (on the README's port if it is free), stopped as Ctrl-C stops it: SIGINT
    to the whole process group, make and the demo."""
    port = README_PORT if _port_free(README_PORT) else pick_free_port()
    if port != README_PORT:
        print(f"\nport {README_PORT} is taken here: the demo and the README's blocks use "
              f"{port}")
    argv = ["make", "--no-print-directory", "demo"]
    if port != README_PORT:
        argv.append(f"DEMO_ARGS=--port {port}")
    child = module_processes.start("make-demo", argv)
    child.wait_for_output("Stop with Ctrl-C", timeout=300)  # set-up first, when not in place
    yield Demo(child, port)
    os.killpg(child.pid, signal.SIGINT)
    child.popen.wait(scaled(30))  # make itself ends by the signal (exit -2), after the demo
    output = child.output()
    assert "shutting down (SIGINT)" in output, output[-3000:]
    assert "Traceback" not in output and not re.search(r" (ERROR|CRITICAL) ", output), \
        output[-3000:]


def _run(block: Block, demo: Demo) -> subprocess.CompletedProcess[str]:
    text = demo.as_written(block.text)
    argv = [sys.executable, "-c", text] if block.language == "python" else \
        ["bash", "-euo", "pipefail", "-c", text]
    return subprocess.run(argv, cwd=str(REPO), capture_output=True, text=True,
                          timeout=scaled(120), start_new_session=True,
                          env={**os.environ, "PATH": f"{REPO / '.venv' / 'bin'}:"
                                                     f"{os.environ['PATH']}"})


def _run_config(block: Block, processes: Processes, tmp_path: Path) -> None:
    """The block as `--config` of a daemon beside the demo: it starts (a bridge it cannot
    create stops it, one line and exit 2) and lists every bridge the file names."""
    config = tmp_path / "bridges.yaml"
    config.write_text(block.text)
    daemon = start_daemon(processes, "--config", str(config))
    named = yaml.safe_load(block.text)
    with daemon.connect() as client:
        kinds = [b["kind"] for b in client.command("list_bridges")["bridges"]]
    expected = {"subscribers": "subscriber", "publishers": "publisher",
                "tf_lookups": "tf_lookup", "robots": "robot"}
    for section, kind in expected.items():
        assert kinds.count(kind) == len(named.get(section, [])), (section, kinds)
    assert_clean_exit(daemon)


@pytest.mark.parametrize("block", [b for b in README_BLOCKS
                                   if b.language in RUNNERS and not b.no_run
                                   and not b.in_slicer],
                         ids=lambda b: b.name)
def test_the_block_runs_against_the_demo(block: Block, demo: Demo, processes: Processes,
                                         tmp_path: Path) -> None:
    if block.language == "yaml":
        _run_config(block, processes, tmp_path)
        return
    result = _run(block, demo)
    output = result.stdout + result.stderr
    assert result.returncode == 0, f"{block.name} exited {result.returncode}:\n{output[-4000:]}"
    assert "Traceback" not in output, output[-4000:]


# --- protocol/README.md's op tables against the registry ----------------------------------
def test_the_op_tables_list_every_op_once_and_only_ops() -> None:
    """protocol/README.md §3.5: each op of the schema (`REQUEST_TYPES`) has one row, and
    each row names an op (a new op without its row fails here, named)."""
    text = (REPO / "protocol" / "README.md").read_text()
    tables = text[text.index("### 3.5"):text.index("### 3.6")]
    rows = re.findall(r"^\| `([a-z_]+)`(?: \([^|]*\))? \|", tables, re.M)
    missing = [op for op in REQUEST_TYPES if op not in rows]
    assert not missing, f"protocol/README.md §3.5: no row for the ops {missing}"
    unknown = [op for op in rows if op not in REQUEST_TYPES]
    assert not unknown, f"protocol/README.md §3.5: rows for {unknown}, which are no ops"
    twice = sorted({op for op in rows if rows.count(op) > 1})
    assert not twice, f"protocol/README.md §3.5: two rows for {twice}"


def test_the_security_page_s_read_and_write_columns_follow_the_declarations() -> None:
    """docs/security.md, "What a client can do": an op in the changes column declares
    ``writes`` (what --read-only refuses), one in the receives column does not, and every
    op that writes is in the changes column."""
    text = (REPO / "docs" / "security.md").read_text()
    table = text[text.index("| area | receives (read) | changes (write) |"):]
    table = table[:table.index("\n\n")]
    reads, writes = set(), set()
    for row in table.splitlines()[2:]:
        cells = row.strip("|").split(" | ")
        reads |= set(re.findall(r"`([a-z_]+)`", cells[1])) & set(REQUEST_TYPES)
        writes |= set(re.findall(r"`([a-z_]+)`", cells[2])) & set(REQUEST_TYPES)
    declared = {op for op, cls in REQUEST_TYPES.items() if cls.writes}
    assert sorted(reads & declared) == [], "in the receives column, but they write"
    assert sorted(writes - declared) == [], "in the changes column, but they only read"
    assert sorted(declared - writes) == [], "they write, but are not in the changes column"


# --- protocol/README.md's list_bridges row against a live reply ----------------------------
def _documented_result(op: str) -> dict[str, Any]:
    """The ``← result`` example of ``op``'s row in protocol/README.md's op tables (the
    first backticked JSON object of its third cell)."""
    for line in (REPO / "protocol" / "README.md").read_text().splitlines():
        if line.startswith(f"| `{op}` |"):
            cells = [cell.strip() for cell in line.strip("|").split(" | ")]
            example = re.match(r"`(\{[^`]*\})`", cells[2])
            assert example, f"{op}'s result cell: expected a backticked JSON object first, " \
                            f"got {cells[2][:80]!r}"
            return dict(json.loads(example.group(1)))
    raise AssertionError(f"protocol/README.md: expected a row for {op}, found none")


def _same_shape(documented: Any, live: Any, where: str) -> None:
    """Documented and live JSON of one kind: objects with the same keys (the documented
    ones all present, in entries of a list: an entry's extra keys are its kind's own), lists
    compared by their first entries of the same kind."""
    if documented is None or live is None:
        return  # null means absent for now (parameter_server)
    assert type(documented) is type(live) or {type(documented), type(live)} <= {int, float}, \
        f"{where}: documented {type(documented).__name__}, live {type(live).__name__}"
    if isinstance(documented, dict) and where.endswith("]"):
        missing = set(documented) - set(live)
        assert not missing, f"{where}: documented keys {sorted(missing)} not in the reply"
    elif isinstance(documented, dict):
        assert set(documented) == set(live), f"{where}: documented {sorted(documented)}, " \
                                             f"live {sorted(live)}"
    if isinstance(documented, dict):
        for key in documented:
            _same_shape(documented[key], live[key], f"{where}.{key}")
    elif isinstance(documented, list):
        for entry in documented:
            same = [e for e in live if not isinstance(entry, dict)
                    or e.get("kind") == entry.get("kind")]
            if same:
                _same_shape(entry, same[0], f"{where}[]")


def test_the_documented_list_bridges_reply_is_the_daemon_s(processes: Processes) -> None:
    """protocol/README.md's list_bridges row: the reply's keys, and each documented entry's
    keys in a live entry of its kind (a subscriber, a served service, cached ROS clients)."""
    documented = _documented_result("list_bridges")
    daemon = start_daemon(processes)
    with daemon.connect() as client:
        client.command("create_subscriber", {"topic": "/readme_tool",
                                             "type": "geometry_msgs/msg/PoseStamped"})
        client.command("advertise_service", {"service": "/readme/reset",
                                             "type": "std_srvs/srv/Trigger"})
        with pytest.raises(CommandRefusedError):
            client.command("call_service", {"service": "/readme/absent",
                                            "type": "std_srvs/srv/Trigger", "timeout": 0.1})
        with pytest.raises(CommandRefusedError):
            client.command("send_goal", {"action": "/readme/absent", "timeout": 0.1,
                                         "type": "control_msgs/action/GripperCommand",
                                         "goal": {}})
        live = client.command("list_bridges")
    assert {b["kind"] for b in live["bridges"]} <= set(bridge_kinds())
    _same_shape(documented, live, "list_bridges")
    assert_clean_exit(daemon)
