"""Host workarounds: where Linux, glibc, CPython or Fast DDS, left at their defaults, cost
the daemon latency, memory or a hang. Each module corrects one; README.md here says what
each wins, how that was measured, and how to turn the switchable ones off.

- receive_priority.py: the DDS receive threads' scheduling (a short slice; SCHED_FIFO on
  request, `--receive-priority`).
- shm_locks.py: Fast DDS shared-memory port locks and segments a killed process left.
- shm_ports.py: a watch thread that says when Fast DDS keeps writing to a replaced port,
  and clears what shm_locks finds.
- allocator.py: glibc's mmap threshold fixed, so large buffers do not ratchet memory up.
- interpreter.py: CPython's GIL switch interval and cyclic collector for streaming threads.

The compiled fast paths (the tf store, the rcl reader, the io_uring fan-out) are not
workarounds but the daemon's own paths; their switches (`--tf-store`, `--ros-take`,
`--send-batch`) are in DaemonConfig.fast_paths, weighed in README.md too.
"""
