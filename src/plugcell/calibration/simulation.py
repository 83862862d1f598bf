"""Noise-free simulated identification: the check of thesis 8.1.

Known errors are added to the nominal geometry, the "measured" flange poses are
computed with the exact four-bar closure (passive angles from the link lengths,
appendix C; twists of the loop links act on the open chain), and the model
identifies them back.  If the error model is right, the residual vanishes and
every identified value equals the input — or, for a parameter that stands for a
combination, the combination (Table 8-1).

The combination is a first-order statement; it is evaluated at the identified
point (:func:`~plugcell.calibration.identifiability.combinations_at`), where the
model was linearised when the iteration stopped.  With the nominal (parallelogram)
coefficients, the crank and coupler lengths differ from them by ≈ 1.8e-5 m for
the errors of Table 8-1 — a genuine second-order effect of the uneven four-bar,
which the thesis's own table shows at half that size (Δa2', Δa3' errors of
8.9e-6).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from plugcell.calibration.data import CalibrationData
from plugcell.calibration.identifiability import combinations_at
from plugcell.calibration.identify import CalibrationError, Calibrator
from plugcell.calibration.result import CalibrationResult
from plugcell.kinematics import RobotDescription, forward

__all__ = ["SimulationReport", "simulated_identification"]


@dataclass(frozen=True, eq=False)
class SimulationReport:
    """Outcome of :func:`simulated_identification`.

    Attributes
    ----------
    result : CalibrationResult
        The identification.
    iterations : int
        Iterations it took.
    converged : bool
        Whether it converged.
    residual_mean_mm : float, mm
        Mean position residual after calibration.
    max_param_error : float
        Largest ``|error|`` over ``rows`` (unit of that parameter).
    max_param_key : str
        Its parameter.
    rows : tuple of dict
        One per identified parameter — ``key``, ``name``, ``unit``, ``input`` (the
        parameter's own simulated error), ``identified``, ``stands_for`` (the nominal
        combination, e.g. ``Δa2' − Δa4'``), ``expected = Σ_j c_kj Δg_j,true`` (that
        combination of the inputs, linearised at the identified point), ``error`` =
        ``Σ_j c_kj Δĝ_j − expected``; SI units.
    dependent : tuple of dict
        Dropped geometric parameters with their input and the kept ones they are
        identified through.
    """

    result: CalibrationResult
    iterations: int
    converged: bool
    residual_mean_mm: float
    max_param_error: float
    max_param_key: str
    rows: tuple[dict[str, Any], ...]
    dependent: tuple[dict[str, Any], ...]

    def as_dict(self) -> dict[str, Any]:
        """The report as a JSON-ready dict (the fields above plus the condition number)."""
        st = self.result.statistics
        return {
            "iterations": self.iterations,
            "converged": self.converged,
            "residual_mean_mm": self.residual_mean_mm,
            "max_param_error": self.max_param_error,
            "max_param_key": self.max_param_key,
            "parameters_identified": len(self.rows),
            "condition_number": None if st is None else st.condition_number,
            "rows": list(self.rows),
            "dependent": list(self.dependent),
        }


def _compared(result: Any, combos: Mapping[str, Any], values: Mapping[str, float],
              truth_of: Callable[[str], float]) -> tuple[list[dict[str, Any]], float, str]:
    """Each identified parameter against what it should be: the combination it stands
    for, ``Σ c·Δg_true``, beside ``Σ c·g_identified``.

    Returns
    -------
    rows : list of dict
        Per kept key: input, identified, expected, error = identified − expected.
    worst, worst_key : float, str
        The largest ``|error|`` and its key.
    """
    space = result.model.space
    rows = []
    worst, worst_key = 0.0, ""
    for k in result.keys:
        comb = combos[k]
        expected = sum(c * truth_of(kk) for kk, c in comb)
        got = sum(c * values[kk] for kk, c in comb)
        err = got - expected
        if abs(err) > worst:
            worst, worst_key = abs(err), k
        rows.append({"key": k, "name": space[k].name, "unit": space[k].unit,
                     "input": truth_of(k), "identified": values[k],
                     "stands_for": result.stands_for(k), "expected": expected,
                     "error": err})
    return rows, worst, worst_key


def simulated_identification(
    desc: RobotDescription,
    errors: Mapping[tuple[str, str], float],
    q: ArrayLike,
    *,
    model: int | str = "loop",
    tol: float = 1e-6,
) -> SimulationReport:
    """Identify known errors back from noise-free poses (the check of thesis 8.1).

    Poses ``T_i = T_n^0(q_i; g_nom + Δg_true)`` (exact four-bar closure, BASE = PROBE = I,
    known) are identified with :class:`Calibrator`; each kept parameter is compared with
    the combination of the inputs it stands for (:func:`combinations_at`).

    Parameters
    ----------
    desc : RobotDescription
        The robot.
    errors : mapping of (str, str) to float
        ``{(link, field): Δg}``, m or rad.
    q : (N, n_readings) array_like, rad
        Joint readings.
    model : int or str
        The model (:func:`~plugcell.calibration.configs.model_config`).
    tol : float
        Convergence tolerance of the identification.

    Returns
    -------
    SimulationReport
        Identified against expected values per parameter.

    Raises
    ------
    CalibrationError
        The identification fails, or its result lacks the identifiability analysis or
        the accuracy statistics the report is built from.
    """
    q = np.asarray(q, dtype=float)
    truth = desc.nominal_parameters().perturbed(dict(errors))
    T = forward(desc, truth, q, closure="fourbar").flange
    data = CalibrationData.from_poses(q, T)
    result = Calibrator(desc, model, base=np.eye(4), probe=np.eye(4), tol=tol).fit(data)
    fin = result.model
    space = fin.space
    ident = result.identifiability
    if ident is None:
        raise CalibrationError(
            "the fit returned no identifiability analysis (result.identifiability is None)")
    dropped = [k for k in ident.dropped if space[k].is_geometric]
    combos = combinations_at(fin, result.keys, dropped)

    def truth_of(key: str) -> float:
        p = space[key]
        return float(errors.get((p.link, p.field), 0.0)) if p.kind == "link" else 0.0  # type: ignore[arg-type]

    rows, worst, worst_key = _compared(result, combos, fin.as_dict(), truth_of)
    dependent = [{"key": k, "name": space[k].name, "input": truth_of(k),
                  "identified_via": [space[v].name for v in ident.via.get(k, ())]}
                 for k in ident.dropped if space[k].is_geometric]
    if result.calibration is None:
        raise CalibrationError(
            "the fit returned no accuracy statistics (result.calibration is None)")
    return SimulationReport(
        result=result,
        iterations=result.iterations,
        converged=result.converged,
        residual_mean_mm=float(result.calibration.position.norm.mean * 1e3),
        max_param_error=float(worst),
        max_param_key=worst_key,
        rows=tuple(rows),
        dependent=tuple(dependent),
    )
