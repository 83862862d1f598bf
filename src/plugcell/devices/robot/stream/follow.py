"""Watching a link's session, waiting on it, and one motion streamed to its end
(:class:`Following`)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from .errors import StreamLinkError, StreamStoppedError
from .source import Correction, CycleState, SourceLike, as_source

__all__ = ["Following"]


class Following:
    """What a robot service does with a link: watch its session (streaming, failure), wait
    on it, and stream one motion.

    Mixed into :class:`~.link.StreamLink`, which keeps ``_cond`` (notified at every cycle
    and session event), ``_failure``, ``_last_failure``, ``_streaming`` and
    :meth:`set_source`.
    """

    _cond: threading.Condition
    _closing: bool
    config: Any
    _failure: StreamLinkError | None
    _last_failure: StreamLinkError | None
    _streaming: bool

    @property
    def failure(self) -> StreamLinkError | None:
        """Why the current or last session failed (``None``: it did not)."""
        return self._failure

    @property
    def last_failure(self) -> StreamLinkError | None:
        """The failure of the latest session that failed (kept across sessions)."""
        return self._last_failure

    @property
    def streaming(self) -> bool:
        """A session is running."""
        return self._streaming

    def set_source(self, source: SourceLike | None) -> None:  # the link has it
        raise NotImplementedError

    def wait(self, predicate: Callable[[Any], bool], timeout: float) -> bool:
        """Wait until ``predicate(link)`` holds (checked at each session event and cycle).

        Parameters
        ----------
        predicate : callable
            Tested on this link.
        timeout : float
            Seconds at most.

        Returns
        -------
        bool
            Whether it holds.
        """
        with self._cond:
            return self._cond.wait_for(lambda: predicate(self), timeout)

    def check(self) -> None:
        """Raise the session's failure, if any."""
        if self._failure is not None:
            raise self._failure

    def follow(self, source: SourceLike, done: Callable[[CycleState], bool],
               timeout: float) -> CycleState:
        """Stream ``source`` until ``done(state)`` holds, then hold the robot: one motion
        as a robot service runs it, ending in a result or in the stream's failure.

        Parameters
        ----------
        source : CorrectionSource or callable
            The motion's corrections.
        done : callable
            Tested on each cycle's state after ``source`` answered it; the cycle where it
            first holds is the motion's last (its correction is sent).
        timeout : float
            Seconds the motion may take on the controller's clock (its cycles, ``T``
            each: a controller whose cycles come slower than real time — on a loaded
            machine — takes longer in wall time), and on the wall clock while no cycle
            of the motion comes (waiting for the controller's stream; once it streams,
            its silence fails the session after one controller timeout).

        Returns
        -------
        CycleState
            The state of the last cycle.

        Raises
        ------
        StreamLinkError
            The stream failed (before or during the motion): its reason, as a
            :class:`StreamStoppedError`, :class:`CorrectionRefusedError` … — a robot
            service turns it into a failed process; :class:`StreamStoppedError` too when
            the link is closed during the motion.
        TimeoutError
            ``done`` did not hold within ``timeout`` seconds.
        """
        self.check()  # a held session is over: the controller has to start a new one
        ask = as_source(source)
        finished: list[CycleState] = []
        cycles = [0]  # of the motion, on the controller's clock
        last = timeout / self.config.cycle_s

        def motion(state: CycleState) -> Correction | None:
            if finished or cycles[0] > last:
                return None  # the motion is over (or out of time): hold
            cycles[0] += 1
            corr = ask(state)
            if done(state):
                finished.append(state)
            return corr

        def over(link: Any) -> bool:
            return (bool(finished) or link.failure is not None or cycles[0] > last
                    or self._closing)

        self.set_source(motion)
        try:
            seen = 0
            while not self.wait(over, timeout) and cycles[0] != seen:
                seen = cycles[0]  # the controller's cycles still come: its clock counts
            if self._failure is not None:
                raise self._failure
            if not finished and self._closing:
                raise StreamStoppedError(f"{self.config.vendor} link closed")
            if not finished:
                where = "streaming" if self._streaming else "no stream from the controller"
                raise TimeoutError(f"the motion did not end within {timeout:g} s ({where})")
            return finished[0]
        finally:
            self.set_source(None)  # the motion is over, however it ended: hold

    async def follow_async(self, source: SourceLike, done: Callable[[CycleState], bool],
                           timeout: float) -> CycleState:
        """:meth:`follow` without blocking an event loop (it waits in a worker thread).

        Parameters
        ----------
        source, done, timeout
            As :meth:`follow`.

        Returns
        -------
        CycleState
            As :meth:`follow`.
        """
        import asyncio

        return await asyncio.to_thread(self.follow, source, done, timeout)
