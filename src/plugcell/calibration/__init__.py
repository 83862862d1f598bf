"""plugcell.calibration — the error model, identifiability and identification (thesis ch. 6, 8).

Pure math (numpy, SI units), no I/O, no framework imports; files go through
:mod:`plugcell.io` and the command modules.  See ``docs/calibration.md``.

* :mod:`.parameters` — named error parameters (Δθ1, Δa2', G1, A4, …) with units;
* :mod:`.structure` — the chain a model runs on (loop or serial family, 8.2.3);
* :mod:`.compliance` — gravity (6.31) and payload (6.40) deflection regressors;
* :mod:`.model` — :class:`ErrorModel`: predicts BASE·T6(q + Δq)·PROBE (6.23);
* :mod:`.jacobian` — the exact analytic identification Jacobian (6.12–6.42, D.5);
* :mod:`.identifiability` — column scaling, rank-revealing QR, rule 4.10;
* :mod:`.initial` — BASE/PROBE from the data (AX = YB, rigid registration);
* :mod:`.identify` — :class:`Calibrator` (Gauss–Newton, LM, robust loss);
* :mod:`.result`, :mod:`.statistics` — :class:`CalibrationResult`, (8.1)–(8.5), the
  residual of every pose (:class:`PoseResiduals`); their files (PARAMS.json, the
  residual file, the HTML report) are :mod:`plugcell.io.params` and
  :mod:`plugcell.io.calibration_report`;
* :mod:`.configs` — the five models of 8.2.3; :mod:`.simulation` — the check of 8.1;
* :mod:`.planning` — choosing the poses of a campaign (I/D/A/E/O-optimal, visible);
* :mod:`.validity` — the region a calibration was identified on, and checks against it;
* :mod:`.prior` — a short campaign in a new set-up with an earlier calibration as prior (MAP).
"""

from plugcell.lazy import exports

#: Module → the public names it defines (imported on first use: :mod:`plugcell.lazy`).
_NAMES = {
    "configs": ("MODELS", "ModelConfig", "model_config"),
    "data": ("CalibrationData",),
    "identifiability": (
        "Identifiability", "analyse", "combinations_at", "structural_identifiability",
    ),
    "identify": ("CalibrationError", "Calibrator", "DivergenceError"),
    "jacobian": ("JacobianResult", "identification_jacobian"),
    "model": ("ErrorModel", "PoseBatch"),
    "parameters": ("ErrorParameter", "ParameterSpace"),
    "result": ("CalibrationResult",),
    "statistics": ("PoseResiduals",),
    "structure": ("KinematicStructure", "kinematic_structure"),
}
__getattr__, __dir__, __all__ = exports(__name__, _NAMES)
