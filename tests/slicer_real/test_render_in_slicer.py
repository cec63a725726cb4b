"""Slicer's own 3D displayable managers render the real scene offscreen (what the README's
demo picture is made with: tools/render_scene_picture.py)."""

from __future__ import annotations

from pathlib import Path


def test_a_model_is_drawn_by_slicer_s_displayable_managers(run_scene, tmp_path: Path) -> None:
    got = run_scene("render_check", out=str(tmp_path / "ball.png"))
    assert got["count"] == 200 * 200
    # The sphere covers the middle of the view, the white background the corners.
    assert 0.2 < got["red"] < 0.8 and got["white"] > 0.2, got
