"""Bytes ↔ lines of the controller protocol (docs/controller-protocol.md §1).

One message per line, UTF-8, ended by LF (CR LF accepted), at most
:data:`MAX_LINE_BYTES`.  :class:`LineBuffer` cuts a byte stream into lines and
turns what cannot be a line — too long, not UTF-8 — into a precise
:class:`FramingError` item instead of losing its place in the stream: after a
line that is too long it skips to the next LF and carries on.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MAX_LINE_BYTES", "FramingError", "LineBuffer", "frame_line"]

#: Longest line (a DATA line of 4096 doubles is about 100 kB).
MAX_LINE_BYTES = 1 << 20


@dataclass(frozen=True)
class FramingError:
    """A line that could not be read (an item of :meth:`LineBuffer.feed`, not raised)."""

    reason: str


class LineBuffer:
    """Feed bytes, get complete lines (``str``) or :class:`FramingError` items."""

    def __init__(self, max_bytes: int = MAX_LINE_BYTES) -> None:
        self.max_bytes = max_bytes
        self._buf = bytearray()
        self._skipping = False

    def feed(self, chunk: bytes) -> list[str | FramingError]:
        out: list[str | FramingError] = []
        self._buf.extend(chunk)
        while True:
            nl = self._buf.find(b"\n")
            if nl < 0:
                if len(self._buf) > self.max_bytes:
                    if not self._skipping:
                        out.append(FramingError(f"line longer than {self.max_bytes} bytes"))
                    self._skipping = True
                    self._buf.clear()
                return out
            raw = bytes(self._buf[:nl])
            del self._buf[: nl + 1]
            if self._skipping:  # the tail of a line already reported as too long
                self._skipping = False
                continue
            if len(raw) > self.max_bytes:
                out.append(FramingError(f"line longer than {self.max_bytes} bytes"))
                continue
            if raw.endswith(b"\r"):
                raw = raw[:-1]
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                out.append(FramingError(f"line is not valid UTF-8 (byte {exc.start + 1})"))
                continue
            if text.strip():
                out.append(text)

    @property
    def pending(self) -> int:
        """Bytes of an unfinished line."""
        return len(self._buf)


def frame_line(line: str) -> bytes:
    """The bytes of one message: UTF-8 and a LF.  ValueError if ``line`` holds a line break."""
    if "\n" in line or "\r" in line:
        raise ValueError("a protocol line cannot contain a line break")
    return line.encode("utf-8") + b"\n"
