"""The weighting's inflation (5) in a learned file: its settings and state (``c_j``, the
last record's power) are saved and a continued learning goes on exactly; a file written
before them (no ``adapt_max``/``adapt_step``, no ``scale``/``power``) loads as the law
without inflation; a wrong ``scale`` is refused with its key."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from test_learned_continuation import CONTEXT, SETTINGS, run, run_both

from plugcell.compensation.tracking import WeightingSettings
from plugcell.compensation.tracking.learning import DEFAULT_WEIGHTING, IterativeLearning
from plugcell.io.learned_paths import LearnedFile, LearnedFileError, load_learned, save_learned

ADAPT = dataclasses.replace(SETTINGS, weighting=WeightingSettings(
    adapt_max=4.0, adapt_step=2.0, adapt_margin=0.5, detect=3.0, detect_fell=1))


def saved(tmp_path, settings, runs: int):
    whole = IterativeLearning(1.0, settings)
    for k in range(runs):
        run(whole, k)
    save_learned(tmp_path / "l.json", LearnedFile(CONTEXT, whole, []))
    return whole


@pytest.mark.slow  # five identifications of the plant (≈ 10 s)
def test_a_continued_file_with_the_inflation_goes_on_exactly(tmp_path):
    whole = saved(tmp_path, ADAPT, 4)
    doc = json.loads((tmp_path / "l.json").read_text())
    assert doc["inverse"]["weighting"]["adapt_max"] == 4.0
    assert doc["inverse"]["state"]["weighting"]["scale"] is not None
    back = load_learned(tmp_path / "l.json")
    assert back.learning.settings == ADAPT
    assert type(back.learning.settings.weighting.detect_fell) is int
    part = back.continued()
    a = part.inverse_state()
    np.testing.assert_array_equal(a.scale, whole.inverse_state().scale)
    run_both(part, whole, range(4, 6))
    a, b = part.inverse_state(), whole.inverse_state()
    np.testing.assert_array_equal(a.scale, b.scale)
    assert np.any(b.scale > 1.0)


@pytest.mark.slow  # three identifications of the plant (≈ 6 s)
def test_a_file_from_before_the_inflation_loads_as_the_law_without_it(tmp_path):
    saved(tmp_path, SETTINGS, 3)
    doc = json.loads((tmp_path / "l.json").read_text())
    for key in ("adapt_max", "adapt_step", "adapt_margin"):
        del doc["inverse"]["weighting"][key]
    for key in ("scale", "power"):
        del doc["inverse"]["state"]["weighting"][key]
    (tmp_path / "old.json").write_text(json.dumps(doc))
    back = load_learned(tmp_path / "old.json")
    assert back.learning.settings.weighting == DEFAULT_WEIGHTING
    state = back.continued().inverse_state()
    assert state.scale is None and state.power is None
    # a scale below 1 is refused, named
    doc = json.loads((tmp_path / "l.json").read_text())
    n = len(doc["inverse"]["state"]["weighting"]["prior"])
    doc["inverse"]["state"]["weighting"]["scale"] = [0.5] * n
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(LearnedFileError, match=r"inverse\.state\.weighting\.scale"):
        load_learned(tmp_path / "bad.json").continued()
    doc = json.loads((tmp_path / "l.json").read_text())
    doc["inverse"]["weighting"]["detect_fell"] = 2
    (tmp_path / "bad2.json").write_text(json.dumps(doc))
    with pytest.raises(LearnedFileError, match="detect_fell must be 0 or 1"):
        load_learned(tmp_path / "bad2.json")
