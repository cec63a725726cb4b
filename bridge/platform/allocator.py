"""Keep large, short-lived buffers from ratcheting the daemon's memory up (glibc only).

Images and point clouds of tens of MB pass through the daemon many times a second, made in
the ROS executor's thread and freed in the event loop's. glibc serves an allocation above
its mmap threshold with its own mapping, given back to the system at free; but its default
threshold is dynamic: each such free raises it (up to 32 MiB), so from the first 20 MB
message on, those buffers come from the heap arenas instead, where freed memory is kept
and fragmented. Repeated floods then raised RSS 510 -> 712 -> 802 MB, and no garbage
collection brought it back. A fixed threshold keeps large buffers on their own mappings.
"""

from __future__ import annotations

import ctypes
import logging
import sys

__all__ = ["MMAP_THRESHOLD_BYTES", "keep_large_buffers_returnable"]

log = logging.getLogger(__name__)

# Above this, a buffer gets its own mapping, returned at free (and zeroed by the kernel
# when mapped: about 1 ms per 4 MB). Above VGA and 720p images, so that common camera
# streams keep reusing heap memory; far below the clouds and volumes that ratcheted RSS.
MMAP_THRESHOLD_BYTES = 4 * 1024 * 1024
_M_MMAP_THRESHOLD = -3  # malloc.h


def keep_large_buffers_returnable() -> bool:
    """Fix glibc's mmap threshold (call before threads start); whether it was set."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    if mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) != 1:
        log.debug("mallopt(M_MMAP_THRESHOLD) refused; large buffers may stay in the heap")
        return False
    return True
