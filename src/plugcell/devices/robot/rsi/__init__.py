"""KUKA RSI, plugcell as the sensor: the robot's state in, corrections out, every 4 ms.

* :mod:`.config` — :class:`RsiConfig`, the one validated value of a stream;
* :mod:`.codec` — ``<Rob>`` packets → :class:`RobotState` (SI), ``<Sen>`` answers;
* :mod:`.link` — :class:`RsiLink`, the UDP loop (:mod:`..stream`: every vendor's cycle
  loop, limits, correction sources — :class:`PathOffset` superimposes an offset on the
  robot's own path — counters and failures);
* :mod:`.controller_files` — the KRL program, ethernet configuration and RSI diagram
  the user copies to the controller (``plugcell rsi files``).

docs/kuka-rsi.md takes a user from an empty controller to plugcell streaming to it.
"""

from ..stream.source import Hold, PathOffset, SineOffset
from .codec import PacketError, RobotState, encode_sen, parse_rob
from .config import (
    CYCLES,
    CorrectionLimits,
    OutputSignal,
    RsiConfig,
    RsiConfigError,
    default_limits,
)
from .link import (
    ControllerStoppedError,
    Correction,
    CorrectionRefusedError,
    CorrectionSource,
    CycleState,
    LinkStats,
    RsiLink,
    RsiLinkError,
    SourceFailedError,
    StreamStoppedError,
)

__all__ = [
    "CYCLES",
    "ControllerStoppedError",
    "Correction",
    "CorrectionLimits",
    "CorrectionRefusedError",
    "CorrectionSource",
    "CycleState",
    "Hold",
    "LinkStats",
    "OutputSignal",
    "PacketError",
    "PathOffset",
    "RobotState",
    "RsiConfig",
    "RsiConfigError",
    "RsiLink",
    "RsiLinkError",
    "SineOffset",
    "SourceFailedError",
    "StreamStoppedError",
    "default_limits",
    "encode_sen",
    "parse_rob",
]
