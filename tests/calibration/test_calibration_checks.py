"""Argument and post-condition checks of the calibration helpers that must hold under
``python -O`` too: explicit exceptions, not ``assert`` or a later ``UnboundLocalError``."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from plugcell.calibration import simulation
from plugcell.calibration.identifiability import random_configurations
from plugcell.calibration.identify import CalibrationError, Calibrator
from plugcell.calibration.initial import estimate_base_probe_positions
from plugcell.calibration.model import ErrorModel


def _flange_and_points(n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    F = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    F[:, :3, 3] = rng.normal(0.0, 0.5, (n, 3))
    return F, F[:, :3, 3] + 0.1


@pytest.mark.parametrize("iterations", [0, -1])
def test_estimate_base_probe_positions_refuses_no_iteration(iterations):
    F, P = _flange_and_points()
    with pytest.raises(ValueError, match="iterations must be ≥ 1"):
        estimate_base_probe_positions(F, P, iterations=iterations)


def test_estimate_base_probe_positions_one_iteration_runs():
    F, P = _flange_and_points()
    est = estimate_base_probe_positions(F, P, iterations=1)
    assert est.base.shape == (4, 4) and np.isfinite(est.rms)


@pytest.mark.parametrize("missing", ["identifiability", "calibration"])
def test_simulated_identification_checks_its_fit_without_assert(h4, monkeypatch, missing):
    fit = Calibrator.fit

    def fit_without(self, data, *args, **kwargs):  # type: ignore[no-untyped-def]
        return dataclasses.replace(fit(self, data, *args, **kwargs), **{missing: None})

    monkeypatch.setattr(Calibrator, "fit", fit_without)
    q = random_configurations(ErrorModel.create(h4, "loop"), 40, seed=1)
    with pytest.raises(CalibrationError, match=missing):
        simulation.simulated_identification(h4, {}, q, model="loop")


def test_updated_refuses_keys_without_a_step_of_their_length():
    # before: keys without step set those parameters to NaN silently
    from plugcell.io.robots import load_robot

    m = ErrorModel.create(load_robot("smart_h4"), "loop")
    keys = list(m.space.keys[:2])
    with pytest.raises(ValueError, match="needs step"):
        m.updated(keys=keys)
    with pytest.raises(ValueError, match="1 increment"):
        m.updated(keys=keys, step=[1e-3])
    moved = m.updated(keys=keys, step=[1e-3, -2e-3])
    assert np.all(np.isfinite(moved.values))
    np.testing.assert_allclose(np.asarray(moved.values)[m.space.indices(keys)],
                               np.asarray(m.values)[m.space.indices(keys)] + [1e-3, -2e-3])
