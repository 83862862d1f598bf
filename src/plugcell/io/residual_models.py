"""The learned residual layer's side file (``PARAMS.residual.skops``).

``plugcell calibrate --residual-model learned --out PARAMS.json`` writes the fitted
:class:`~plugcell.calibration.residual_model.LearnedResidual` next to PARAMS.json,
serialised with **skops** (no pickle: loading never runs code from the file, and
only the scikit-learn types listed in :data:`TRUSTED_TYPES` are accepted).
PARAMS.json records the file name, its SHA-256, the robot, the fingerprint of the
physical calibration and the scikit-learn version in ``residual_model``.

Loading checks, each failure a :class:`ResidualFileError` naming the file:

* the file exists and its SHA-256 is the one PARAMS.json recorded;
* it contains only trusted types;
* its robot and calibration fingerprint are those of PARAMS.json (a layer trained
  on another robot or on another calibration of the same robot is refused; the
  fingerprint covers the robot's parameters, not BASE and PROBE);
* it was written by the same scikit-learn major.minor version (tree predictors are
  not guaranteed across versions: re-run ``plugcell calibrate``).

Format 2 added the transferable arm-shape stage
(:class:`~plugcell.calibration.residual_model.ShapeStage`: its estimators,
nearest-neighbour index and summary); format 3 adds the prior stage, an arm-shape stage
of another set-up the layer was learned on top of (``calibrate --residual-prior``);
format 4 (this version) adds the layer's ``weight`` (a campaign stage shrunk by its own
CV, ``calibrate --prior``: the factor on its regressors' correction).  Files of formats
1–3 still load, with weight 1 (their layers were applied whole); a weight that is not a
number in [0, 1] is refused.  Only a layer whose weight is not 1 is written as format 4
(an older plugcell refuses it rather than apply a shrunk stage whole); a layer applied
whole is written as format 3, which it reads.
"""

from __future__ import annotations

import hashlib
from dataclasses import fields
from pathlib import Path
from typing import Any

from plugcell.calibration.residual_model import (
    CrossValidation,
    LearnedResidual,
    ResidualModelError,
    ShapeStage,
    calibration_fingerprint,
    check_weight,
)

__all__ = ["FORMAT", "TRUSTED_TYPES", "ResidualFileError", "load_residual", "residual_path",
           "save_residual"]

FORMAT = "plugcell-residual-model"
FORMAT_VERSION = 4
#: The version a layer of weight 1 is written as (format 3: what a plugcell before the
#: weight reads; its ``weight`` in the summary is then ignored, as it may be).
WHOLE_FORMAT_VERSION = 3
#: versions :func:`load_residual` reads (1: no arm-shape stage; 2: no prior stage; 3: no
#: weight, read as 1).
READABLE_VERSIONS = (1, 2, 3, 4)
#: The only non-builtin types a side file may contain.
TRUSTED_TYPES = (
    "sklearn.ensemble._hist_gradient_boosting.gradient_boosting.HistGradientBoostingRegressor",
    "sklearn.ensemble._hist_gradient_boosting.predictor.TreePredictor",
    "sklearn.ensemble._hist_gradient_boosting.binning._BinMapper",
    "sklearn._loss.loss.HalfSquaredError",
    "sklearn._loss.link.IdentityLink",
    "sklearn._loss.link.Interval",
    "sklearn.neighbors._unsupervised.NearestNeighbors",
    "sklearn.neighbors._kd_tree.KDTree",
    "sklearn.neighbors._ball_tree.BallTree",
    "sklearn.metrics._dist_metrics.EuclideanDistance64",
    "numpy.dtype",
    "numpy.ndarray",
    "builtins.slice",
)


class ResidualFileError(ValueError):
    """A residual-model side file that cannot be used (message names the file)."""


def residual_path(params_path: str | Path) -> Path:
    """The side file next to a PARAMS.json: ``<dir>/<stem>.residual.skops``.

    Parameters
    ----------
    params_path : str or Path
        The PARAMS.json path (e.g. ``out/PARAMS.json``).

    Returns
    -------
    Path
        The side file's path in the same directory (``out/PARAMS.residual.skops``).
    """
    p = Path(params_path)
    return p.with_name(p.stem + ".residual.skops")


