"""The files every command reads or writes, with one-line errors that name them.

:func:`write_text` writes an output file (folders made); :func:`read_calibration`
reads a PARAMS.json of ``plugcell calibrate`` into the dictionary and the
:class:`~plugcell.calibration.result.CalibrationResult` it describes, for the robot the
file records (``description``, else ``robot_source``, else the shipped ``robot``) or the
one the command's ``--robot`` options name.  Every failure is a
:class:`~plugcell.apps.cli.CommandError` naming the file: exit code 2, nothing written.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from plugcell.apps.cli import CommandError

if TYPE_CHECKING:
    from plugcell.calibration.result import CalibrationResult


def write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path``, making its folder; an OS error names the file."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise CommandError(f"{path}: cannot write: {exc.strerror or exc}") from None


def read_params_document(path: Path) -> dict[str, Any]:
    """The JSON object of a PARAMS.json file (unreadable, not JSON, not an object: error)."""
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CommandError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise CommandError(f"{path}: not valid JSON: {exc}") from None
    except json.JSONDecodeError as exc:
        raise CommandError(f"{path}: not valid JSON: line {exc.lineno}: {exc.msg}") from None
    if not isinstance(d, dict):
        raise CommandError(f"{path}: expected a JSON object written by plugcell calibrate")
    return d


def read_calibration(path: Path, args: argparse.Namespace | None = None
                     ) -> tuple[dict[str, Any], CalibrationResult]:
    """PARAMS.json ``path`` as ``(document, result)``.

    Parameters
    ----------
    path : Path
        A PARAMS.json written by ``plugcell calibrate``.
    args : argparse.Namespace, optional
        The command's options: when ``args.robot`` is given (with the URDF options of
        :func:`~plugcell.apps.commands.robotargs.add_robot_args`) that robot replaces the one
        the file records.

    Returns
    -------
    document : dict
        The file's JSON object.
    result : CalibrationResult
        The calibration, ready to predict (no residual layer: the caller loads it).
    """
    from plugcell.apps.commands.robotargs import load_robot_of
    from plugcell.io.params import ParamsError, result_from_params
    from plugcell.io.robots import description_of_params
    from plugcell.kinematics.errors import DescriptionError

    d = read_params_document(path)
    given = args is not None and getattr(args, "robot", None) is not None
    if given:
        desc = load_robot_of(args)
    else:
        try:
            desc = description_of_params(d, str(path))
        except DescriptionError as exc:
            raise CommandError(str(exc)) from None
    try:
        # the robot the command was given must be the one calibrated; one the file
        # records is (a file naming another robot elsewhere fails on its side file)
        return d, result_from_params(d, desc, check_robot=given)
    except ParamsError as exc:  # names the key, the robot or the format
        raise CommandError(f"{path}: {exc}") from None
    except (KeyError, TypeError, ValueError) as exc:
        what = f"missing key {exc}" if isinstance(exc, KeyError) else str(exc)
        raise CommandError(f"{path}: not a plugcell calibration: {what}") from None


def read_compensation_model(path: Path, args: argparse.Namespace, residual: bool = True
                            ) -> Any:
    """The calibration of PARAMS.json ``path`` as ``plugcell compensate`` uses it: with its
    learned residual layer when ``residual`` and the file has one (``--physical-only``:
    without)."""
    d, result = read_calibration(path, args)
    entry = d.get("residual_model")
    if residual and entry:
        from plugcell.io.residual_models import ResidualFileError, load_residual

        try:
            layer = load_residual(entry, path, robot=result.robot, model=result.model)
        except ResidualFileError as exc:
            raise CommandError(f"{exc} (--physical-only ignores it)") from None
        result = result.with_residual_model(layer)
    return result


def check_region_of(result: Any, q: Any, payload: Any) -> Any:
    """The compensated joints ``q`` ((N, n), rad) with their payloads ((N,), kg), and
    their T-MAC positions in the robot base frame, checked against the region the
    parameters were identified on; ``None`` for a PARAMS.json without one."""
    if result.validity is None:
        return None
    import numpy as np

    m = result.model
    targets = (np.linalg.inv(m.base()) @ m.predict(q, payload))[:, :3, 3]
    return result.check_region(q, payload, targets)
