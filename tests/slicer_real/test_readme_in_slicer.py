"""The README's blocks for 3D Slicer's Python console (```` ```python slicer-console ````)
run as written in a real Slicer scene, fed the demo robot by Slicer's own connector."""

from __future__ import annotations

import pytest

from support import RunningDaemon
from test_readme import README_BLOCKS, Block

CONSOLE_BLOCKS = [b for b in README_BLOCKS if b.in_slicer]


def test_the_readme_has_a_console_block() -> None:
    assert len(CONSOLE_BLOCKS) >= 1


@pytest.mark.parametrize("block", CONSOLE_BLOCKS, ids=lambda b: b.name)
def test_the_console_block_places_and_colours_the_robot(run_scene, demo: RunningDaemon,
                                                        block: Block) -> None:
    got = run_scene("console", port=demo.port, code=block.text, models=14, links=11)
    assert len(got["models"]) == 14
    for name, model in got["models"].items():
        assert model["parent"] == model["expected_parent"] and model["parent"], (name, model)
        assert model["scalars"] and model["active"] == "RGBA", (name, model)
