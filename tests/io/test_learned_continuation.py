"""A learning by the inverse law with its defaults (re-identification after each run, the
input weighted by its Kalman gain) saved in a learned file (format version 3), read back
and continued, goes on exactly as the learning that was never interrupted: the same
offsets, the same re-identified plant, the same weighting state — on a small synthetic
plant, the tracker's noise seeded per run (what ``plugcell path run --learned FILE
--learn N`` does: :func:`~plugcell.io.learned_paths.load_learned` then
:meth:`~plugcell.io.learned_paths.LearnedFile.continued`)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from plugcell.compensation.tracking.learning import (
    InverseSettings,
    IterativeLearning,
    LearningSettings,
)
from plugcell.compensation.tracking.plant import ModalPlant
from plugcell.io.json_fields import strict
from plugcell.io.learned_paths import (
    LearnedContext,
    LearnedFile,
    LearnedFileError,
    load_learned,
    save_learned,
)

T = 0.004
J = np.array([[1.0, 0.3, 0.1], [-0.2, 0.9, 0.2], [0.1, -0.1, 1.1]])
#: the arm: two cycles of dead time, a mode at 10 Hz (ζ 0.05), the axes mixed by J
_HEAD = np.zeros((3, 3, 3))
_HEAD[2] = 0.2 * J
TRUE = ModalPlant(T, _HEAD, np.array([10.0]), np.array([0.05]),
                  np.array([[0.05 * J, -0.03 * J]]))
SETTINGS = LearningSettings(gain=0.8, lead_s=0.008, cutoff_hz=6.0, order=4, gain_decay=0.5,
                            post_s=0.15, max_offset_m=5e-3,
                            inverse=InverseSettings(modes=1, taps=4, seed=3))
CONTEXT = LearnedContext("line.csv", "0" * 64, (100.0,), "smart_h4", (0.0,) * 6, 36.0,
                         "nominal", False, "model", "6dof", 1.0)


def disturbance(g: np.ndarray) -> np.ndarray:
    """The path's repeating error: slow, and the mode rung at the start."""
    after = np.clip(g, 0.0, None)
    return np.column_stack([1e-4 * np.sin(2 * np.pi * g), 5e-5 * np.cos(3 * g),
                            3e-5 * np.sin(2 * np.pi * 10 * after) * np.exp(-3 * after)])


def run(lr: IterativeLearning, k: int) -> None:
    """Run ``k`` of the path (its noise seeded by ``k``), learned from."""
    e = disturbance(lr.grid) + TRUE.simulate(lr.u)
    lr.learn_error(e + 10e-6 * np.random.default_rng(50 + k).standard_normal(e.shape))


def run_both(part: IterativeLearning, whole: IterativeLearning, runs: range) -> None:
    """Runs ``runs`` of the continued and the uninterrupted learning: the same offset and
    the same re-identified plant after every run, to the arithmetic's precision (the
    offset is in mm in the file: an ulp from ×1000 and back, which the mode search's
    stopping tolerance carries into the plant's coefficients — ≤ 5e-9 of each array's
    largest with numpy 2.4.6 / SciPy 1.17.1; compared to 1e-6 of it: an entry near zero,
    the head's first, moved by 1.5e-5 of itself in the fresh install of 2026-11-28 and
    not in the CI run of the day before, and a relative tolerance per entry took that
    for a different plant)."""
    for k in runs:
        run(whole, k)
        run(part, k)
        np.testing.assert_allclose(part.u, whole.u, rtol=0, atol=1e-11)
        for name in ("head", "frequency_hz", "damping", "residues"):
            want = getattr(whole.plant, name)
            np.testing.assert_allclose(getattr(part.plant, name), want, rtol=0,
                                       atol=1e-6 * float(np.abs(want).max()))


def test_the_defaults_are_both_options():
    s = LearningSettings(inverse=InverseSettings())
    assert s.inverse.reidentify == 1 and s.weighting is not None
    assert SETTINGS.weighting == s.weighting


