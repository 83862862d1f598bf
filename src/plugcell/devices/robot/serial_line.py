"""The robot ↔ PC serial line of the thesis's cell, as simulated time (thesis 7.2, 9.3).

The C3G talked to the robot service over RS-232 at 19.2 kbit/s: every ACTIVATE
string a program writes and every answer it gets (data included) takes
``10 bits × characters / baud`` seconds on the line (8 data bits, a start and a stop
bit).  The simulated controller charges that time to its simulated clock, so a
program that forwards tracker data through the robot (the thesis's calibration,
8.2.2) is slower, in simulated time, than one whose data go straight where they are
needed (9.3) — by exactly the characters it no longer carries.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

__all__ = ["BITS_PER_CHARACTER", "THESIS_BAUD", "LineUsage", "SerialLine"]

#: 8N1: a start bit, 8 data bits, a stop bit.
BITS_PER_CHARACTER = 10
#: The C3G's serial line to the PC in the thesis's cell (7.2).
THESIS_BAUD = 19_200.0


@dataclass(frozen=True)
class LineUsage:
    """What crossed the line: characters each way and their time on the line."""

    baud: float
    chars_out: int
    chars_in: int

    @property
    def seconds(self) -> float:
        return (self.chars_out + self.chars_in) * BITS_PER_CHARACTER / self.baud

    def __str__(self) -> str:
        return (f"serial line: {self.chars_out} characters out, {self.chars_in} in, "
                f"{self.seconds:.3f} s at {self.baud:g} bit/s")


class SerialLine:
    """Counts the characters of one program run and prices them in seconds."""

    def __init__(self, baud: float) -> None:
        if not baud > 0:
            raise ValueError(f"the serial line's baud rate must be positive, not {baud}")
        self.baud = float(baud)
        self._lock = threading.Lock()
        self._out = 0
        self._in = 0

    def carry(self, line: str, outbound: bool) -> float:
        """Count ``line`` (and its line end); the seconds it takes on the line."""
        chars = len(line.encode("utf-8")) + 1
        with self._lock:
            if outbound:
                self._out += chars
            else:
                self._in += chars
        return chars * BITS_PER_CHARACTER / self.baud

    def usage(self) -> LineUsage:
        with self._lock:
            return LineUsage(self.baud, self._out, self._in)

    def reset(self) -> None:
        with self._lock:
            self._out = self._in = 0
