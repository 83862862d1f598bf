"""Why a datagram was dropped, and why a stream failed (every vendor's link)."""

from __future__ import annotations

__all__ = [
    "ControllerStoppedError",
    "CorrectionRefusedError",
    "PacketError",
    "SourceFailedError",
    "StreamLinkError",
    "StreamStoppedError",
]


class PacketError(ValueError):
    """A datagram that is no robot packet.

    Parameters
    ----------
    kind : {"malformed", "oversized", "foreign"}
        The counter it is dropped under.
    message : str
        What is wrong with it.
    """

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


class StreamLinkError(RuntimeError):
    """Why a stream failed; ``str(error)`` is the reason for the user."""


class StreamStoppedError(StreamLinkError):
    """The controller went silent, or missed cycles reached its timeout."""


class ControllerStoppedError(StreamLinkError):
    """The controller's own count of late packets (RSI's ``<Delay>``) reached its limit."""


class CorrectionRefusedError(StreamLinkError):
    """A correction beyond the configured limits (policy ``"refuse"``), or not sendable."""


class SourceFailedError(StreamLinkError):
    """The correction source raised; the link holds the robot."""