@pytest.mark.slow  # five identifications of the plant (≈ 10 s)
def test_a_continued_file_goes_on_as_the_uninterrupted_learning(tmp_path):
    whole = IterativeLearning(1.0, SETTINGS)
    for k in range(3):
        run(whole, k)
    assert [h["law"] for h in whole.history] == ["p", "inverse", "inverse"]
    save_learned(tmp_path / "l.json", LearnedFile(CONTEXT, whole, []))
    back = load_learned(tmp_path / "l.json")
    assert back.learning.settings == SETTINGS
    part = back.continued()
    saved = part.inverse_state()
    assert len(saved.pairs) == 2 and saved.excited is not None and saved.prior is not None
    run_both(part, whole, range(3, 6))
    a, b = part.inverse_state(), whole.inverse_state()
    assert len(a.pairs) == len(b.pairs) == 5
    np.testing.assert_allclose(a.prior, b.prior, rtol=1e-5, atol=1e-6 * b.prior.max())
    assert a.weighting_history[-1]["mean_gain"] == pytest.approx(
        b.weighting_history[-1]["mean_gain"], rel=1e-5)
    assert (part.inverse_steps, part.regularisation_scale, part.steps) == \
        (whole.inverse_steps, whole.regularisation_scale, whole.steps)
    # without the state (as a version-2 file) the same runs go elsewhere: the state matters
    v2 = IterativeLearning(1.0, dataclasses.replace(SETTINGS, weighting=None),
                           back.learning.plant)
    v2.u = back.learning.u.copy()
    v2.resume_inverse(back.learning.inverse_steps, back.learning.regularisation_scale)
    for k in range(3, 6):
        run(v2, k)
    assert np.abs(v2.u - whole.u).max() > 1e-7


@pytest.mark.slow  # three identifications of the plant (≈ 6 s)
def test_a_file_saved_before_its_identifying_run_goes_on_with_the_identification(tmp_path):
    """A robot program's tracked move learns one run a program run: its file is saved
    after the first update, whose offset carries the excitation — the next program run is
    the identifying run, the identification's reference the run before it."""
    whole = IterativeLearning(1.0, SETTINGS)
    run(whole, 0)
    assert whole.identifying_next and whole.plant is None
    save_learned(tmp_path / "l.json", LearnedFile(CONTEXT, whole, []))
    doc_state = load_learned(tmp_path / "l.json").document()["inverse"]["state"]
    assert doc_state["identifying"] is not None and doc_state["excited"] is None
    part = load_learned(tmp_path / "l.json").continued()
    assert part.identifying_next and part.plant is None
    np.testing.assert_allclose(part.u, whole.u, rtol=0, atol=1e-11)  # with the excitation
    run_both(part, whole, range(1, 4))
    assert [h["law"] for h in part.history] == ["inverse"] * 3
    assert not part.identifying_next and part.inverse_state().identifying is None
    # without the run before it, the file cannot be continued by the inverse law
    doc = load_learned(tmp_path / "l.json").document()
    doc["inverse"]["state"]["identifying"] = None
    (tmp_path / "m.json").write_text(json.dumps(strict(doc)))
    with pytest.raises(ValueError, match="no identifying run ahead"):
        load_learned(tmp_path / "m.json").continued()


def test_the_run_before_the_identifying_one_is_refused_beside_an_identified_state(tmp_path):
    whole = IterativeLearning(1.0, SETTINGS)
    run(whole, 0)
    doc = LearnedFile(CONTEXT, whole, []).document()
    doc["inverse"]["state"]["excited"] = doc["inverse"]["state"]["identifying"]
    (tmp_path / "x.json").write_text(json.dumps(strict(doc)))
    with pytest.raises(LearnedFileError, match=r"inverse\.state\.identifying: the run before"):
        load_learned(tmp_path / "x.json")
    doc["inverse"]["state"]["excited"] = None
    doc["inverse"]["state"]["identifying"]["measured"] = "01"
    (tmp_path / "y.json").write_text(json.dumps(strict(doc)))
    with pytest.raises(LearnedFileError, match=r"inverse\.state\.identifying\.measured"):
        load_learned(tmp_path / "y.json")
