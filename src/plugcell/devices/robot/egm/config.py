"""The EGM link's configuration: one validated value.

Where the sensor side listens, which controller may talk to it, what it sends — joint
targets (``EGMRunJoint``), pose targets (``EGMRunPose``) or path corrections
(``EGMMoveL``) — the controller's sample rate and communication timeout, and the limits
every target is held to, as one frozen :class:`EgmConfig`, checked when it is made: a
wrong value raises :class:`~..stream.config.StreamConfigError` naming the field and why.

Units are SI inside (m, rad, s); the controller's mm, degrees and quaternions only at the
message boundary (:mod:`.messages`) and in the controller files
(:mod:`.controller_files`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..stream.config import StreamConfigError, check_host, check_port
from ..stream.limits import CorrectionLimits, default_limits

__all__ = ["EgmConfig", "EgmConfigError", "Mode"]

Mode = Literal["joint", "pose", "pathcorr"]

#: A configuration that cannot be used: the one error of every streaming interface.
EgmConfigError = StreamConfigError


@dataclass(frozen=True)
class EgmConfig:
    """One EGM stream, sensor side.

    Attributes
    ----------
    robot_host : str
        The controller's address; datagrams from any other host are dropped and counted.
    listen_host, listen_port : str, int
        Where the link receives ``EgmRobot``: the remote address and port of the
        controller's UDP unit device (``UDPUC``); port 0: any free port (tests).
    robot_port : int or None
        The controller's source port, if fixed; ``None`` accepts any.
    mode : {"joint", "pose", "pathcorr"}
        What the answers carry.  ``joint``: joint targets, the robot's joints at the
        stream's start plus the commanded offset (A1..A6, rad); ``pose``: the TCP pose
        at the start moved by the offset ``(Δx, Δy, Δz, ω)`` — a translation (m) and a
        rotation vector ``ω`` (rad) applied in the work object's frame,
        ``R = exp([ω]×) R₀``; ``pathcorr``: the offset's x, y, z (m) as a path
        correction (its rotations must stay zero).
    sample_rate_ms : int
        ``\\SampleRate`` of ``EGMActJoint``/``EGMActPose``/``EGMActMove``: the cycle
        (ms, a multiple of 4).
    comm_timeout_s : float
        ``\\CommTimeout`` of ``EGMSetupUC``: the controller stops EGM after this long
        without a message; so does the link, and as many missed cycles in a row fail
        the stream.
    limits : CorrectionLimits
        What the offset may do (:func:`~..stream.limits.default_limits` of the mode if
        not given: joint limits for ``joint``, Cartesian for ``pose`` and ``pathcorr``).
    path_age_ms : int
        ``pathCorr.age`` sent with path corrections (ms).
    max_packet_bytes : int
        Larger datagrams are dropped as oversized (an EgmRobot is ~ 200-400 bytes).
    """

    robot_host: str
    listen_host: str = "0.0.0.0"
    listen_port: int = 6510
    robot_port: int | None = None
    mode: Mode = "joint"
    sample_rate_ms: int = 4
    comm_timeout_s: float = 1.0
    limits: CorrectionLimits | None = None
    path_age_ms: int = 1
    max_packet_bytes: int = 1400

    def __post_init__(self) -> None:
        check_host("robot_host", self.robot_host)
        check_host("listen_host", self.listen_host)
        check_port("listen_port", self.listen_port, allow_zero=True)
        if self.robot_port is not None:
            check_port("robot_port", self.robot_port, allow_zero=False)
        if self.mode not in ("joint", "pose", "pathcorr"):
            raise EgmConfigError(f"mode {self.mode!r}: expected 'joint', 'pose' or "
                                 "'pathcorr'")
        if isinstance(self.sample_rate_ms, bool) or not isinstance(self.sample_rate_ms, int) \
                or self.sample_rate_ms < 4 or self.sample_rate_ms % 4:
            raise EgmConfigError(f"sample_rate_ms {self.sample_rate_ms!r}: expected a "
                                 "multiple of 4 ms (EGM's \\SampleRate)")
        t = self.comm_timeout_s
        if not isinstance(t, int | float) or not math.isfinite(t) or \
                not 5 * self.sample_rate_ms / 1000 <= t <= 60:
            raise EgmConfigError(f"comm_timeout_s {t!r}: expected {5 * self.sample_rate_ms} "
                                 "ms .. 60 s (EGMSetupUC's \\CommTimeout)")
        if self.limits is None:
            object.__setattr__(self, "limits", default_limits(
                "joint" if self.mode == "joint" else "cartesian"))
        elif not isinstance(self.limits, CorrectionLimits):
            raise EgmConfigError("limits: expected a CorrectionLimits")
        if isinstance(self.path_age_ms, bool) or not isinstance(self.path_age_ms, int) \
                or not 0 <= self.path_age_ms <= 10_000:
            raise EgmConfigError(f"path_age_ms {self.path_age_ms!r}: expected 0..10000")
        if not 128 <= self.max_packet_bytes <= 65507:
            raise EgmConfigError(f"max_packet_bytes {self.max_packet_bytes}: expected "
                                 "128..65507")

    @property
    def cycle_s(self) -> float:
        """The cycle ``T`` (s)."""
        return self.sample_rate_ms / 1000

    @property
    def vendor(self) -> str:
        """The interface's name in messages."""
        return "EGM"

    @property
    def joint_targets(self) -> bool:
        """Each answer carries the whole joint command (``EGMRunJoint``): what the PC needs
        to drive the robot along a planned trajectory."""
        return self.mode == "joint"

    @property
    def timeout_s(self) -> float:
        """One controller timeout (s): silence this long stops the stream."""
        return float(self.comm_timeout_s)

    @property
    def timeout_packets(self) -> int:
        """Cycles in one controller timeout: this many missed in a row fail the stream."""
        return max(1, round(self.comm_timeout_s / self.cycle_s))
