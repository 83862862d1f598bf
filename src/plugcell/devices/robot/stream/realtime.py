"""How the cycle loop is scheduled: real-time priority, CPUs, locked memory.

A 4 ms cycle with an answer in well under a millisecond needs the loop to run the
moment its packet arrives.  Three knobs of Linux decide that, and :class:`RealTime` holds
them for a link (:class:`~.link.StreamLink`, the link process of :mod:`.process`, the
robot service's ``stream_rt_priority``/``stream_cpu``/``stream_mlock``, ``plugcell rsi|egm
run``'s ``--rt-priority``/``--cpu``/``--mlock``):

* ``priority`` — ``SCHED_FIFO`` at 1..99 for the link's thread: it preempts every
  ordinary (``SCHED_OTHER``) process the moment its packet arrives (root or
  ``CAP_SYS_NICE``; ``chrt -f N`` does the same from outside);
* ``cpus`` — the CPUs the link may run on (``sched_setaffinity``; ``taskset -c`` from
  outside): one CPU given to the stream, the cell's other services kept off it
  (``isolcpus=`` on the kernel's command line keeps every other process off it);
* ``lock_memory`` — ``mlockall(MCL_CURRENT | MCL_FUTURE)``: no page of the process is
  paged out, so no cycle waits on a page fault served from disk.  Only for a PC that
  swaps: on the shared VM (Linux 6.18, not PREEMPT_RT) a benchmark process under
  ``SCHED_FIFO`` with its memory locked once spun in the kernel for minutes, deaf to
  ``SIGKILL`` (docs/kuka-rsi.md, "The PC's set-up for a 4 ms cycle").

Each is applied where the loop runs (:class:`LoopScheduling`: by the loop's own thread
when it starts — a link's, the twin's robot side's), and a refusal (no privilege, a CPU
that does not exist) is not fatal there: :meth:`RealTime.apply` returns what happened as
a note (the link's :attr:`~.link.StreamLink.rt_note`; a refused priority says why:
:func:`fifo_refused`), so a stream still runs, at normal priority, on a machine that
does not allow it.  Values that can never work (priority 0, a CPU
number that is not one, an empty set) are refused when the options are parsed, with the
reason.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
import threading
from dataclasses import dataclass

__all__ = ["SWITCH_INTERVAL_S", "LoopScheduling", "RealTime", "fifo_refused", "lock_memory",
           "parse_cpus", "pin", "pin_process", "stream_realtime"]

#: The interpreter's switch interval in a link's process (s): a thread that holds it when
#: the link's thread asks for it hands it over within this (Python's default is 5 ms).
SWITCH_INTERVAL_S = 0.0005

#: mlockall(2)'s flags (linux/mman.h, the same on every architecture Linux runs on).
MCL_CURRENT, MCL_FUTURE = 1, 2


def parse_cpus(text: str) -> frozenset[int]:
    """The CPUs of a list as ``taskset -c`` and ``isolcpus=`` write it: ``"1"``,
    ``"0,2"``, ``"2-3"``, ``"0,2-3"``.

    Parameters
    ----------
    text : str
        The list.

    Returns
    -------
    frozenset of int
        The CPU numbers (≥ 0).

    Raises
    ------
    ValueError
        Empty, not numbers, a range running backwards: the reason, naming the part.
    """
    cpus: set[int] = set()
    parts = [p.strip() for p in str(text).split(",")]
    if not any(parts):
        raise ValueError(f"CPU list {text!r}: empty (expected e.g. 1, 0,2 or 2-3)")
    for part in parts:
        first, sep, last = part.partition("-")
        try:
            lo = int(first)
            hi = int(last) if sep else lo
        except ValueError:
            raise ValueError(f"CPU list {text!r}: {part!r} is not a CPU number or a range "
                             "like 2-3") from None
        if lo < 0 or hi < lo:
            raise ValueError(f"CPU list {text!r}: {part!r} is not a range of CPU numbers "
                             "(≥ 0, low-high)")
        cpus.update(range(lo, hi + 1))
    return frozenset(cpus)


def pin(cpus: frozenset[int] | None, pid: int = 0) -> str:
    """Restrict ``pid`` (0: the calling thread) to ``cpus``; what happened, as a note.

    Parameters
    ----------
    cpus : frozenset of int or None
        The CPUs; ``None``: leave the affinity as it is.
    pid : int
        A thread or process id (Linux: a thread's own id pins that thread only).

    Returns
    -------
    str
        ``"CPU 1"``, or why the affinity was not set.
    """
    if cpus is None:
        return ""
    names = ",".join(str(c) for c in sorted(cpus))
    try:
        os.sched_setaffinity(pid, cpus)
    except AttributeError:
        return f"CPUs {names} not set (no sched_setaffinity here)"
    except OSError as exc:  # EINVAL: none of them online
        return f"CPUs {names} refused ({exc.strerror or exc}; online: {_online()})"
    return f"CPU{'s' if len(cpus) > 1 else ''} {names}"


def pin_process(cpus: frozenset[int]) -> str:
    """:func:`pin` every thread of this process (Linux lists them in /proc/self/task;
    elsewhere the calling thread); the note of the calling thread's."""
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        tids = []
    for tid in tids:
        if tid != threading.get_native_id():
            pin(cpus, tid)
    return pin(cpus)


def _online() -> str:
    try:
        return ",".join(str(c) for c in sorted(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return "unknown"


def lock_memory() -> str:
    """``mlockall(MCL_CURRENT | MCL_FUTURE)`` for the calling process; what happened.

    Returns
    -------
    str
        ``"memory locked"``, or why not (no libc, ``EPERM``/``ENOMEM``: the limit
        ``ulimit -l`` or no ``CAP_IPC_LOCK``).
    """
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name, use_errno=True)
        mlockall = libc.mlockall
    except (OSError, AttributeError, TypeError):
        return "memory not locked (no mlockall here)"
    if mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        err = ctypes.get_errno()
        return f"memory not locked ({os.strerror(err)}; see ulimit -l)"
    return "memory locked"


def fifo_refused(exc: BaseException, priority: int) -> str:
    """Why ``SCHED_FIFO`` at ``priority`` was refused, for a note: ``"SCHED_FIFO refused
    (…)"`` — for ``EPERM`` what it needs (root or ``CAP_SYS_NICE``, or ``ulimit -r``)."""
    if isinstance(exc, PermissionError):
        return (f"SCHED_FIFO refused (not permitted: priority {priority} needs root or "
                f"CAP_SYS_NICE, e.g. setcap cap_sys_nice+ep on the Python binary, or "
                f"ulimit -r {priority} or more; {exc})")
    if isinstance(exc, AttributeError):
        return "SCHED_FIFO refused (no sched_setscheduler here: Linux only)"
    return f"SCHED_FIFO refused ({exc})"


@dataclass(frozen=True)
class RealTime:
    """The scheduling of a link's cycle loop (module doc).

    Attributes
    ----------
    priority : int or None
        ``SCHED_FIFO`` priority 1..99 of the link's thread; ``None``: normal scheduling.
    cpus : frozenset of int or None
        The CPUs the loop may run on; ``None``: any.
    lock_memory : bool
        Lock the process's memory (``mlockall``).

    Raises
    ------
    ValueError
        A priority outside 1..99, an empty or negative CPU set: the reason.
    """

    priority: int | None = None
    cpus: frozenset[int] | None = None
    lock_memory: bool = False

    def __post_init__(self) -> None:
        if self.priority is not None and (isinstance(self.priority, bool)
                                          or not isinstance(self.priority, int)
                                          or not 1 <= self.priority <= 99):
            raise ValueError(f"rt_priority {self.priority!r}: expected 1..99 (SCHED_FIFO)")
        if self.cpus is not None:
            if not self.cpus:
                raise ValueError("the link's CPUs: an empty set (give at least one CPU)")
            bad = [c for c in self.cpus if isinstance(c, bool) or not isinstance(c, int)
                   or c < 0]
            if bad:
                raise ValueError(f"the link's CPUs: {bad[0]!r} is not a CPU number (≥ 0)")
            object.__setattr__(self, "cpus", frozenset(self.cpus))

    @classmethod
    def given(cls, priority: int | None, realtime: RealTime | None) -> RealTime:
        """A link's ``realtime`` option, or one of its older ``rt_priority`` alone;
        ``ValueError`` when both are given."""
        if realtime is None:
            return cls(priority=priority)
        if priority is not None:
            raise ValueError("give rt_priority or realtime, not both")
        return realtime

    @property
    def asked(self) -> bool:
        """Anything other than the defaults was asked for."""
        return self.priority is not None or self.cpus is not None or self.lock_memory

    def prepare_process(self) -> str:
        """Called by the main thread of a process that runs a link, before any other
        thread starts: every thread of the process on :attr:`cpus` (they inherit it), the
        switch interval :data:`SWITCH_INTERVAL_S`, and — with a :attr:`priority` — the
        process's other threads under ``SCHED_FIFO`` one below the link's.

        The link's thread shares the interpreter (the GIL) with them, and the GIL knows no
        priorities: a thread holding it while an ordinary process has its CPU would hold
        up the link's thread until the scheduler gives that CPU back — milliseconds on a
        loaded machine (measured: a 5.6 ms answer when the benchmark's link process read
        a line at the start of its run).  One real-time priority below the link's, such a
        thread runs until it lets go of the interpreter, the link's thread still
        preempting it.  What happened, as a note.
        """
        if not self.asked:  # the defaults: the process as Python starts it
            return ""
        notes = [pin_process(self.cpus)] if self.cpus is not None else []
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        if self.priority is not None:
            below = max(1, self.priority - 1)
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(below))
            except (AttributeError, OSError) as exc:
                notes.append(f"other threads at normal priority ({fifo_refused(exc, below)})")
            else:
                notes.append(f"other threads SCHED_FIFO priority {below}")
        return ", ".join(n for n in notes if n)

    def apply(self) -> str:
        """Apply to the calling thread (priority, CPUs) and process (memory); a note of
        what happened, e.g. ``"SCHED_FIFO priority 20, CPU 1, memory locked"``."""
        notes = [pin(self.cpus)] if self.cpus is not None else []
        if self.lock_memory:
            notes.append(lock_memory())
        if self.priority is not None:
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.priority))
            except (AttributeError, OSError) as exc:  # not Linux, or no CAP_SYS_NICE
                notes.insert(0, f"{fifo_refused(exc, self.priority)}; normal priority")
            else:
                notes.insert(0, f"SCHED_FIFO priority {self.priority}")
        else:
            notes.insert(0, "normal priority")
        return ", ".join(n for n in notes if n)


