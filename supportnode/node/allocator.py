"""Keep freed memory in the process for the next scan (glibc's malloc).

A detection allocates and frees tens of megabytes of numpy arrays per scan. By default glibc
hands blocks above a dynamic threshold back to the kernel (mmap, heap trimming), so the next
scan faults the same pages in again and the kernel zeroes them: about 5,000 page faults per
detection on a room-sized map, 20 % of its time on this machine. A node is a long-running
process whose working set is the same scan after scan, so it keeps that memory instead.
Memory use then stays at the peak of one scan; it is still flat over time.

Process-wide: `supportnode run` calls it; programs that embed a `Node` may call it too.
"""

from __future__ import annotations

import ctypes
import sys

__all__ = ["retain_freed_memory"]

# mallopt parameters (malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
# glibc refuses mmap thresholds above half its 64 MB heap size on 64-bit systems; blocks above
# it (a map of millions of points) are still mapped and unmapped each time.
_MMAP_THRESHOLD = 32 * 1024 * 1024
_TRIM_THRESHOLD = 1 << 30


def retain_freed_memory() -> bool:
    """Ask glibc to keep freed blocks up to 32 MB for reuse; True when it agreed. A no-op
    (False) on other platforms and C libraries."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):  # no glibc (musl, ...)
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    # Both: setting the trim threshold alone also freezes the mmap threshold at 128 kB.
    ok = mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD) == 1
    return mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD) == 1 and ok
