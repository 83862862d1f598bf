"""Hold every correction to the configured limits before it leaves.

The link keeps the offset it has commanded since the stream started, ``o_k`` (SI, six
axes).  A correction source asks for a new offset ``o*`` (or a step ``s* = o* − o_k``);
the limiter computes what may be sent:

    s_i = clip(o*_i − o_k,i, −b_i, b_i),   b_i = min(max_step_i, max_speed_i · T)
    o_k+1,i = clip(o_k,i + s_i, −max_offset_i, max_offset_i)

and answers the step ``o_k+1 − o_k`` (relative mode) or the offset ``o_k+1`` (absolute
mode).  With the ``"clamp"`` policy a cut correction is sent cut, and the reason is
returned; with ``"refuse"`` nothing beyond the limits is sent: the answer holds the robot
(step 0, the offset kept) and the reason is returned for the link to fail the stream.
A non-finite request is always refused.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from plugcell.io.units import DEG, M_PER_MM

from .config import StreamConfigError, six_values

Array = NDArray[np.float64]

__all__ = ["CorrectionLimits", "Limited", "OffsetLimiter", "default_limits"]

Kind = Literal["joint", "cartesian"]
Policy = Literal["clamp", "refuse"]


@dataclass(frozen=True)
class CorrectionLimits:
    """What a correction may do, per axis, in SI.

    For joint corrections the six axes are the joints (rad); for Cartesian corrections
    X, Y, Z (m) then three rotations (rad: KUKA's A, B, C; EGM's rotation vector).

    Attributes
    ----------
    max_step : tuple of 6 float
        Largest change of the offset in one cycle (rad or m per cycle).
    max_offset : tuple of 6 float
        Largest total offset from where the stream started, ``|offset_i| ≤ max_offset_i``.
    max_speed : tuple of 6 float
        Largest speed of the offset (rad/s or m/s); with the cycle ``T`` it caps the step
        at ``max_speed_i · T``.  For joint corrections this is the joint speed limit.
    policy : {"clamp", "refuse"}
        ``"clamp"``: a correction beyond a limit is cut to the limit (counted, the reason
        kept); ``"refuse"``: it is not sent — the link holds the robot (zero step) and
        fails the stream with the reason.
    """

    max_step: tuple[float, ...]
    max_offset: tuple[float, ...]
    max_speed: tuple[float, ...]
    policy: Policy = "clamp"

    def __post_init__(self) -> None:
        object.__setattr__(self, "max_step", six_values("max_step", self.max_step))
        object.__setattr__(self, "max_offset", six_values("max_offset", self.max_offset))
        object.__setattr__(self, "max_speed", six_values("max_speed", self.max_speed))
        if self.policy not in ("clamp", "refuse"):
            raise StreamConfigError(f"policy {self.policy!r}: expected 'clamp' or 'refuse'")

    def step_bound(self, cycle_s: float) -> tuple[float, ...]:
        """The per-cycle bound ``min(max_step_i, max_speed_i · T)``.

        Parameters
        ----------
        cycle_s : float
            The controller's cycle ``T`` (s).

        Returns
        -------
        tuple of 6 float
            The largest step per cycle of each axis (rad or m).
        """
        return tuple(min(s, v * cycle_s) for s, v in zip(self.max_step, self.max_speed,
                                                         strict=True))


def default_limits(kind: Kind, policy: Policy = "clamp") -> CorrectionLimits:
    """Conservative limits for a first test on a real robot.

    Joint: 0.1° a cycle, 20°/s, 10° in total.  Cartesian: 0.2 mm and 0.02° a cycle,
    50 mm/s and 5°/s, 50 mm and 5° in total (POSCORR's default box is ±50 mm).

    Parameters
    ----------
    kind : {"joint", "cartesian"}
        Which correction the limits are for.
    policy : {"clamp", "refuse"}
        What happens beyond them (:class:`CorrectionLimits`).

    Returns
    -------
    CorrectionLimits
        The limits in SI.
    """
    if kind == "joint":
        return CorrectionLimits((0.1 * DEG,) * 6, (10 * DEG,) * 6, (20 * DEG,) * 6, policy)
    mm = M_PER_MM
    return CorrectionLimits((0.2 * mm,) * 3 + (0.02 * DEG,) * 3,
                            (50 * mm,) * 3 + (5 * DEG,) * 3,
                            (50 * mm,) * 3 + (5 * DEG,) * 3, policy)


@dataclass(frozen=True)
class Limited:
    """The outcome of one request.

    Attributes
    ----------
    step : ndarray, shape (6,)
        What the offset changes by this cycle (SI): the relative-mode correction.
    offset : ndarray, shape (6,)
        The offset after this cycle (SI): the absolute-mode correction.
    clamped : bool
        The request was cut to the limits (policy ``"clamp"``).
    refused : bool
        The request was not sent; ``step`` is zero (policy ``"refuse"`` or not finite).
    reason : str
        Why it was cut or refused (empty when neither).
    """

    step: Array
    offset: Array
    clamped: bool = False
    refused: bool = False
    reason: str = ""


class OffsetLimiter:
    """The commanded offset and the limits it is held to (module doc).

    Parameters
    ----------
    limits : CorrectionLimits
        The limits (SI).
    cycle_s : float
        The controller's cycle ``T`` (s).
    axes : tuple of str
        The axes' names, for the reasons (``A1..A6`` or ``X..C``).
    units : tuple of (str, float)
        Per axis the unit named in reasons and its size in SI (``("deg", π/180)``).
    """

    def __init__(self, limits: CorrectionLimits, cycle_s: float, axes: tuple[str, ...],
                 units: tuple[tuple[str, float], ...]) -> None:
        self.limits = limits
        self.T = cycle_s
        self.speed_step = np.array(limits.max_speed) * cycle_s
        self.bound = np.array(limits.step_bound(cycle_s))
        self.max_offset = np.array(limits.max_offset)
        # a request within a relative 1e-12 of a limit is at the limit, not beyond it; the
        # tolerances stay finite, so that no infinity is within them
        big = np.finfo(float).max
        self._bound_tol = np.minimum(self.bound * (1 + 1e-12), big)
        self._offset_tol = np.minimum(self.max_offset * (1 + 1e-12), big)
        self.axes = axes
        self.units = units
        self.offset = np.zeros(6)

    def reset(self) -> None:
        """A new stream: the commanded offset is zero again."""
        self.offset = np.zeros(6)

    def _say(self, i: int, value: float) -> str:
        name, size = self.units[i]
        return f"{value / size:.4g} {name}"

    def hold(self) -> Limited:
        """No change this cycle: step zero, offset kept.

        Returns
        -------
        Limited
            The hold.
        """
        return Limited(step=np.zeros(6), offset=self.offset.copy())

    def apply(self, target: Array) -> Limited:
        """Limit the request for the offset ``target`` and commit the result.

        Parameters
        ----------
        target : ndarray, shape (6,)
            The offset asked for (SI).

        Returns
        -------
        Limited
            What to send, and whether and why it was cut or refused.
        """
        target = np.asarray(target, dtype=float).reshape(-1)
        if target.shape != (6,):
            return Limited(np.zeros(6), self.offset.copy(), refused=True,
                           reason=f"a correction has 6 values, got {target.size}")
        want = target - self.offset
        # the common case, as asked: every step and the offset within the limits (a NaN or
        # an infinity fails the comparisons and is refused below)
        if (np.abs(want) <= self._bound_tol).all() and \
                (np.abs(target) <= self._offset_tol).all():
            self.offset = target.copy()
            return Limited(want, target.copy())
        if not np.isfinite(target).all():
            return Limited(np.zeros(6), self.offset.copy(), refused=True,
                           reason=f"a correction must be finite, got {target.tolist()}")
        over_step = np.abs(want) > self._bound_tol
        over_total = np.abs(target) > self._offset_tol
        step = np.minimum(np.maximum(want, -self.bound), self.bound)
        new = np.minimum(np.maximum(self.offset + step, -self.max_offset), self.max_offset)
        step = new - self.offset
        # what was cut, in the units the user configured
        reasons = []
        for i in np.flatnonzero(over_step):
            if self.speed_step[i] < self.limits.max_step[i]:  # the speed limit binds
                reasons.append(f"{self.axes[i]} speed {self._say(i, abs(want[i]) / self.T)}/s "
                               f"> {self._say(i, self.limits.max_speed[i])}/s")
            else:
                reasons.append(f"{self.axes[i]} step {self._say(i, abs(want[i]))} per cycle "
                               f"> {self._say(i, self.bound[i])}")
        for i in np.flatnonzero(over_total):
            reasons.append(f"{self.axes[i]} offset {self._say(i, abs(target[i]))} > "
                           f"{self._say(i, self.max_offset[i])}")
        reason = "; ".join(reasons)
        if self.limits.policy == "refuse":
            return Limited(np.zeros(6), self.offset.copy(), refused=True, reason=reason)
        self.offset = new
        return Limited(step, new.copy(), clamped=True, reason=reason)
