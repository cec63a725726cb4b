"""ROS data in a real Slicer scene through the module: tf, an image, a point cloud,
markers and text, each as the node Slicer's own connector makes (scenes/ros_data.py)."""

from __future__ import annotations

import numpy as np
import pytest

from support import Processes, RunningDaemon


def test_tf_images_clouds_markers_and_text_become_slicer_nodes(
        run_scene, daemon: RunningDaemon, processes: Processes) -> None:
    processes.python("data", "scene_data_publisher.py").wait_for_output("READY")
    got = run_scene("ros_data", port=daemon.port)
    # tf: world -> base (100, 200, 300) mm, base -> tool (10, 20, 30) mm turned 90° about z.
    np.testing.assert_allclose(got["tf"], [[0, -1, 0, 110], [1, 0, 0, 220], [0, 0, 1, 330],
                                           [0, 0, 0, 1]], atol=1e-4)
    # The image: a scalar volume of 1 slice, 3 rows, 4 columns, as published.
    assert got["volume"]["class"] == "vtkMRMLScalarVolumeNode"
    assert got["volume"]["pixels"] == [[[10 * r + c for c in range(4)] for r in range(3)]]
    # The cloud: 4 points in mm, in order, one vertex each (the daemon sends one polyvertex
    # cell: a vertex cell per point crashed Slicer's converter, which keeps the first id of
    # a cell; the module gives each point its vertex again), and its colours as published.
    np.testing.assert_allclose(got["cloud"]["points"],
                               [[10.0 * i, 20.0 * i, 30.0 * i] for i in range(4)], atol=1e-3)
    assert got["cloud"]["vertices"] == [1, 0, 1, 1, 1, 2, 1, 3]
    np.testing.assert_allclose(got["cloud"]["colours"],
                               [[40 * i / 255, 80 / 255, 120 / 255, 1.0] for i in range(4)],
                               atol=1e-6)
    assert got["text"].startswith("note ")
    # Markers: the cube as a red model 20 mm wide placed in world by tf, the text as a
    # labelled point at (0.03, 0, 0) m in base, i.e. (130, 200, 300) mm in world.
    cubes = [m for m in got["markers"] if m["type"] == "cube"]
    assert len(cubes) == 1 and cubes[0]["class"] == "vtkMRMLModelNode"
    x0, x1, y0, y1, z0, z1 = cubes[0]["bounds"]
    assert (x1 - x0, y1 - y0, z1 - z0) == pytest.approx((20.0, 20.0, 20.0), abs=1e-3)
    assert cubes[0]["colour"] == pytest.approx([1.0, 0.0, 0.0])
    (dots,) = [m for m in got["markers"] if m["type"] == "points"]
    assert dots["vertices"] == [1, 0, 1, 1, 1, 2]
    assert got["label"]["text"] == "hello"
    assert got["label"]["world"] == pytest.approx([130.0, 200.0, 300.0], abs=1e-3)
