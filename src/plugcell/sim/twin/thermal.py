"""Thermal drift of the twin's cell over a production shift (issue 19 §3).

A hall warms up during a shift; two things move:

* the robot's links expand: every length of the arm scales by ``1 + κ·ΔT`` — the
  flange position in the robot base frame scales by it (rotations do not depend on
  lengths), the thermal term κT of :mod:`plugcell.calibration.model`;
* BASE — the robot base seen from the tracker — drifts: the tracker's stand and the
  floor between them expand and tilt.  Modelled as a small rigid motion in the
  tracker frame, linear in ΔT: translation ``v·ΔT``, rotation ``Exp(w·ΔT)``.

:func:`shift_temperature` is the temperature profile of an 8-hour shift used by the
drift-watch benchmark: a warm-up towards +6 K (time constant 1.5 h) from the start,
and a gate opened at 4 h for 20 min (−2.5 K, recovering with 30 min).  The numbers
are assumptions of the simulation (stated in docs/twin.md), not measurements.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics.transforms import so3_exp

Array = NDArray[np.float64]

__all__ = ["ThermalDrift", "shift_temperature"]


@dataclass(frozen=True)
class ThermalDrift:
    """Linear thermal drift about ``reference_c`` (module docstring).

    ``length_per_k``: κ of the arm (1/K; cast steel and aluminium arms 12–23·10⁻⁶);
    ``base_translation_m_per_k``, ``base_rotation_rad_per_k``: the drift of BASE per
    kelvin in the tracker frame (m/K, rad/K).
    """

    length_per_k: float = 12e-6
    base_translation_m_per_k: tuple[float, float, float] = (9e-6, -6e-6, 14e-6)
    base_rotation_rad_per_k: tuple[float, float, float] = (2e-6, -3e-6, 4e-6)
    reference_c: float = 20.0

    def length_scale(self, temperature_c: float) -> float:
        """``1 + κ·(T − T_ref)``."""
        return 1.0 + self.length_per_k * (temperature_c - self.reference_c)

    def base_drift(self, temperature_c: float) -> Array:
        """``D(ΔT)`` ``(4, 4)``: the true BASE at ``T`` is ``D · BASE_ref``."""
        dt = temperature_c - self.reference_c
        D = np.eye(4)
        D[:3, :3] = so3_exp(np.asarray(self.base_rotation_rad_per_k) * dt)
        D[:3, 3] = np.asarray(self.base_translation_m_per_k) * dt
        return D


def shift_temperature(t_h: ArrayLike, start_c: float = 20.0) -> Array:
    """Hall temperature (°C) at ``t_h`` hours into the shift (module docstring)."""
    t = np.asarray(t_h, dtype=float)
    warm = 6.0 * (1.0 - np.exp(-t / 1.5))
    gate_open, gate_close = 4.0, 4.0 + 20.0 / 60.0
    cooling = np.where((t >= gate_open) & (t < gate_close),
                       -2.5 * (t - gate_open) / (gate_close - gate_open), 0.0)
    after = t >= gate_close
    cooling = np.where(after, -2.5 * np.exp(-(t - gate_close) / 0.5), cooling)
    return start_c + warm + cooling