def _minor(version: str) -> str:
    return ".".join(version.split(".")[:2])


def save_residual(layer: LearnedResidual, path: str | Path) -> dict[str, Any]:
    """Write ``layer`` to ``path`` (skops, format :data:`FORMAT_VERSION`; a layer of
    weight 1, :data:`WHOLE_FORMAT_VERSION`, which older plugcell reads).

    The file holds the layer's summary, cross-validation, estimators and nearest-
    neighbour index (and those of its shape stage); its SHA-256 goes into the entry.

    Parameters
    ----------
    layer : LearnedResidual
        The fitted layer.
    path : str or Path
        The side file to write (parent directories are created); to be found again by
        :func:`load_residual` it must lie in the directory of PARAMS.json — use
        :func:`residual_path`.

    Returns
    -------
    dict
        The ``residual_model`` entry of PARAMS.json: :meth:`LearnedResidual.summary`
        plus ``file`` (the file's name only, resolved against PARAMS.json's directory)
        and ``sha256`` (hex digest of the bytes written).

    Raises
    ------
    ResidualFileError
        The file cannot be written.
    """
    import skops.io as sio

    p = Path(path)
    meta = layer.summary()
    # a layer applied whole is written as format 3, which a plugcell before the weight reads
    version = FORMAT_VERSION if layer.weight != 1.0 else WHOLE_FORMAT_VERSION
    obj = {"format": FORMAT, "format_version": version, "meta": meta,
           # the record without the per-pose CV errors (fields with compare=False)
           "cv": {**{f.name: getattr(layer.cv, f.name) for f in fields(layer.cv) if f.compare},
                  "scores": [[dict(s), v] for s, v in layer.cv.scores]},
           "estimators": list(layer.estimators), "neighbours": layer.neighbours}
    for key, stage in (("shape", layer.shape), ("prior", layer.prior)):
        if stage is not None:
            obj[key] = {"estimators": list(stage.estimators), "neighbours": stage.neighbours}
    blob = sio.dumps(obj)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(blob)
    except OSError as exc:
        raise ResidualFileError(f"{p}: cannot write: {exc.strerror}") from None
    return {**meta, "file": p.name, "sha256": hashlib.sha256(blob).hexdigest()}


def load_residual(entry: dict[str, Any], params_path: str | Path, *, robot: str,
                  model: Any) -> LearnedResidual:
    """The layer PARAMS.json's ``residual_model`` ``entry`` refers to, checked.

    Accepted only when ``SHA-256(file) = entry["sha256"]``, the file holds only
    :data:`TRUSTED_TYPES`, its format version is readable, its robot is ``robot``, its
    fingerprint is ``calibration_fingerprint(model)`` and its scikit-learn major.minor
    version is the installed one (module docstring).

    Parameters
    ----------
    entry : dict
        PARAMS.json's ``residual_model`` (needs ``file`` and ``sha256``).
    params_path : str or Path
        The PARAMS.json; the side file is ``params_path.parent / entry["file"]``.
    robot : str
        The calibration's robot name.
    model : ErrorModel
        The calibration's physical model (its :func:`calibration_fingerprint` must
        match the file's).

    Returns
    -------
    LearnedResidual
        The layer (with its arm-shape stage and its prior stage when the file has them;
        format 1 has neither, format 2 no prior stage) and its ``weight`` (1 when the
        file has none: formats 1–3).

    Raises
    ------
    ResidualFileError
        The entry lacks ``file``/``sha256``, or the file is missing, differs from the
        recorded SHA-256, is not a skops file, contains untrusted types, is not a
        plugcell residual model of a readable version, belongs to another robot or
        calibration, was written by another scikit-learn major.minor version, or its
        ``weight`` is not a number in [0, 1].
    """
    import sklearn

    try:
        p = Path(params_path).parent / str(entry["file"])
        want = str(entry["sha256"])
    except (KeyError, TypeError):
        raise ResidualFileError(f"{params_path}: 'residual_model' lacks 'file' or "
                                "'sha256'") from None
    obj = _trusted_document(p, want, params_path)
    meta = obj["meta"]
    if meta.get("robot") != robot:
        raise ResidualFileError(f"{p}: residual model of robot {meta.get('robot')!r}, the "
                                f"calibration is of {robot!r}")
    fp = calibration_fingerprint(model)
    if meta.get("fingerprint") != fp:
        raise ResidualFileError(f"{p}: trained on top of another calibration (fingerprint "
                                f"{meta.get('fingerprint')}, this one {fp}): re-run calibrate")
    if _minor(str(meta.get("sklearn_version", ""))) != _minor(sklearn.__version__):
        raise ResidualFileError(
            f"{p}: written with scikit-learn {meta.get('sklearn_version')}, this is "
            f"{sklearn.__version__}: re-run plugcell calibrate --residual-model learned")
    cvd = dict(obj["cv"])
    cvd["scores"] = tuple((dict(s), float(v)) for s, v in cvd["scores"])
    features = list(meta["features"])
    shape = _stage(meta.get("shape_stage"), obj.get("shape"), p, "shape")
    prior = _stage(meta.get("prior_stage"), obj.get("prior"), p, "prior")
    try:
        weight = check_weight(meta.get("weight", 1.0), f"{p}: the layer's 'weight'")
    except ResidualModelError as exc:
        raise ResidualFileError(str(exc)) from None
    return LearnedResidual(
        robot=robot, fingerprint=fp, estimators=tuple(obj["estimators"]),
        neighbours=obj["neighbours"], threshold=float(meta["threshold"]),
        uses_temperature=any(f.startswith("temperature") for f in features),
        uses_payload=any(f.startswith("payload") for f in features),
        orientation=bool(meta["orientation"]), params=dict(meta["params"]),
        cv=CrossValidation(**cvd), useful=bool(meta["useful"]), n_poses=int(meta["poses"]),
        sklearn_version=str(meta["sklearn_version"]), shape=shape, prior=prior, weight=weight)


