"""Run by tests/packaging/test_wheels.py with the client wheel's own Python (3.9 there):
only the installed `slicer_client` and `protocol`, outside the repository.

usage: client_wheel_probe.py PORT IMAGE_TOPIC MODEL_TOPIC MODEL_SEEN_FILE
Loads the demo robot (its meshes are messages of 3 KB and more), waits for one image on
IMAGE_TOPIC, then sends a model to MODEL_TOPIC until MODEL_SEEN_FILE exists (the test makes
it once ROS has the model). Prints one `RESULT {json}` line per step; exits 0 when done.
Written for Python 3.9: no project code but the wheel's.
"""

import json
import sys
import time
from pathlib import Path

import numpy as np

import slicer_client
from protocol import crc64


def result(step: str, **values: object) -> None:
    print("RESULT " + json.dumps({"step": step, **values}), flush=True)


def main() -> int:
    port, image_topic, model_topic, seen = int(sys.argv[1]), sys.argv[2], sys.argv[3], \
        Path(sys.argv[4])
    result("environment", python=list(sys.version_info[:2]), numpy=np.__version__,
           crc_backend=crc64.BACKEND)
    ros = slicer_client.connect("127.0.0.1", port, reconnect=False)
    try:
        robot = ros.robot("demo")
        robot.wait_until_loaded(timeout=120)
        sizes = sorted(len(mesh.pack()) for link in robot.links.values()
                       for mesh in link.meshes.values())
        result("robot", links=sorted(robot.links), meshes=len(sizes), largest_body=sizes[-1],
               bodies_over_3kb=sum(1 for size in sizes if size >= 3072))

        image = ros.subscribe(image_topic, "Image").wait_for_message(timeout=120)
        pixels = np.asarray(image)
        result("image", shape=list(pixels.shape), sum=int(pixels.astype(np.int64).sum()))

        grid = np.stack(np.meshgrid(np.arange(30.0), np.arange(30.0)), -1).reshape(-1, 2)
        points = np.column_stack([grid, np.zeros(len(grid))])  # 900 points in mm: ~11 KB
        triangles = [[i, i + 1, i + 30] for i in range(30 * 29) if i % 30 != 29]
        publisher = ros.publisher(model_topic, "shape_msgs/msg/Mesh", frame="base_link")
        deadline = time.monotonic() + 120
        while not seen.exists() and time.monotonic() < deadline:
            publisher.send_model((points, triangles))  # again until a ROS subscriber has it
            time.sleep(0.2)
        result("model", points=len(points), triangles=len(triangles), seen=seen.exists(),
               errors=list(ros.errors))
        return 0 if seen.exists() else 1
    finally:
        ros.close()


if __name__ == "__main__":
    sys.exit(main())
