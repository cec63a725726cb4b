"""Mesh files parsed in reader processes, beside the daemon's loop and each other (issue 44).

Parsing a mesh file holds the interpreter's lock (trimesh reads a 3,000-triangle COLLADA or
OBJ file in about 4 ms of Python on a quiet machine): a 130-link robot's files took 0.5 s
of parsing one after the other, and more than 1 s in a daemon, whose loop sends the meshes
read so far (and every other stream) on the same interpreter meanwhile. `MeshReaders`
parses them in ``workers`` processes (one per core, at most two by default), so the files of
one robot are read side by side, and the loop keeps its interpreter.

The readers are forked by a forkserver that has imported trimesh
(`bridge.robots.mesh_worker`) once: a reader starts in milliseconds and shares those pages
(each imports the process's main module, as multiprocessing's children do; the command's,
`bridge.console`, is small). They start with the first file a robot reads, not with the
daemon (a daemon whose robots come from the mesh cache folder never needs them); until
they are up (0.2-0.5 s) files are read in the asking threads, one at a time, as without
readers. `close`
ends them (the daemon's stop); the forkserver ends with the process that started it.

A reader that dies while reading (a parser crashing on a hostile file) breaks its pool:
the pool is replaced, and each read that was in flight is made again alone, in a process
of its own; the file that kills that one too is a `MeshError`, which leaves its visual out
with a warning as any unreadable file does, and the daemon goes on serving.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
from concurrent.futures import CancelledError, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Optional, Sequence

from bridge.core.threads import OnFailure, start_thread
from bridge.robots.errors import MeshError

if TYPE_CHECKING:
    from bridge.robots.meshes import MeshData

__all__ = ["DEFAULT_READERS", "MeshReaders", "ReadMesh", "read_mesh"]

# One reader per core, two at most: the loop and the client need the rest of a small machine.
DEFAULT_READERS = max(1, min(2, os.cpu_count() or 1))

# (path, scale, max_triangles) -> the mesh; module-level, so a reader finds it by name.
ReadMesh = Callable[[str, tuple[float, ...], Optional[int]], "MeshData"]


def read_mesh(path: str, scale: tuple[float, ...], max_triangles: Optional[int]) -> MeshData:
    """In a reader: `bridge.robots.meshes.load_mesh_file`."""
    from bridge.robots.meshes import load_mesh_file

    return load_mesh_file(Path(path), scale, max_triangles=max_triangles)


def _started() -> int:
    return os.getpid()


def _reader_begins() -> None:
    """A reader ignores Ctrl-C: it reaches the daemon's whole process group, and the daemon
    ends its readers itself (`close`); a reader would print a KeyboardInterrupt."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _forkserver_context() -> multiprocessing.context.ForkServerContext:
    """Forks from a process that imported trimesh once (not the daemon's own fork: its ROS
    threads may hold locks a child would never see released)."""
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["bridge.robots.mesh_worker"])
    return context


def _pool(workers: int) -> ProcessPoolExecutor:
    return ProcessPoolExecutor(workers, mp_context=_forkserver_context(),
                               initializer=_reader_begins)


class MeshReaders:
    """A pool of ``workers`` mesh reader processes; `read` has `load_mesh_file`'s
    signature, so a `MeshCache` reads its files through it. Thread-safe: a robot's loader
    reads several files at once from its threads. ``read_file`` is what a reader runs
    (tests give one that crashes)."""

    def __init__(self, workers: int = DEFAULT_READERS, *,
                 read_file: ReadMesh = read_mesh) -> None:
        if workers < 1:
            raise ValueError(f"workers: expected at least 1, got {workers}")
        self.workers = workers
        self._read_file = read_file
        self._lock = threading.Lock()
        self._pool: Optional[ProcessPoolExecutor] = None
        self._closed = False
        self._starting = False
        self._ready = threading.Event()
        self._here = threading.Lock()

    @property
    def ready(self) -> bool:
        """Are the readers up (reads go to them, not to the asking thread)?"""
        return self._ready.is_set()

    def start(self) -> None:
        """Fork the readers now; blocks while the forkserver imports trimesh (`read` calls
        it in a thread of its own)."""
        pool = self._running()
        if pool is None:
            return
        try:
            for future in [pool.submit(_started) for _ in range(self.workers)]:
                future.result()
        except (BrokenProcessPool, CancelledError, RuntimeError):
            return  # closed meanwhile, or broken: the next read replaces the pool
        self._ready.set()

    def read(self, path: Path, scale: Sequence[float] = (1.0, 1.0, 1.0), *,
             max_triangles: Optional[int] = None) -> MeshData:
        """`load_mesh_file` in a reader process (here while they start): the same mesh, the
        same `MeshError`."""
        args = (str(path), tuple(float(s) for s in scale), max_triangles)
        if not self._ready.is_set():
            self._start_soon()
            # One file at a time here: threads parsing side by side in one process only take
            # turns at its interpreter lock (and the loop's turns with them).
            with self._here:
                if not self._ready.is_set() and not self._closed:
                    return self._read_file(*args)
        pool = self._running()
        if pool is None:
            raise MeshError(str(path), "a running daemon", "the mesh readers are stopped")
        try:
            return pool.submit(self._read_file, *args).result()
        except BrokenProcessPool:
            self._replace(pool)
        except (CancelledError, RuntimeError):  # closed while this read waited
            raise MeshError(str(path), "a running daemon",
                            "the mesh readers stopped") from None
        # A reader died, and every read in flight died with it: this one again, alone.
        with _pool(1) as alone:
            try:
                return alone.submit(self._read_file, *args).result()
            except BrokenProcessPool:
                raise MeshError(str(path), "a mesh file its reader process survives",
                                "the reader process died reading it") from None

    def close(self) -> None:
        """End the readers (reads waiting get a `MeshError`); later reads are refused."""
        with self._lock:
            self._closed = True
            self._ready.clear()
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def pids(self) -> list[int]:
        """The reader processes' ids (for tests and diagnostics)."""
        pool = self._pool
        processes = getattr(pool, "_processes", None) or {}
        return sorted(int(pid) for pid in processes)

    def _start_soon(self) -> None:
        with self._lock:
            if self._starting or self._closed:
                return
            self._starting = True
        # The helper's: a failure is logged and the start tried again (the daemon's rule).
        start_thread("mesh-readers-start", self.start, OnFailure.RESTART)

    def _running(self) -> Optional[ProcessPoolExecutor]:
        with self._lock:
            if self._closed:
                return None
            if self._pool is None:
                self._pool = _pool(self.workers)
            return self._pool

    def _replace(self, broken: ProcessPoolExecutor) -> None:
        with self._lock:
            if self._pool is broken:
                self._pool = None
        broken.shutdown(wait=False, cancel_futures=True)
