"""What a vendor's real-time streaming interface needs, whatever the vendor.

KUKA RSI (:mod:`..rsi`) and ABB EGM (:mod:`..egm`) both send the robot's state over UDP
every cycle (4 ms) and expect the sensor's answer within it.  Everything that does not
depend on the packets' format lives here, once:

* :mod:`.config` — :class:`StreamConfigError` and the checks of addresses, ports, axes;
* :mod:`.limits` — :class:`CorrectionLimits` and the :class:`OffsetLimiter` every
  correction passes (per-cycle step, speed, total offset; clamp or refuse);
* :mod:`.source` — :class:`Correction`, :class:`CycleState`, the
  :class:`CorrectionSource` interface and two first-contact sources;
* :mod:`.errors` — why a packet was dropped (:class:`PacketError`) and why a stream failed;
* :mod:`.link` — :class:`StreamLink`, the UDP cycle loop with its sessions, counters and
  failures; a vendor's link gives it the codec.
"""

from .config import StreamConfigError
from .errors import (
    ControllerStoppedError,
    CorrectionRefusedError,
    PacketError,
    SourceFailedError,
    StreamLinkError,
    StreamStoppedError,
)
from .limits import CorrectionLimits, Limited, OffsetLimiter, default_limits
from .link import LinkStats, StreamLink
from .source import Correction, CorrectionSource, CycleState, Hold, SineOffset

__all__ = [
    "ControllerStoppedError",
    "Correction",
    "CorrectionLimits",
    "CorrectionRefusedError",
    "CorrectionSource",
    "CycleState",
    "Hold",
    "Limited",
    "LinkStats",
    "OffsetLimiter",
    "PacketError",
    "SineOffset",
    "SourceFailedError",
    "StreamConfigError",
    "StreamLink",
    "StreamLinkError",
    "StreamStoppedError",
    "default_limits",
]
