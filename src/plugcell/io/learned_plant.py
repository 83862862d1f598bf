"""The inverse learning law's state in a learned-correction file (``"inverse"`` of
:mod:`plugcell.io.learned_paths`, format versions 2 and 3): what continuing a learning by
the norm-optimal inverse law (3) of :mod:`plugcell.compensation.tracking.learning` needs::

    "inverse": {"settings": {"gain": 1.0, "regularisation": 0.05, …},  # InverseSettings
                "steps": 3,                    # updates by (3) so far (γ_j's j)
                "regularisation_scale": 1.0,   # β's factor after the supervisor's back-offs
                "plant": null | {              # the identified ModalPlant, (2) of plant.py
                    "cycle_s": 0.004,          # T (s), the learning's cycle
                    "head": [[[…3]…3]…K],      # D[k, i, j] (m/m), 1 ≤ K ≤ 200, |D| ≤ 1e6
                    "frequency_hz": [f_m…],    # 0 < f_m < 1/(2T)  (M ≤ 12)
                    "damping": [ζ_m…],         # 0 < ζ_m < 1
                    "residues": [[B, C]…M],    # each 3×3 (m/m)
                    "fit": R² | null},
                "weighting": null | {…},       # version 3: WeightingSettings
                "state": {…}}                  # version 3: the runs, the supervisor, S_j

(``weighting`` and ``state``: :mod:`plugcell.io.learned_state`; a version-2 file has
neither: its law learned all of the error, and it goes on without re-identifying.)
``plant`` is null until the identifying run was learned from (a learning saved between
its excited run and the identification cannot go on by (3)).  Every value is checked on
reading (shapes, finite numbers, the bounds above): a
:class:`~plugcell.io.json_fields.DocumentError` naming the dotted key.  SI inside, as in
the document.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.compensation.tracking.learning import InverseSettings, IterativeLearning
from plugcell.compensation.tracking.plant import ModalPlant
from plugcell.io.json_fields import (
    DocumentError,
    at,
    integer,
    number,
    typename,
)
from plugcell.io.learned_state import state_document, weighting_document

Array = NDArray[np.float64]

__all__ = ["inverse_document", "plant_document", "read_inverse", "read_plant"]

#: The largest FIR head and the most modes a saved plant may have (identify_plant's bounds).
MAX_TAPS, MAX_MODES = 200, 12
#: The largest coefficient of a saved plant (m/m): an arm answers an offset with a gain of
#: order 1 (≈ 12 at a resonance); beyond this a file is corrupt, not a plant.
MAX_GAIN = 1e6
KEY = "inverse"


def plant_document(plant: ModalPlant) -> dict[str, Any]:
    """The JSON object of an identified plant (module docstring).

    Parameters
    ----------
    plant : ModalPlant

    Returns
    -------
    dict
        Nested lists of floats (``fit`` NaN stays NaN: the writer makes it null).
    """
    return {"cycle_s": float(plant.cycle_s), "head": np.asarray(plant.head, float).tolist(),
            "frequency_hz": np.asarray(plant.frequency_hz, float).tolist(),
            "damping": np.asarray(plant.damping, float).tolist(),
            "residues": np.asarray(plant.residues, float).tolist(), "fit": float(plant.fit)}


def inverse_document(learning: IterativeLearning) -> dict[str, Any] | None:
    """``"inverse"`` of a learning with the law (3) (None: the P-type law alone).

    Parameters
    ----------
    learning : IterativeLearning

    Returns
    -------
    dict or None

    Raises
    ------
    ValueError
        A state beyond the file's bound (:func:`~plugcell.io.learned_state.state_document`).
    """
    inv = learning.settings.inverse
    if inv is None:
        return None
    return {"settings": dataclasses.asdict(inv), "steps": learning.inverse_steps,
            "regularisation_scale": learning.regularisation_scale,
            "plant": None if learning.plant is None else plant_document(learning.plant),
            "weighting": weighting_document(learning.settings.weighting),
            "state": state_document(learning)}


def _tensor(x: Any, label: str, shape: tuple[int | None, ...]) -> Array:
    """``x`` as a float array of ``shape`` (None: any length ≥ 0), every element a finite
    number; a DocumentError naming the first wrong element otherwise."""
    if not shape:
        return np.array(number({label: x}, label))
    if not isinstance(x, list):
        raise DocumentError(f"{label}: expected a list, got {typename(x)}")
    want = shape[0]
    if want is not None and len(x) != want:
        raise DocumentError(f"{label}: expected {want} entries, got {len(x)}")
    rows = [_tensor(v, f"{label}[{i}]", shape[1:]) for i, v in enumerate(x)]
    if not rows:
        return np.zeros((0, *(s or 0 for s in shape[1:])))
    return np.stack(rows)


def read_plant(doc: Any, cycle_s: float, label: str = f"{KEY}.plant") -> ModalPlant:
    """An identified plant from its JSON object (module docstring), for a learning of
    cycle ``cycle_s`` (s).

    Parameters
    ----------
    doc : object
        The parsed JSON value.
    cycle_s : float
        The learning's cycle ``T`` (s): the plant's must be the same.
    label : str
        The dotted key, for messages.

    Returns
    -------
    ModalPlant

    Raises
    ------
    DocumentError
        A missing or wrong key (named), shapes that do not agree, a mode out of bounds.
    """
    if not isinstance(doc, dict):
        raise DocumentError(f"{label}: expected an object, got {typename(doc)}")
    T = number(doc, "cycle_s")
    if abs(T - cycle_s) > 1e-12:
        raise DocumentError(f"{label}.cycle_s: {T!r} s is not the learning's cycle {cycle_s:g} s")
    head = _tensor(at(doc, "head"), f"{label}.head", (None, 3, 3))
    if not 1 <= head.shape[0] <= MAX_TAPS:
        raise DocumentError(f"{label}.head: expected 1–{MAX_TAPS} taps, got {head.shape[0]}")
    f = _tensor(at(doc, "frequency_hz"), f"{label}.frequency_hz", (None,))
    if f.size > MAX_MODES:
        raise DocumentError(f"{label}.frequency_hz: at most {MAX_MODES} modes, got {f.size}")
    z = _tensor(at(doc, "damping"), f"{label}.damping", (f.size,))
    res = _tensor(at(doc, "residues"), f"{label}.residues", (f.size, 2, 3, 3))
    for name, x in (("head", head), ("residues", res)):
        if x.size and float(np.abs(x).max()) > MAX_GAIN:
            raise DocumentError(f"{label}.{name}: a coefficient beyond ±{MAX_GAIN:g} (m/m)")
    nyq = 0.5 / T
    for i in range(f.size):
        if not 0 < f[i] < nyq:
            raise DocumentError(f"{label}.frequency_hz[{i}]: {float(f[i])!r} Hz must lie in "
                                f"(0, {nyq:g}) Hz")
        if not 0 < z[i] < 1:
            raise DocumentError(f"{label}.damping[{i}]: {float(z[i])!r} must lie in (0, 1) "
                                "(a stable, lightly damped mode)")
    fit = at(doc, "fit")
    fit = math.nan if fit is None else number(doc, "fit")
    return ModalPlant(T, head, f.reshape(-1), z.reshape(-1), res.reshape(f.size, 2, 3, 3),
                      fit)


def read_inverse(doc: dict[str, Any]) -> tuple[InverseSettings, int, float, Any]:
    """``"inverse"`` of a document, checked, except against the learning's cycle.

    Parameters
    ----------
    doc : dict
        The whole document (its ``inverse`` key read).

    Returns
    -------
    settings : InverseSettings
    steps : int
        Updates by (3) so far.
    regularisation_scale : float
        ``β``'s factor (≥ 1).
    plant : object
        The plant's raw JSON value (read it with :func:`read_plant` once the cycle is
        known), None when not identified yet.

    Raises
    ------
    DocumentError
        A missing or wrong key (named), settings the law refuses.
    """
    values: dict[str, Any] = {}
    for f in fields(InverseSettings):
        values[f.name] = integer(doc, KEY, "settings", f.name) \
            if f.type in ("int", int) else number(doc, KEY, "settings", f.name)
    try:
        settings = InverseSettings(**values)
    except ValueError as exc:
        raise DocumentError(f"{KEY}.settings: {exc}") from None
    steps = integer(doc, KEY, "steps")
    if steps < 0:
        raise DocumentError(f"{KEY}.steps must be ≥ 0, got {steps}")
    scale = number(doc, KEY, "regularisation_scale")
    if not scale >= 1:
        raise DocumentError(f"{KEY}.regularisation_scale must be ≥ 1, got {scale!r}")
    return settings, steps, scale, at(doc, KEY, "plant")
