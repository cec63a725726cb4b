"""A robot load in steps (issue 44): every link's lookup starts once the URDF is parsed,
before any mesh goes out; each mesh goes out once, as it is read; a reload or a removal
during the load leaves no device of the old load behind. The robot capability on the loop
with its worker thread, the hub and tf replaced by recorders (no ROS, no socket)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any, Optional

from bridge.robots.capability import RobotServing
from bridge.robots.demo import DEMO_URDF, demo_urdf_path
from protocol.commands import CreateRobot, RemoveRobot, RobotSource
from protocol.messages import PolyData
from protocol.naming import DeviceNameRegistry

ONE_BOX = ('<robot name="box"><link name="base_link"><visual><geometry><box size="1 1 1"/>'
           '</geometry></visual></link></robot>')


class Recorder:
    """The hub and the tf lookups, as the capability sees them: what it did, in order."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.events: list[tuple[str, str]] = []
        self.persistent: dict[str, Any] = {}
        self.lookups: dict[int, str] = {}
        self.groups: set[str] = set()
        self.on_mesh: Optional[Any] = None

    # hub
    def call_soon(self, callback: Any, *args: Any) -> None:
        self.loop.call_soon_threadsafe(callback, *args)

    def publish_persistent(self, message: Any) -> None:
        assert isinstance(message.body, PolyData)
        self.events.append(("mesh", message.device_name))
        self.persistent[message.device_name] = message
        if self.on_mesh is not None:
            self.on_mesh()

    def stream(self, message: Any) -> None:
        self.events.append(("status", message.device_name))

    def bridge_device(self, key: Any, device: str) -> None:
        pass  # who gets it is the hub's (tests/bridge/test_stream_audience.py)

    def forget(self, device: str) -> None:
        self.events.append(("forget", device))
        self.persistent.pop(device, None)

    # tf
    def stream_lookup(self, parent: str, child: str, *, device: str, metadata: Any,
                      group: Optional[str] = None) -> int:
        assert group is not None and group in self.groups  # a robot's poses go as one TDATA
        self.events.append(("lookup", device))
        handle = len(self.events)
        self.lookups[handle] = device
        return handle

    def stop_lookup(self, handle: int) -> None:
        self.lookups.pop(handle)

    def open_pose_group(self, device: str, metadata: Any) -> None:
        self.groups.add(device)

    def close_pose_group(self, device: str) -> None:
        self.groups.discard(device)


class Guard:
    def readable_roots(self) -> None:
        return None

    def frame_refusal(self, frame: str) -> None:
        return None

    def check_frame(self, field: str, frame: str) -> None:
        return None


class Served(RobotServing):
    """Descriptions from `texts` (by robot name), as a parameter would give them."""

    texts: dict[str, str] = {}

    async def _first_description(self, robot: Any) -> Optional[str]:
        return self.texts[robot.name]


def serving(tmp_path: Path) -> tuple[Served, Recorder]:
    _, packages = demo_urdf_path(tmp_path / "demo")
    recorder = Recorder(asyncio.get_running_loop())
    served = Served(recorder, DeviceNameRegistry(), tf=recorder,  # type: ignore[arg-type]
                    package_paths=packages)
    served.texts = {"arm": DEMO_URDF}
    return served, recorder


def create(name: str = "arm") -> CreateRobot:
    return CreateRobot(name=name, source=RobotSource(kind="parameter"))


async def settle(served: Served) -> None:
    while served._tasks:
        await asyncio.gather(*served._tasks, return_exceptions=True)
    await asyncio.sleep(0)


def test_links_stream_before_any_mesh_and_each_mesh_goes_out_once(tmp_path: Path) -> None:
    async def run() -> None:
        served, recorder = serving(tmp_path)
        result: Any = (await served.create_robot(create(), None, Guard())).reply  # type: ignore[arg-type]
        kinds = [kind for kind, _ in recorder.events]
        links = [item["device"] for item in result.links]
        visuals = [item["device"] for item in result.visuals]
        assert len(links) == 11 and len(visuals) == 14
        assert kinds.index("mesh") > max(i for i, k in enumerate(kinds) if k == "lookup")
        assert sorted(d for k, d in recorder.events if k == "lookup") == sorted(links)
        meshes = [d for k, d in recorder.events if k == "mesh"]
        assert sorted(meshes) == sorted(visuals)  # each once: none sent again at the end
        assert set(recorder.persistent) == set(visuals)
        assert kinds[-1] == "status"  # "loaded", with the counts, after the last mesh
        served.close()

    asyncio.run(run())


def test_a_reload_forgets_what_the_previous_load_sent(tmp_path: Path) -> None:
    async def run() -> None:
        served, recorder = serving(tmp_path)
        await served.create_robot(create(), None, Guard())  # type: ignore[arg-type]
        robot = served.robots["arm"]
        served._reload(robot, ONE_BOX)
        await settle(served)
        assert robot.state == "loaded" and len(robot.visuals) == 1
        assert set(recorder.persistent) == set(robot.visuals)
        assert sorted(recorder.lookups.values()) == [robot.links["base_link"].device]
        served.close()

    asyncio.run(run())


def test_a_robot_removed_while_its_meshes_are_read_leaves_nothing(tmp_path: Path) -> None:
    async def run() -> None:
        served, recorder = serving(tmp_path)
        removed: list[dict[str, Any]] = []

        def remove() -> None:
            removed.append(served.remove_robot(RemoveRobot(name="arm")))

        def remove_after_first_mesh() -> None:  # a request between two of the loop's turns
            recorder.on_mesh = None
            recorder.loop.call_soon(remove)

        recorder.on_mesh = remove_after_first_mesh
        await served.create_robot(create(), None, Guard())  # type: ignore[arg-type]
        await settle(served)
        assert removed and "arm" not in served.robots
        assert recorder.persistent == {} and recorder.lookups == {} and recorder.groups == set()
        served.close()

    asyncio.run(run())
