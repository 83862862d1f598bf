"""ABB EGM (Externally Guided Motion), plugcell as the sensor: ``EgmRobot`` in,
``EgmSensor`` out, every 4 ms.

* :mod:`.config` — :class:`EgmConfig`, the one validated value of a stream;
* :mod:`.messages` — ABB's ``egm.proto`` compiled by protobuf (from the
  ``abb-robot-client`` package): ``EgmRobot`` → :class:`EgmState` (SI), the answers;
* :mod:`.link` — :class:`EgmLink`: EGM's codec on the shared cycle loop
  (:mod:`..stream`: limits, correction sources, sessions, counters and failures);
* :mod:`.controller_files` — the RAPID module and the UDP unit device configuration the
  user loads into the controller (``plugcell egm files``).

docs/abb-egm.md takes a user from an empty controller to plugcell streaming to it.
"""

from ..stream import (
    Correction,
    CorrectionLimits,
    CorrectionRefusedError,
    CycleState,
    LinkStats,
    SourceFailedError,
    StreamStoppedError,
    default_limits,
)
from .config import EgmConfig, EgmConfigError
from .link import EgmLink, EgmLinkError
from .messages import EgmState, parse_egm_robot

__all__ = [
    "Correction",
    "CorrectionLimits",
    "CorrectionRefusedError",
    "CycleState",
    "EgmConfig",
    "EgmConfigError",
    "EgmLink",
    "EgmLinkError",
    "EgmState",
    "LinkStats",
    "SourceFailedError",
    "StreamStoppedError",
    "default_limits",
    "parse_egm_robot",
]
