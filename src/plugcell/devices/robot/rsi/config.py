"""The RSI link's configuration: one validated value.

Everything the sensor side needs to know about one RSI stream — where it listens, which
robot may talk to it, which correction it sends (joint ``AKorr`` or Cartesian ``RKorr``,
relative or absolute), the controller's cycle and ``Timeout``, the limits every
correction is held to, and the digital I/O words routed through RSI — is one frozen
:class:`RsiConfig`, checked when it is made: a wrong value raises :class:`RsiConfigError`
naming the field and why, so a link never starts half-configured.

Units are SI inside (m, rad, s).  The controller's files speak mm and degrees; the
conversion happens only at the packet boundary (:mod:`.codec`) and in the controller
files (:mod:`.controller_files`), through :mod:`plugcell.io.units`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Literal

from ..stream.config import StreamConfigError, check_host, check_port
from ..stream.limits import CorrectionLimits, default_limits

__all__ = [
    "CYCLES",
    "CorrectionLimits",
    "OutputSignal",
    "RsiConfig",
    "RsiConfigError",
    "default_limits",
]

#: The controller's RSI cycles (``RSI_ON(…, #IPO_FAST)`` / ``#IPO``), in seconds.
CYCLES = {"IPO_FAST": 0.004, "IPO": 0.012}

Kind = Literal["joint", "cartesian"]
Mode = Literal["relative", "absolute"]
Frame = Literal["base", "tool"]
Policy = Literal["clamp", "refuse"]

#: An XML name as RSI's ethernet configuration accepts it for a RECEIVE tag.
_TAG = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,31}$")


#: A configuration that cannot be used: the one error of every streaming interface.
RsiConfigError = StreamConfigError


@dataclass(frozen=True)
class OutputSignal:
    """A value the sensor writes through RSI every cycle (a digital output word, …).

    Attributes
    ----------
    tag : str
        The RECEIVE tag of the ethernet configuration (``DiO`` → ``<DiO>5</DiO>``).
    bits : int
        Width of the word, 1..32; a value must be an integer in ``[0, 2**bits)``.
    initial : int
        Sent until a correction source sets it.
    """

    tag: str
    bits: int = 16
    initial: int = 0

    def __post_init__(self) -> None:
        if not _TAG.match(self.tag) or self.tag in ("IPOC", "AKorr", "RKorr"):
            raise RsiConfigError(f"output tag {self.tag!r}: not a free RSI tag name")
        if not 1 <= int(self.bits) <= 32:
            raise RsiConfigError(f"output {self.tag}: bits {self.bits} not in 1..32")
        self.check(self.initial)

    def check(self, value: object) -> int:
        """``value`` as the integer sent, or :class:`ValueError` naming the signal."""
        if isinstance(value, bool):
            value = int(value)
        if not isinstance(value, int) or not 0 <= value < (1 << self.bits):
            raise ValueError(f"output {self.tag} = {value!r}: expected an integer in "
                             f"[0, {1 << self.bits}) ({self.bits} bits)")
        return value


def _check_host(what: str, host: str) -> str:
    return check_host(what, host, "RSI's IP_NUMBER is numeric")


@dataclass(frozen=True)
class RsiConfig:
    """One RSI stream, sensor side.

    Attributes
    ----------
    listen_host, listen_port : str, int
        Where the link receives the robot's ``<Rob>`` packets: the ``IP_NUMBER`` and
        ``PORT`` of the controller's ethernet configuration (port 0: any free port, for
        tests).
    robot_host : str
        The controller's address; packets from any other host are dropped and counted.
    robot_port : int or None
        The controller's source port, if fixed; ``None`` accepts any port of
        ``robot_host`` (the controller sends from a port of its choosing).
    correction : {"joint", "cartesian"}
        ``AKorr A1..A6`` (AXISCORR) or ``RKorr X Y Z A B C`` (POSCORR).
    mode : {"relative", "absolute"}
        ``RSI_ON(#RELATIVE)``: each packet carries the step of this cycle;
        ``#ABSOLUTE``: each packet carries the whole offset from the start.
    frame : {"base", "tool"}
        The frame a Cartesian correction is expressed in (POSCORR's ``RefCorrSys``):
        ``"base"`` — X, Y, Z along the base frame's axes, A, B, C rotating about them;
        ``"tool"`` — along and about the axes of the TCP of the robot's path.  Unused for
        joint corrections.
    cycle : {"IPO_FAST", "IPO"}
        The controller's cycle: 4 ms or 12 ms (:data:`CYCLES`).
    timeout_packets : int
        The ETHERNET object's ``Timeout``: after this many missed cycles in a row the
        controller breaks off, and so does the link; silence for this many cycles is a
        stopped stream.
    limits : CorrectionLimits
        The limits every correction is held to (:func:`default_limits` if not given).
    sentype : str
        ``SENTYPE`` of the ethernet configuration (``<Sen Type="…">``).
    outputs : tuple of OutputSignal
        The words the sensor writes (digital outputs, a STOP flag …).
    max_packet_bytes : int
        Larger datagrams are dropped as oversized.
    """

    robot_host: str
    listen_host: str = "0.0.0.0"
    listen_port: int = 49152
    robot_port: int | None = None
    correction: Kind = "joint"
    mode: Mode = "relative"
    frame: Frame = "base"
    cycle: Literal["IPO_FAST", "IPO"] = "IPO_FAST"
    timeout_packets: int = 100
    limits: CorrectionLimits | None = None
    sentype: str = "ImFree"
    outputs: tuple[OutputSignal, ...] = field(default_factory=tuple)
    max_packet_bytes: int = 4096

    def __post_init__(self) -> None:
        _check_host("robot_host", self.robot_host)
        _check_host("listen_host", self.listen_host)
        check_port("listen_port", self.listen_port, allow_zero=True)
        if self.robot_port is not None:
            check_port("robot_port", self.robot_port, allow_zero=False)
        if self.correction not in ("joint", "cartesian"):
            raise RsiConfigError(f"correction {self.correction!r}: expected 'joint' or "
                                 "'cartesian'")
        if self.mode not in ("relative", "absolute"):
            raise RsiConfigError(f"mode {self.mode!r}: expected 'relative' or 'absolute'")
        if self.frame not in ("base", "tool"):
            raise RsiConfigError(f"frame {self.frame!r}: expected 'base' or 'tool'")
        if self.cycle not in CYCLES:
            raise RsiConfigError(f"cycle {self.cycle!r}: expected one of {sorted(CYCLES)}")
        if isinstance(self.timeout_packets, bool) or not isinstance(self.timeout_packets, int) \
                or not 1 <= self.timeout_packets <= 10000:
            raise RsiConfigError(f"timeout_packets {self.timeout_packets!r}: expected an "
                                 "integer 1..10000 (the ETHERNET object's Timeout)")
        if self.limits is None:
            object.__setattr__(self, "limits", default_limits(self.correction))
        elif not isinstance(self.limits, CorrectionLimits):
            raise RsiConfigError("limits: expected a CorrectionLimits")
        if not _TAG.match(self.sentype):
            raise RsiConfigError(f"sentype {self.sentype!r}: expected an XML name")
        outs = tuple(self.outputs)
        tags = [o.tag for o in outs]
        if len(set(tags)) != len(tags):
            raise RsiConfigError(f"outputs: a tag is listed twice in {tags}")
        object.__setattr__(self, "outputs", outs)
        if not 256 <= self.max_packet_bytes <= 65507:
            raise RsiConfigError(f"max_packet_bytes {self.max_packet_bytes}: expected "
                                 "256..65507")

    @property
    def cycle_s(self) -> float:
        """The cycle ``T`` in seconds."""
        return CYCLES[self.cycle]

    @property
    def vendor(self) -> str:
        """The interface's name in messages."""
        return "RSI"

    @property
    def joint_targets(self) -> bool:
        """Each answer carries the whole joint command (absolute ``AKorr``): what the PC
        needs to drive the robot along a planned trajectory."""
        return self.correction == "joint" and self.mode == "absolute"

    @property
    def ipoc_step(self) -> int:
        """IPOC advance per cycle: the controller's IPOC counts milliseconds."""
        return round(self.cycle_s * 1000)

    @property
    def timeout_s(self) -> float:
        """One controller timeout, ``Timeout · T`` (s): silence this long stops the stream."""
        return self.timeout_packets * self.cycle_s
