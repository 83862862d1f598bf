"""A small progress line for long CLI work (stderr, rewritten in place on a TTY)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """Callable ``(done, total)`` printing ``label  done/total  pct  elapsed`` to ``stream``.

    On a terminal the line is rewritten in place; elsewhere (CI logs, pipes) only
    every 10 % and the end are printed, so logs stay short.
    """

    def __init__(self, label: str, stream: TextIO | None = None) -> None:
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.start = time.monotonic()
        self._last_decile = -1
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def __call__(self, done: int, total: int) -> None:
        pct = 100.0 * done / max(total, 1)
        line = f"{self.label}  {done}/{total}  {pct:5.1f} %  {time.monotonic() - self.start:6.1f} s"
        if self._tty:
            end = "\n" if done >= total else ""
            self.stream.write("\r" + line + end)
            self.stream.flush()
            return
        decile = int(pct // 10)
        if decile != self._last_decile or done >= total:
            self._last_decile = decile
            self.stream.write(line + "\n")
            self.stream.flush()
