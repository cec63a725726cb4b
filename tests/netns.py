"""Hosts on one machine for tests that cross a network: Linux network namespaces joined by
veth pairs ("cables"), with addresses that exist only inside them (iproute2, as root).

    with Hosts(["robot", "bridge", "slicer"],
               cables=[("robot", "bridge", "10.77.1"), ("bridge", "slicer", "10.77.0")]) as net:
        net.address("bridge", "slicer")      # the bridge's address on that cable: 10.77.0.1
        net.argv("bridge", [python, ...])    # run a command on that host
        net.pull("bridge", "slicer")         # the cable goes dead: no carrier, nothing passes
        net.plug("bridge", "slicer")

A pulled cable is the far end's link set down: both ends lose carrier, packets are dropped
and nothing tells TCP, as when a cable is pulled. Every namespace and link goes on exit.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid
from typing import Dict, List, Sequence, Tuple

import pytest

Cable = Tuple[str, str, str]  # host a, host b, a /24 prefix ("10.77.0": a .1, b .2)


class Hosts:
    def __init__(self, names: Sequence[str], cables: Sequence[Cable]) -> None:
        self._tag = uuid.uuid4().hex[:6]
        self.names = list(names)
        self.cables = list(cables)
        self._namespaces: Dict[str, str] = {n: f"srb{self._tag}{n[:4]}" for n in names}
        self._ends: Dict[Tuple[str, str], Tuple[str, str]] = {}  # (a, b) -> (link, address)

    def __enter__(self) -> Hosts:
        if os.geteuid() != 0 or shutil.which("ip") is None:
            pytest.skip("needs root and iproute2's ip (network namespaces for several hosts)")
        try:
            for name in self.names:
                self._ip("netns", "add", self._namespaces[name])
                self._ip("-n", self._namespaces[name], "link", "set", "lo", "up")
            for i, (a, b, prefix) in enumerate(self.cables):
                link_a, link_b = f"v{self._tag}{i}a", f"v{self._tag}{i}b"
                self._ip("link", "add", link_a, "type", "veth", "peer", "name", link_b)
                for host, link, last in ((a, link_a, 1), (b, link_b, 2)):
                    ns = self._namespaces[host]
                    self._ip("link", "set", link, "netns", ns)
                    self._ip("-n", ns, "addr", "add", f"{prefix}.{last}/24", "dev", link)
                    self._ip("-n", ns, "link", "set", link, "multicast", "on", "up")
                    self._ends[(host, b if host == a else a)] = (link, f"{prefix}.{last}")
        except (OSError, subprocess.CalledProcessError) as error:
            self.__exit__()
            pytest.skip(f"cannot make network namespaces here: {error}")
        return self

    def __exit__(self, *exc: object) -> None:
        for ns in self._namespaces.values():  # deleting a namespace deletes its veth ends
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)

    @staticmethod
    def _ip(*args: str) -> None:
        subprocess.run(["ip", *args], check=True, capture_output=True, text=True)

    def address(self, host: str, toward: str) -> str:
        """`host`'s address on its cable to `toward`."""
        return self._ends[(host, toward)][1]

    def argv(self, host: str, argv: Sequence[str]) -> List[str]:
        """`argv` run on `host` (its network namespace; the same files and processes)."""
        return ["ip", "netns", "exec", self._namespaces[host], *argv]

    def route_default(self, host: str, toward: str) -> None:
        """`host` sends everything it has no route for (DDS multicast discovery) down its
        cable to `toward`."""
        link, _ = self._ends[(host, toward)]
        self._ip("-n", self._namespaces[host], "route", "add", "default", "dev", link)

    def pull(self, a: str, b: str) -> None:
        """The cable between `a` and `b` goes dead (b's end loses its link)."""
        link, _ = self._ends[(b, a)]
        self._ip("-n", self._namespaces[b], "link", "set", link, "down")

    def plug(self, a: str, b: str) -> None:
        link, _ = self._ends[(b, a)]
        self._ip("-n", self._namespaces[b], "link", "set", link, "up")
