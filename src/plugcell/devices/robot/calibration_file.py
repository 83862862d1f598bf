"""A calibration (PARAMS.json, what ``plugcell calibrate`` writes) as the robot service reads it.

Two of the service's corrections use the calibrated model: ``CORRECT compensation
calibration=PARAMS.json`` (:mod:`.stream.correcting`) and the tracked moves of a streamed
robot started with ``--param calibration=PARAMS.json`` (:mod:`.tracked_moves`).  Both
read the file here: the physical model (its learned residual layer, if any, is not used
by the service), every failure a :class:`ValueError` naming the file and the cause.
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
        ``model`` (the identified :class:`~plugcell.calibration.ErrorModel`), ``robot``.

    Raises
    ------
    ValueError
        ``calibration PATH: cannot read: …``, ``…: not a plugcell calibration: …`` or
        ``…: the calibration is of the robot 'A', this robot is 'B'``.
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
    return result