def _trusted_document(p: Path, want: str, params_path: str | Path) -> dict[str, Any]:
    """The side file's document, loaded only once it is trusted: ``SHA-256(file) =
    want``, nothing but :data:`TRUSTED_TYPES` in it, a plugcell residual model of a
    readable format version (ResidualFileError saying which failed)."""
    import skops.io as sio

    try:
        blob = p.read_bytes()
    except OSError as exc:
        raise ResidualFileError(f"{p}: cannot read the residual model named by {params_path}: "
                                f"{exc.strerror}") from None
    if hashlib.sha256(blob).hexdigest() != want:
        raise ResidualFileError(f"{p}: not the residual model {params_path} was written with "
                                "(SHA-256 differs): from another calibration?")
    try:
        untrusted = sio.get_untrusted_types(data=blob)
    except Exception as exc:  # skops raises several types on damaged data
        raise ResidualFileError(f"{p}: not a skops file: {exc}") from None
    bad = sorted(set(untrusted) - set(TRUSTED_TYPES))
    if bad:
        raise ResidualFileError(f"{p}: contains types plugcell does not load: {bad}")
    try:
        obj = sio.loads(blob, trusted=list(untrusted))
    except Exception as exc:
        raise ResidualFileError(f"{p}: cannot load: {exc}") from None
    if not isinstance(obj, dict) or obj.get("format") != FORMAT:
        raise ResidualFileError(f"{p}: not a plugcell residual model")
    version = obj.get("format_version")
    if isinstance(version, bool) or version not in READABLE_VERSIONS:
        raise ResidualFileError(f"{p}: residual model format version {version!r}, this "
                                f"plugcell reads {', '.join(map(str, READABLE_VERSIONS))}: "
                                "re-run plugcell calibrate --residual-model learned")
    return obj


def _stage(summary: dict[str, Any] | None, fitted: Any, p: Path, what: str
           ) -> ShapeStage | None:
    """An arm-shape stage from its summary (PARAMS.json's words) and its fitted parts."""
    if summary is None:
        return None
    if not isinstance(fitted, dict):
        raise ResidualFileError(f"{p}: the {what} stage's estimators are missing")
    return ShapeStage(
        joints=tuple(int(j) - 1 for j in summary["joints"]),
        estimators=tuple(fitted["estimators"]), neighbours=fitted["neighbours"],
        threshold=float(summary["threshold"]), params=dict(summary["params"]),
        physical_mm=float(summary["physical_mm"]), cv_mm=float(summary["cv_mm"]),
        useful=bool(summary["useful"]))
