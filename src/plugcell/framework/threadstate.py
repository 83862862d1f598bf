"""Python thread states that live as long as Zenoh's threads.

Zenoh calls plugcell's callbacks on its own threads, which Python did not create.
Each call takes the GIL with ``PyGILState_Ensure`` and gives it back with
``PyGILState_Release`` (eclipse-zenoh's bindings, through PyO3).  On such a thread the
release that brings the thread state's nesting count back to zero destroys the thread
state the ensure created, so every sample creates and destroys one — with its
16 KiB frame stack, mapped and unmapped again each time (``strace -f -k`` on a
service: one ``mmap``/``munmap`` pair per round trip, from
``_PyThreadState_BumpFramePointerSlow``), and the unmapping interrupts the process's
other threads on the other cores.

CPython documents the remedy (C API, "Non-Python created threads": reusing a thread
state across repeated calls, gh-146219): keep one outer ``PyGILState_Ensure``
outstanding for the thread's lifetime, so that the callbacks' own ensure/release pairs
nest inside it and never bring the count to zero.  :func:`pin` takes that outer ensure,
once per thread, from inside a callback (where the GIL is held).  On a thread Python
created it changes nothing (Python deletes such a thread's state when the thread ends,
whatever the count).  Zenoh's runtime threads last as long as the process; should a
foreign thread end, its pinned state stays allocated, so at most :data:`MAX_PINNED`
threads are pinned.  What it saves is measured by ``benchmarks/round_trip_cpu.py``
(docs/results/framework-performance.md).
"""

from __future__ import annotations

import ctypes
import threading

#: The most thread states :func:`pin` keeps (a bound on what threads that end can leak).
MAX_PINNED = 256

_ensure = ctypes.pythonapi.PyGILState_Ensure
_ensure.restype = ctypes.c_int
_ensure.argtypes = ()
_seen = threading.local()  # lives in the thread state: set once it is pinned
_lock = threading.Lock()
_pinned = 0


def pin() -> None:
    """Keep the calling thread's Python thread state until the thread ends (module doc).

    Call it with the GIL held, as every Python callback runs; cheap after the first call
    on a thread (a thread-local attribute).
    """
    global _pinned
    if getattr(_seen, "pinned", False):
        return
    with _lock:
        if _pinned >= MAX_PINNED:
            return
        _pinned += 1
    _ensure()  # never released: the count stays above zero while the thread lives
    _seen.pinned = True


def pinned() -> int:
    """How many threads :func:`pin` has pinned in this process."""
    return _pinned
