"""The PC drives a KUKA robot over RSI: :class:`RsiDrive`, the streaming drive
(:class:`~..stream.drive.StreamDrive`, every vendor's) on an
:class:`~.link.RsiLink` configured for absolute joint corrections."""

from ..stream.drive import IN_POSITION_RAD, SETTLE_S
from ..stream.drive import StreamDrive as RsiDrive

__all__ = ["IN_POSITION_RAD", "SETTLE_S", "RsiDrive"]
