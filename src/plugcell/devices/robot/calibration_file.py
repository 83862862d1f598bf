"""A calibration (PARAMS.json, what ``plugcell calibrate`` writes) as the robot service reads it.

Two of the service's corrections use the calibrated model: ``CORRECT compensation
calibration=PARAMS.json`` (:mod:`.stream.correcting`) and the tracked moves of a streamed
robot started with ``--param calibration=PARAMS.json`` (:mod:`.tracked_moves`).  Both
read the file here: the physical model and, when the file names one, its **learned
residual layer** (the hybrid model ``plugcell compensate`` uses: its side file checked by
:func:`~plugcell.io.residual_models.load_residual` — its SHA-256, robot, the physical
model's fingerprint, the scikit-learn version), every failure a :class:`ValueError`
naming the file and the cause (a layer that cannot be used is refused, not left out
silently).
"""

from __future__ import annotations

import json
from typing import Any

__all__ = ["read_calibration"]


def read_calibration(path: str, robot: str | None = None) -> Any:
    """The :class:`~plugcell.calibration.result.CalibrationResult` of PARAMS.json ``path``.

    Parameters
    ----------
    path : str
        The file.
    robot : str, optional
        The robot it must be of (its description's name); ``None``: any.

    Returns
    -------
    CalibrationResult
        ``model`` (the identified :class:`~plugcell.calibration.ErrorModel`), ``robot``,
        ``residual_model`` (its learned layer, or None).

    Raises
    ------
    ValueError
        ``calibration PATH: cannot read: …``, ``…: not a plugcell calibration: …``,
        ``…: the calibration is of the robot 'A', this robot is 'B'`` or ``…: its learned
        residual layer cannot be used: …``.
    """
    from plugcell.io.params import result_from_params
    from plugcell.io.robots import description_of_params

    try:
        with open(path, encoding="utf-8") as f:
            d = json.load(f)
        result = result_from_params(d, description_of_params(d, path), check_robot=False)
    except OSError as exc:
        raise ValueError(f"calibration {path}: cannot read: {exc.strerror or exc}") from None
    except Exception as exc:  # not JSON, not a plugcell calibration: say which
        raise ValueError(f"calibration {path}: not a plugcell calibration: "
                         f"{type(exc).__name__}: {exc}") from None
    if robot is not None and result.robot != robot:
        raise ValueError(f"calibration {path}: the calibration is of the robot "
                         f"{result.robot!r}, this robot is {robot!r}")
    entry = d.get("residual_model")
    if entry:
        from plugcell.io.residual_models import ResidualFileError, load_residual

        try:
            layer = load_residual(entry, path, robot=result.robot, model=result.model)
        except ResidualFileError as exc:
            raise ValueError(f"calibration {path}: its learned residual layer cannot be "
                             f"used: {exc}") from None
        result = result.with_residual_model(layer)
    return result
