"""Large frames without page faults: the C allocator kept from returning big blocks.

A streamed camera frame (0.3–0.9 MB) is still copied on its way — into its message's
encoding, into the Zenoh sample, out of it on the other side (and into its typed buffer
first when the device posts a writeable array; framework/data.py).  glibc serves a
block of 128 KiB or more with a fresh ``mmap`` and returns it with ``munmap`` when
freed, so every copy of every frame lands in fresh pages and pays a page fault per
4 KiB: on the development machine a 0.9 MB copy took ~480 µs that way against ~80 µs
into reused memory, and a service's path per 0.9 MB frame 606 µs against 113 µs
(``benchmarks/service_frames.py --large``).  :func:`tune_allocator` raises glibc's
mmap threshold to 64 MiB and its trim threshold to 128 MiB (``mallopt``), so those
blocks come from the heap and are reused; the price is that a process keeps up to
128 MiB of freed memory instead of returning it to the system at once.

Called once per process when a participant starts; ``PLUGCELL_MALLOC=default`` leaves
the allocator as it is.  Only glibc has ``mallopt``: elsewhere (musl, macOS,
Windows) nothing changes.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

#: glibc's mallopt parameters (malloc.h).
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD = 64 * 1024 * 1024
TRIM_THRESHOLD = 128 * 1024 * 1024

_tuned: bool | None = None


def tune_allocator() -> bool:
    """Tune glibc's allocator for large frames (module docstring), once per process.

    Returns
    -------
    bool
        Whether the allocator is tuned (False: not glibc, or ``PLUGCELL_MALLOC=default``).
    """
    global _tuned
    if _tuned is None:
        _tuned = _tune()
    return _tuned


def _tune() -> bool:
    if os.environ.get("PLUGCELL_MALLOC", "").lower() == "default":
        return False
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
        mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
