"""The inverse law's run-to-run state in a learned-correction file (format version 3):
the weighting's settings and state, the re-identification's runs and the supervisor's
best run — what :class:`~plugcell.compensation.tracking.learning.IterativeLearning`
needs, besides the plant, ``j`` and ``β``'s scale (:mod:`plugcell.io.learned_plant`), to
go on **exactly** as the learning saved would (:class:`~plugcell.compensation.tracking.
learning.InverseState`).  Inside ``"inverse"`` of :mod:`plugcell.io.learned_paths`::

    "weighting": null | {"noise_low_hz": 50.0, "noise_high_hz": 110.0,   # WeightingSettings
                         "smooth_hz": 0.5, "detect": null, "window_s": 0.0,  # null: inf
                         "adapt_max": 1.0, "adapt_step": 2.0,   # optional: absent → these
                         "adapt_margin": 0.0, "detect_fell": 0},
    "state": {
      "excited": null | {"u_m": [[x, y, z]…G], "e_m": […G], "measured": "0111…1"},
      "pairs": [{"du_m": […G], "de_m": […G], "mask": "0111…1"}, …],
      "supervisor": null | {"rms_m": 2.1e-05, "u_m": […G], "e_m": […G]},
      "weighting": {"prior": null | [S_j…] | [[S…]…], "noise": null | N,
                    "history": [{"noise": N, "mean_gain": K̄, "rematched": r}, …],
                    "scale": null | [c_j…] | [[c…]…], "power": null | [P_j…] | …},
      "identifying": null | {"u_m": […G], "e_m": […G], "measured": "0111…1"}}

The weighting's ``adapt_*`` and ``detect_fell`` settings and its state's
``scale``/``power`` (the inflation (5) of :mod:`~plugcell.compensation.tracking.smoothing`)
are optional: a file written before them has none, and loads as the law without
inflation, ``adapt_max`` 1.
``identifying`` (optional, absent is null) is the run before the identifying run while
that run is still ahead — a learning saved after its first update (whose offset carries
the excitation) goes on with the identification exactly (a robot program's tracked move
learns one run a program run).  A plugcell that does not know the key finds no plant in
such a file and refuses to continue it by the inverse law, so the format stays version 3.

Why the runs themselves and not sufficient statistics: the identification
(:func:`~plugcell.compensation.tracking.plant.identify_plant`) searches the modes
``(f_m, ζ_m)`` afresh each time, and its regressors are the inputs filtered through each
candidate mode's ``1/A_m(z)`` — the least squares' Gram matrix depends on the modes, so no
fixed summary of the pairs (``Σ Xᵀ X``, ``Σ Xᵀ y``) reproduces the search; the pairs
``(Δu, Δe, mask)`` and the excited run (the next pair's reference) are the minimal data
to continue it exactly.  Their size grows by one grid a run: the state's rows are bounded
by :data:`MAX_STATE_CYCLES` (a file that would exceed it is refused on writing, with the
way out, and on reading, before its arrays are parsed).

Arrays in SI (m; the weighting's powers in m² per FFT bin), written at full precision
(JSON's float text round-trips exactly); the cycle masks as strings of ``0``/``1``, one
character a cycle.  Every value is checked on reading: a
:class:`~plugcell.io.json_fields.DocumentError` naming the dotted key.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.compensation.tracking.learning import MAX_GRID, InverseState, IterativeLearning
from plugcell.compensation.tracking.smoothing import WeightingSettings
from plugcell.io.json_fields import DocumentError, finite, typename

Array = NDArray[np.float64]

__all__ = ["MAX_STATE_CYCLES", "read_state", "read_weighting", "state_document",
           "weighting_document"]

#: The most grid rows the state may hold (the excited run, the pairs and the supervisor's
#: run, each a grid of the learning): 2**20, ≈ 7 million numbers, ≈ 150 MB of JSON.
MAX_STATE_CYCLES = MAX_GRID
#: The weighting's settings a file may lack (written before them: their defaults).
OPTIONAL_WEIGHTING = ("adapt_max", "adapt_step", "adapt_margin", "detect_fell")
#: The history entries of the weighting.
HISTORY_KEYS = ("noise", "mean_gain", "rematched")


def _get(doc: dict[str, Any], key: str, label: str) -> Any:
    """``doc[key]`` of the object at ``label`` (a missing key named in full)."""
    if key not in doc:
        raise DocumentError(f"missing key {f'{label}.{key}'!r}")
    return doc[key]


def _number(doc: dict[str, Any], key: str, label: str, none: float | None = None) -> float:
    """The finite number at ``label.key`` (``none``: what null means, when it may be)."""
    x = _get(doc, key, label)
    if x is None and none is not None:
        return none
    return finite(x, f"{label}.{key}")


def weighting_document(w: WeightingSettings | None) -> dict[str, float] | None:
    """``"weighting"``: the settings (``detect`` inf is written null by the strict
    writer).

    Parameters
    ----------
    w : WeightingSettings or None
        The learning's weighting (None: the learning is not weighted).

    Returns
    -------
    dict or None
        The settings by field name (``N``'s band in Hz, the averaging width, …), or None.
    """
    return None if w is None else dataclasses.asdict(w)


def read_weighting(doc: Any, label: str) -> WeightingSettings | None:
    """The weighting's settings of ``doc`` (null: none); ``detect`` null is inf.

    Parameters
    ----------
    doc : object
        The ``"weighting"`` value of a learned file (an object or null).
    label : str
        Where it sits in the file, for the error (e.g. ``inverse.weighting``).

    Returns
    -------
    WeightingSettings or None

    Raises
    ------
    DocumentError
        Not an object or null, a missing or non-finite field (named), settings the
        weighting refuses (its reason).
    """
    if doc is None:
        return None
    if not isinstance(doc, dict):
        raise DocumentError(f"{label}: expected an object or null, got {typename(doc)}")
    values = {f.name: _number(doc, f.name, label, math.inf if f.name == "detect" else None)
              for f in dataclasses.fields(WeightingSettings)
              if f.name not in OPTIONAL_WEIGHTING or f.name in doc}
    if values.get("detect_fell") in (0, 1):  # a flag: 0 or 1 (other values refused below)
        values["detect_fell"] = int(values["detect_fell"])
    try:
        return WeightingSettings(**values)
    except ValueError as exc:
        raise DocumentError(f"{label}: {exc}") from None


def _mask(m: Array) -> str:
    return "".join("1" if v else "0" for v in np.asarray(m, bool))


def _run(u: Array, e: Array, m: Array, names: tuple[str, str, str]) -> dict[str, Any]:
    return {names[0]: np.asarray(u, float).tolist(), names[1]: np.asarray(e, float).tolist(),
            names[2]: _mask(m)}


def state_document(learning: IterativeLearning) -> dict[str, Any]:
    """``"state"`` of a learning by the inverse law (module docstring).

    Parameters
    ----------
    learning : IterativeLearning
        A learning by the inverse law (its grid of ``G`` cycles).

    Returns
    -------
    dict
        The state's document: the excited run and the pairs of runs (offsets and errors
        (G, 3) in m, masks as strings of ``G`` characters 0/1), the weighting's
        ``S_j``/``N``, the supervisor's best run and, before the identification, the run
        before the identifying one.

    Raises
    ------
    ValueError
        The state's rows would exceed :data:`MAX_STATE_CYCLES` (the way out named).
    """
    s = learning.inverse_state()
    G = learning.grid.size
    rows = G * ((s.excited is not None) + len(s.pairs) + 2 * (s.best is not None)
                + (s.identifying is not None))
    if rows > MAX_STATE_CYCLES:
        raise ValueError(f"the inverse law's state holds {len(s.pairs)} pairs of runs of "
                         f"{G} cycles ({rows} rows); a learned file holds at most "
                         f"{MAX_STATE_CYCLES}: learn this path with InverseSettings."
                         f"reidentify 0 (--inverse-reidentify 0) or fewer runs a file")
    return {
        "excited": None if s.excited is None else _run(*s.excited, ("u_m", "e_m", "measured")),
        "pairs": [_run(*p, ("du_m", "de_m", "mask")) for p in s.pairs],
        "supervisor": None if s.best is None else {
            "rms_m": s.best[0], "u_m": s.best[1].tolist(), "e_m": s.best[2].tolist()},
        "weighting": {"prior": None if s.prior is None else s.prior.tolist(),
                      "noise": s.noise, "history": s.weighting_history,
                      "scale": None if s.scale is None else s.scale.tolist(),
                      "power": None if s.power is None else s.power.tolist()},
        "identifying": None if s.identifying is None else _run(*s.identifying,
                                                                ("u_m", "e_m", "measured"))}


def _rows(x: Any, label: str, n: int) -> Array:
    """``x`` as ``n`` rows of 3 finite numbers (m); the first wrong one named."""
    if not isinstance(x, list) or len(x) != n:
        got = f"{len(x)} rows" if isinstance(x, list) else typename(x)
        raise DocumentError(f"{label}: expected {n} rows of the learning's grid, got {got}")
    out = None
    if all(isinstance(r, list) and len(r) == 3 and all(type(v) in (int, float) for v in r)
           for r in x):
        try:
            out = np.array(x, dtype=float).reshape(n, 3)
        except OverflowError:  # an integer beyond float: named below
            out = None
    if out is None or not np.all(np.isfinite(out)):
        for i, r in enumerate(x):
            if not (isinstance(r, list) and len(r) == 3):
                raise DocumentError(f"{label}[{i}]: expected 3 numbers (x, y, z m), got "
                                    f"{typename(r)}")
            for j, v in enumerate(r):
                finite(v, f"{label}[{i}][{j}]")
    return out  # type: ignore[return-value]


def _cycles(x: Any, label: str, n: int) -> NDArray[np.bool_]:
    """A mask string of ``n`` characters ``0``/``1``."""
    if not isinstance(x, str) or len(x) != n or set(x) - {"0", "1"}:
        got = f"{len(x)} characters" if isinstance(x, str) else typename(x)
        raise DocumentError(f"{label}: expected a string of {n} characters 0 or 1 (one a "
                            f"cycle of the grid), got {got}"
                            + (" with others" if isinstance(x, str) and len(x) == n else ""))
    return np.frombuffer(x.encode("ascii"), np.uint8) == ord("1")


def _read_run(doc: Any, label: str, n: int, names: tuple[str, str, str]
              ) -> tuple[Array, Array, NDArray[np.bool_]]:
    if not isinstance(doc, dict):
        raise DocumentError(f"{label}: expected an object, got {typename(doc)}")
    return (_rows(_get(doc, names[0], label), f"{label}.{names[0]}", n),
            _rows(_get(doc, names[1], label), f"{label}.{names[1]}", n),
            _cycles(_get(doc, names[2], label), f"{label}.{names[2]}", n))


def _prior(x: Any, label: str, shape: tuple[int, ...] | None, what: str = "S_j"
           ) -> Array | None:
    if x is None:
        return None
    if shape is None:
        raise DocumentError(f"{label}: a weighting state in a learning without weighting")
    arr = None
    try:
        if isinstance(x, list) and all(type(v) in (int, float) or (
                isinstance(v, list) and all(type(w) in (int, float) for w in v)) for v in x):
            arr = np.array(x, dtype=float)
    except (ValueError, OverflowError):  # ragged, or an integer beyond float
        arr = None
    if arr is None or arr.shape != shape or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise DocumentError(f"{label}: expected {' × '.join(map(str, shape))} finite powers "
                            f"≥ 0 (the weighting's {what} on this learning's bins)")
    return arr


def _read_weighting_state(doc: Any, label: str, shape: tuple[int, ...] | None
                          ) -> tuple[Array | None, float, list[dict[str, float]],
                                     Array | None, Array | None]:
    if not isinstance(doc, dict):
        raise DocumentError(f"{label}: expected an object, got {typename(doc)}")
    prior = _prior(_get(doc, "prior", label), f"{label}.prior", shape)
    scale = _prior(doc.get("scale"), f"{label}.scale", shape, "inflation c_j")
    power = _prior(doc.get("power"), f"{label}.power", shape, "power P_j")
    if scale is not None and np.any(scale < 1):
        raise DocumentError(f"{label}.scale: the inflation c_j must be ≥ 1")
    noise = _number(doc, "noise", label, math.nan)
    if not (math.isnan(noise) or noise >= 0):
        raise DocumentError(f"{label}.noise must be ≥ 0 (a power), got {noise!r}")
    history = _get(doc, "history", label)
    if not isinstance(history, list):
        raise DocumentError(f"{label}.history: expected a list, got {typename(history)}")
    out = []
    for i, h in enumerate(history):
        if not isinstance(h, dict):
            raise DocumentError(f"{label}.history[{i}]: expected an object, got "
                                f"{typename(h)}")
        out.append({k: _number(h, k, f"{label}.history[{i}]", math.nan)
                    for k in HISTORY_KEYS})
    return prior, noise, out, scale, power


def read_state(doc: Any, learning: IterativeLearning, label: str = "inverse.state"
               ) -> InverseState:
    """``"state"`` (module docstring) for ``learning`` (its grid, its weighting).

    Parameters
    ----------
    doc : object
        The ``"state"`` value of a learned file.
    learning : IterativeLearning
        The learning it continues (its grid of ``G`` cycles and its weighting).
    label : str
        Where it sits in the file, for the errors.

    Returns
    -------
    InverseState
        What :meth:`IterativeLearning.resume_inverse` continues from (SI units).

    Raises
    ------
    DocumentError
        A missing or wrong key (named), rows that are not the learning's grid, more rows
        than :data:`MAX_STATE_CYCLES`, a weighting state of another shape.
    """
    if not isinstance(doc, dict):
        raise DocumentError(f"{label}: expected an object, got {typename(doc)}")
    G = learning.grid.size
    pairs = _get(doc, "pairs", label)
    if not isinstance(pairs, list):
        raise DocumentError(f"{label}.pairs: expected a list, got {typename(pairs)}")
    if G * (len(pairs) + 3) > MAX_STATE_CYCLES:
        raise DocumentError(f"{label}.pairs: {len(pairs)} pairs of {G} cycles exceed the "
                            f"file's bound of {MAX_STATE_CYCLES} rows")
    raw = _get(doc, "excited", label)
    excited = None if raw is None else _read_run(raw, f"{label}.excited", G,
                                                 ("u_m", "e_m", "measured"))
    if pairs and excited is None:
        raise DocumentError(f"{label}.pairs: pairs of the re-identification without the "
                            "excited run (excited is null)")
    read = [_read_run(p, f"{label}.pairs[{i}]", G, ("du_m", "de_m", "mask"))
            for i, p in enumerate(pairs)]
    sup = _get(doc, "supervisor", label)
    best = None
    if sup is not None:
        if not isinstance(sup, dict):
            raise DocumentError(f"{label}.supervisor: expected an object or null, got "
                                f"{typename(sup)}")
        rms = _number(sup, "rms_m", f"{label}.supervisor")
        if rms < 0:
            raise DocumentError(f"{label}.supervisor.rms_m must be ≥ 0, got {rms!r}")
        best = (rms, _rows(_get(sup, "u_m", f"{label}.supervisor"),
                           f"{label}.supervisor.u_m", G),
                _rows(_get(sup, "e_m", f"{label}.supervisor"), f"{label}.supervisor.e_m", G))
    prior, noise, history, scale, power = _read_weighting_state(_get(doc, "weighting", label),
                                                  f"{label}.weighting",
                                                  learning.prior_shape())
    raw = doc.get("identifying")
    identifying = None if raw is None else _read_run(raw, f"{label}.identifying", G,
                                                     ("u_m", "e_m", "measured"))
    if identifying is not None and (excited is not None or read or best is not None):
        raise DocumentError(f"{label}.identifying: the run before the identifying one in a "
                            "learning that has identified its plant (excited, pairs or "
                            "supervisor set)")
    return InverseState(excited, read, best, prior, noise, history, identifying, scale,
                        power)