class LoopScheduling:
    """A cycle loop's scheduling: :class:`RealTime`, applied by the loop's own thread when
    it starts (:meth:`apply_here`), and what happened (:meth:`wait` returns the note) — a
    link's (:class:`~.link.StreamLink`), the twin's robot side's (``plugcell twin
    rsi|egm``'s ``--rt-priority``/``--cpu``/``--mlock``).

    Parameters
    ----------
    realtime : RealTime, optional
        What to apply (default: nothing, normal scheduling).
    """

    def __init__(self, realtime: RealTime | None = None) -> None:
        self.realtime = realtime if realtime is not None else RealTime()
        self.note = "normal priority"
        self._applied = threading.Event()

    def apply_here(self) -> None:
        """Apply it to the calling thread (the loop's, first thing) and its process."""
        if self.realtime.asked:
            self.note = self.realtime.apply()
        self._applied.set()

    def wait(self, timeout: float = 5.0) -> str:
        """The note once the loop's thread applied it (at most ``timeout`` s)."""
        self._applied.wait(timeout)
        return self.note


def stream_realtime(priority: int | None, cpus: str, lock: bool) -> RealTime:
    """The link's scheduling the robot service's options ``stream_rt_priority``,
    ``stream_cpu`` and ``stream_mlock`` give (:func:`~..streamed.streamed_link`; ``plugcell
    rsi|egm run``'s ``--rt-priority``, ``--cpu``, ``--mlock`` too).

    Parameters
    ----------
    priority : int or None
        ``SCHED_FIFO`` priority 1..99.
    cpus : str
        A CPU list (:func:`parse_cpus`); empty: any CPU.
    lock : bool
        Lock the memory.

    Returns
    -------
    RealTime
        The scheduling.

    Raises
    ------
    ValueError
        A priority outside 1..99, a malformed CPU list or one naming a CPU this machine
        does not have: the option and the reason.
    """
    try:
        given = parse_cpus(cpus) if cpus else None
    except ValueError as exc:
        raise ValueError(f"stream_cpu: {exc}") from None
    try:
        realtime = RealTime(priority, given, lock)
    except ValueError as exc:
        raise ValueError(f"stream_rt_priority: {exc}") from None
    count = os.cpu_count()
    if given is not None and count and max(given) >= count:
        # this machine's, not this process's: a service kept on CPU 0 (taskset,
        # systemd's CPUAffinity) may put its link process on CPU 1
        raise ValueError(f"stream_cpu {cpus!r}: CPU {max(given)} is not one of this "
                         f"machine's (0-{count - 1})")
    return realtime
