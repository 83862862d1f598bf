"""Exceptions of :mod:`plugcell.compensation`.

* :class:`CompensationError` — model-based compensation (thesis 6.5.1) failed for a
  target: no nominal joint solution, no convergence of the iteration, or the
  compensated joints leave the joint limits.  ``kind`` says which, ``index`` names
  the target.
* :class:`SensorError` — a measuring device could not deliver a reading (a laser
  tracker whose beam is not locked, a blocked line of sight...).  Raised by device
  adapters; ``reason`` is a short machine-readable word.
* :class:`CorrectionError` — the sensor-based correction loop (thesis 6.5.2) had to
  stop before the thresholds were met.  ``reason`` says why (``"sensor:<reason>"``,
  ``"max_iterations"``, ``"joint_limit"``, ``"singular"``, ``"robot"``; the settling
  loop also ``"noisy"``, ``"not_settled"``, ``"max_corrections"``) and
  ``result`` carries every iteration recorded up to that point, so the caller can
  decide (re-point the tracker, accept the residual, abort the program).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from plugcell.compensation.sensor_based import CorrectionResult
    from plugcell.compensation.settling import SettlingResult

__all__ = ["CompensationError", "CorrectionError", "SensorError"]

#: Kinds of :class:`CompensationError`.
COMPENSATION_KINDS: tuple[str, ...] = ("unreachable", "no_convergence", "joint_limit")


class CompensationError(ValueError):
    """Model-based compensation failed for a target (module docstring).

    ``kind`` ∈ :data:`COMPENSATION_KINDS`; ``index`` the target's position in the
    batch (``None`` for a single target); ``joint``/``value``/``limit`` for a limit
    violation (radians).
    """

    def __init__(
        self,
        message: str,
        *,
        kind: str,
        index: int | None = None,
        joint: str | None = None,
        value: float | None = None,
        limit: tuple[float, float] | None = None,
    ) -> None:
        if kind not in COMPENSATION_KINDS:
            raise ValueError(f"kind must be one of {COMPENSATION_KINDS}, got {kind!r}")
        self.kind = kind
        self.index = index
        self.joint = joint
        self.value = value
        self.limit = limit
        super().__init__(message)


class SensorError(RuntimeError):
    """A measuring device could not deliver a reading; ``reason`` is machine-readable."""

    def __init__(self, message: str, *, reason: str, details: dict[str, Any] | None = None
                 ) -> None:
        self.reason = reason
        self.details = dict(details or {})
        super().__init__(message)


class CorrectionError(RuntimeError):
    """The sensor-based correction stopped early (module docstring)."""

    def __init__(self, message: str, *, reason: str,
                 result: CorrectionResult | SettlingResult | None = None) -> None:
        self.reason = reason
        self.result = result
        super().__init__(message)
