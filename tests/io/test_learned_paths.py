"""The learned-correction file of ``plugcell path run --learned-out`` (plugcell.io.learned_paths):
round trip, the context's refusals with their precise reasons, corrupt files (and, with
hypothesis, any text and any mutation of a valid document: a LearnedFileError or a
correction that loads, never another exception)."""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plugcell.compensation.tracking.learning import (
    DEFAULT_WEIGHTING,
    InverseSettings,
    InverseState,
    IterativeLearning,
    LearningSettings,
)
from plugcell.compensation.tracking.plant import ModalPlant
from plugcell.compensation.tracking.repeat import RunRecord
from plugcell.compensation.tracking.smoothing import WeightingSettings
from plugcell.io.json_fields import strict
from plugcell.io.learned_paths import (
    LearnedContext,
    LearnedFile,
    LearnedFileError,
    load_learned,
    path_sha256,
    run_entries,
    save_learned,
)
from plugcell.io.path_files import parse_path

PATH = "x,y,z,speed\n1473.3,-231.7,2488.4,\n1473.3,-131.7,2488.4,100\n"
SETTINGS = LearningSettings(gain=0.8, cutoff_hz=6.0, order=4, gain_decay=0.5, post_s=0.15,
                            max_offset_m=5e-3)


def _context(**kw) -> LearnedContext:
    path = parse_path(PATH, "line.csv")
    base = LearnedContext("line.csv", path_sha256(path), (100.0,), "smart_h4",
                          (0.0, 0.0, 0.0, 0.0, 0.0, 0.0), 36.0, "nominal", False, "tracking",
                          "6dof", 1.0)
    return dataclasses.replace(base, **kw)


def _file() -> LearnedFile:
    lr = IterativeLearning(1.0, SETTINGS)
    lr.u = 1e-4 * np.sin(np.outer(lr.grid, [1.0, 2.0, 3.0]))
    lr.steps = 3
    runs = run_entries([RunRecord(1, 3e-4, 5e-4, 1.0, 1e-4, "learned"),
                        RunRecord(2, 1e-4, 2e-4, 0.9, float("nan"), "diverged", "why")], [])
    return LearnedFile(_context(), lr, runs, best=(1e-4, 0.5 * lr.u, 2))


def _document() -> dict:
    return json.loads(json.dumps(_file().document()))


def test_round_trip(tmp_path):
    f = _file()
    save_learned(tmp_path / "l.json", f)
    back = load_learned(tmp_path / "l.json")
    assert back.context == f.context and back.context.mismatch(f.context) is None
    assert back.learning.settings == SETTINGS and back.learning.steps == 3
    np.testing.assert_allclose(back.learning.u, f.learning.u, atol=1e-9)  # 1 nm in the file
    assert [r["run"] for r in back.runs] == [1, 2]
    assert back.runs[1]["change_max_mm"] is None  # NaN written as null (strict JSON)
    # the stop rule's best run (version 2): its rms, the offset it ran with, its steps
    assert back.best[0] == pytest.approx(1e-4) and back.best[2] == 2
    np.testing.assert_allclose(back.best[1], 0.5 * f.learning.u, atol=1e-9)
    # the offset fed forward is the one saved
    ff = back.learning.feedforward(5.0)
    np.testing.assert_allclose(ff(5.0 + 0.5), f.learning.feedforward(5.0)(5.5), atol=1e-9)


def test_the_path_hash_is_the_geometry_not_the_text():
    a = parse_path(PATH, "a.csv")
    b = parse_path("# the same line\nspeed,z,y,x\n,2488.4,-231.7,1473.3\n"
                   "250,2488.4,-131.7,1473.3\n", "b.csv")
    c = parse_path(PATH.replace("-131.7", "-131.6"), "c.csv")
    assert path_sha256(a) == path_sha256(b) != path_sha256(c)


@pytest.mark.parametrize(("change", "reason"), [
    ({"path": "other.csv", "path_sha256": "f" * 64},
     "it was learned on the path 'line.csv' (sha256 "),
    ({"speeds_mm_s": (250.0,)}, "segment 1 was learned at 100 mm/s, this run goes 250 mm/s"),
    ({"speeds_mm_s": (100.0, 100.0)}, "it was learned for 1 segments, the path has 2"),
    ({"robot": "kr16"}, "it was learned on the robot 'smart_h4', this run is on 'kr16'"),
    ({"tool_mm_deg": (0.0, 0.0, 100.0, 0.0, 0.0, 0.0)},
     "it was learned with the tool (0.000, 0.000, 0.000, 0.000, 0.000, 0.000), this run's "
     "is (0.000, 0.000, 100.000, 0.000, 0.000, 0.000) (mm, deg)"),
    ({"payload_kg": 20.0}, "it was learned with a payload of 36 kg, this run carries 20 kg"),
    ({"calibration": "sha256:" + "a" * 64},
     "it was learned with the calibration nominal (no PARAMS.json), this run uses "
     "sha256:aaaaaaaaaaaa… without residual layer"),
    ({"loop": "model"}, "it was learned with the loop 'tracking', this run's is 'model'"),
    ({"reflector": "3dof"}, "it was learned with the reflector '6dof', this run's is '3dof'"),
    ({"duration_s": 1.5}, "it was learned on a motion of 1.0000 s, this run's takes 1.5000 s"),
])
def test_a_context_that_differs_is_refused_with_the_reason(change, reason):
    assert reason in _context().mismatch(_context(**change))


def _write(tmp_path, doc) -> str:
    p = tmp_path / "l.json"
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return str(p)


def _mutated(**edits):
    doc = _document()
    for key, value in edits.items():
        *parents, last = key.split(".")
        d = doc
        for k in parents:
            d = d[k]
        if value is KeyError:
            del d[last]
        else:
            d[last] = value
    return doc


INVERSE = InverseSettings(gain=0.9, regularisation=0.02, modes=2, taps=3, seed=7)


def _plant() -> ModalPlant:
    rng = np.random.default_rng(3)
    return ModalPlant(SETTINGS.cycle_s, rng.normal(0, 0.1, (3, 3, 3)),
                      np.array([9.2, 13.7]), np.array([0.04, 0.06]),
                      rng.normal(0, 0.01, (2, 2, 3, 3)), 0.93)


def _inverse_file(plant: ModalPlant | None = None) -> LearnedFile:
    """An inverse-law learning with its plant identified and 2 updates by (3), β backed
    off once."""
    lr = IterativeLearning(1.0, dataclasses.replace(SETTINGS, inverse=INVERSE),
                           _plant() if plant is None else plant)
    lr.u = _file().learning.u
    lr.steps = 3
    lr.resume_inverse(2, 10.0)
    return LearnedFile(_context(), lr, [])


def test_the_law_is_recorded_and_read_back(tmp_path):
    """``law``: the learning's own (``inverse`` when its settings have InverseSettings);
    a file without the key is ``p``; a version-1 file of the inverse law (no plant) is
    read with the P-type settings, ``law`` says ``inverse``, and is continued only by the
    P-type law."""
    assert _file().document()["law"] == "p" and load_learned(_write(tmp_path, _document())
                                                             ).law == "p"
    assert "inverse" not in _document()
    assert load_learned(_write(tmp_path, _mutated(law=KeyError))).law == "p"
    v1 = _mutated(law="inverse", format_version=1)
    back = load_learned(_write(tmp_path, v1))
    assert back.law == "inverse" and back.learning.settings == SETTINGS
    assert back.continued("p") is back.learning
    with pytest.raises(ValueError, match=r"it was learned with the inverse law but holds no "
                       r"identified plant .* continue it by the P-type law or start anew"):
        back.continued()
    with pytest.raises(ValueError, match="law: expected one of p, inverse, got 'x'"):
        LearnedFile(_context(), _file().learning, [], "x")


def _stated_file() -> LearnedFile:
    """An inverse-law learning with the defaults (re-identification, the weighting) in the
    middle of its runs: the excited run, two pairs, the supervisor's best run, the
    weighting's S_j — a state made by hand (no identification: fast)."""
    f = _inverse_file()
    lr = f.learning
    G = lr.grid.size
    rng = np.random.default_rng(11)

    def run() -> tuple:
        m = np.ones(G, bool)
        m[40:50] = False
        return rng.normal(0, 1e-5, (G, 3)), rng.normal(0, 2e-5, (G, 3)), m

    state = InverseState(excited=run(), pairs=[run(), run()],
                         best=(2.5e-5, rng.normal(0, 1e-5, (G, 3)), rng.normal(0, 1e-5, (G, 3))),
                         prior=rng.uniform(0, 1e-9, lr.prior_shape()), noise=3e-10,
                         weighting_history=[{"noise": 3e-10, "mean_gain": 0.4,
                                             "rematched": 0.0}])
    lr.resume_inverse(2, 10.0, state)
    return f


def test_the_weighting_and_the_reidentifications_runs_are_saved_and_go_on(tmp_path):
    """Version 3: the weighting's settings and state (S_j, N, its history) and the
    re-identification's runs (the excited run, the pairs) and the supervisor's best run
    are written at full precision and read back; the next update is the same."""
    f = _stated_file()
    doc = f.document()
    assert doc["format_version"] == 3 and doc["inverse"]["weighting"]["smooth_hz"] == 0.5
    st = doc["inverse"]["state"]
    assert len(st["pairs"]) == 2 and st["excited"]["measured"][38:52] == "11" + "0" * 10 + "11"
    save_learned(tmp_path / "s.json", f)
    back = load_learned(tmp_path / "s.json")
    lr, lb = f.learning, back.learning
    assert lb.settings == lr.settings and lb.settings.weighting == DEFAULT_WEIGHTING
    a, b = lr.inverse_state(), lb.inverse_state()
    for x, y in zip([*a.excited, *(v for p in a.pairs for v in p), *a.best[1:], a.prior],
                    [*b.excited, *(v for p in b.pairs for v in p), *b.best[1:], b.prior],
                    strict=True):
        np.testing.assert_array_equal(x, y)  # exactly: the state is SI at full precision
    assert (b.best[0], b.noise, b.weighting_history) == (a.best[0], a.noise,
                                                         a.weighting_history)
    e = 2e-5 * np.cos(np.outer(lr.grid, [3.0, 1.0, 2.0]))
    np.testing.assert_allclose(lb.step(e), lr.step(e), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(lb.inverse_state().prior, lr.inverse_state().prior)
    # per tile: S_j is (bins, tiles)
    tiles = dataclasses.replace(SETTINGS, inverse=INVERSE,
                                weighting=WeightingSettings(window_s=0.25))
    t = IterativeLearning(1.0, tiles, _plant())
    t.step(e)
    assert t.inverse_state().prior.ndim == 2
    save_learned(tmp_path / "t.json", LearnedFile(_context(), t, []))
    tb = load_learned(tmp_path / "t.json").learning
    np.testing.assert_array_equal(tb.inverse_state().prior, t.inverse_state().prior)
    np.testing.assert_allclose(tb.step(e), t.step(e), rtol=0, atol=1e-15)
    # no weighting: null, read back as none
    none = LearnedFile(_context(), IterativeLearning(
        1.0, dataclasses.replace(tiles, weighting=None), _plant()), [])
    assert none.document()["inverse"]["weighting"] is None
    save_learned(tmp_path / "n.json", none)
    assert load_learned(tmp_path / "n.json").learning.settings.weighting is None


def test_a_version_2_file_goes_on_unweighted_and_without_its_runs(tmp_path):
    """A version-2 file of the inverse law learned all of the error: it is read with no
    weighting, and, holding no runs, goes on without re-identifying."""
    doc = json.loads(json.dumps(strict(_stated_file().document())))
    doc["format_version"] = 2
    del doc["inverse"]["weighting"], doc["inverse"]["state"]
    back = load_learned(_write(tmp_path, doc))
    lb = back.learning
    assert lb.settings.weighting is None and lb.settings.inverse == INVERSE
    s = lb.inverse_state()
    assert (s.excited, s.pairs, s.best, s.prior) == (None, [], None, None)
    assert back.continued() is lb and lb.plant is not None


def test_a_state_beyond_the_files_bound_is_refused_on_writing_and_reading(tmp_path,
                                                                          monkeypatch):
    import plugcell.io.learned_state as ls

    f = _stated_file()
    doc = json.loads(json.dumps(strict(f.document())))
    G = f.learning.grid.size
    monkeypatch.setattr(ls, "MAX_STATE_CYCLES", 4 * G)  # excited + 2 pairs + supervisor: 5 G
    with pytest.raises(ValueError, match=r"holds 2 pairs of runs of 363 cycles \(1815 rows\); "
                       r"a learned file holds at most 1452: learn this path with "
                       r"InverseSettings.reidentify 0"):
        f.document()
    with pytest.raises(LearnedFileError, match=r"inverse.state.pairs: 2 pairs of 363 cycles "
                       r"exceed the file's bound of 1452 rows"):
        load_learned(_write(tmp_path, doc))


def test_the_inverse_law_keeps_its_plant_and_goes_on(tmp_path):
    """Version 2: the inverse law's settings, updates, β's scale and identified plant are
    saved and read back; the learning continues by (3) exactly as the one saved would."""
    f = _inverse_file()
    doc = f.document()
    assert doc["format_version"] == 3 and doc["law"] == "inverse"
    assert doc["inverse"]["steps"] == 2 and doc["inverse"]["regularisation_scale"] == 10.0
    save_learned(tmp_path / "i.json", f)
    back = load_learned(tmp_path / "i.json")
    lr, lb = f.learning, back.learning
    assert back.law == "inverse" and lb.settings == lr.settings and lb.settings.inverse == INVERSE
    assert (lb.inverse_steps, lb.regularisation_scale, lb.steps) == (2, 10.0, 3)
    for name in ("head", "frequency_hz", "damping", "residues"):
        np.testing.assert_array_equal(getattr(lb.plant, name), getattr(lr.plant, name))
    assert lb.plant.fit == lr.plant.fit and back.continued() is lb
    # the same update from the same error (1 nm rounding of u in the file)
    e = 2e-5 * np.cos(np.outer(lr.grid, [3.0, 1.0, 2.0]))
    np.testing.assert_allclose(lb.step(e), lr.step(e), atol=1e-8)
    # continued by the P-type law: the offset and steps kept, no plant
    p = back.continued("p")
    assert p.settings.inverse is None and p.plant is None and p.steps == 4  # one step above
    np.testing.assert_allclose(p.u, lb.u)
    with pytest.raises(ValueError, match="it was learned with the P-type law"):
        _file().continued("inverse")


def test_an_inverse_file_saved_before_the_identification_is_not_continued_by_it(tmp_path):
    lr = IterativeLearning(1.0, dataclasses.replace(SETTINGS, inverse=INVERSE))
    f = LearnedFile(_context(), lr, [])
    assert f.document()["inverse"]["plant"] is None
    save_learned(tmp_path / "i.json", f)
    back = load_learned(tmp_path / "i.json")
    assert back.learning.settings.inverse == INVERSE and back.learning.plant is None
    with pytest.raises(ValueError, match="holds no identified plant"):
        back.continued("inverse")


def _inverse_mutated(**edits):
    doc = json.loads(json.dumps(strict(_inverse_file().document())))
    for key, value in edits.items():
        *parents, last = key.split(".")
        d = doc
        for k in parents:
            d = d[int(k)] if isinstance(d, list) else d[k]
        if value is KeyError:
            del d[last]
        else:
            d[int(last) if isinstance(d, list) else last] = value
    return doc


@pytest.mark.parametrize(("edits", "message"), [
    ({"law": "p"}, "inverse: the state of the inverse law in a file learned with the law 'p'"),
    ({"inverse.settings.gain": 2.0}, "inverse.settings: InverseSettings.gain (γ) must lie in"),
    ({"inverse.settings.modes": 2.5}, "inverse.settings.modes: expected an integer"),
    ({"inverse.settings.cutoff_hz": 300.0}, "inverse.settings: InverseSettings.cutoff_hz "
     "300.0 must lie below the Nyquist rate 125 Hz"),
    ({"inverse.steps": -1}, "inverse.steps must be ≥ 0, got -1"),
    ({"inverse.regularisation_scale": 0.5}, "inverse.regularisation_scale must be ≥ 1"),
    ({"inverse.plant.cycle_s": 0.012}, "inverse.plant.cycle_s: 0.012 s is not the learning's "
     "cycle 0.004 s"),
    ({"inverse.plant.head": []}, "inverse.plant.head: expected 1–200 taps, got 0"),
    ({"inverse.plant.head.1": [[0, 0, 0]] * 2}, "inverse.plant.head[1]: expected 3 entries, "
     "got 2"),
    ({"inverse.plant.head.0.2.1": "x"}, "inverse.plant.head[0][2][1]: expected a finite "
     "number, got the string 'x'"),
    ({"inverse.plant.residues.1.0.2.2": 3e6}, "inverse.plant.residues: a coefficient beyond "
     "±1e+06 (m/m)"),
    ({"inverse.plant.damping": [0.04]}, "inverse.plant.damping: expected 2 entries, got 1"),
    ({"inverse.plant.damping.1": 1.5}, "inverse.plant.damping[1]: 1.5 must lie in (0, 1)"),
    ({"inverse.plant.frequency_hz.0": 200.0}, "inverse.plant.frequency_hz[0]: 200.0 Hz must "
     "lie in (0, 125) Hz"),
    ({"inverse.plant.residues": [[]]}, "inverse.plant.residues: expected 2 entries, got 1"),
    ({"inverse.plant.fit": "good"}, "fit: expected a finite number, got the string 'good'"),
    ({"inverse.plant": 3}, "inverse.plant: expected an object, got the number 3"),
    ({"inverse.settings.seed": KeyError}, "missing key 'inverse.settings.seed'"),
])
def test_a_corrupt_inverse_state_is_refused_naming_the_cause(tmp_path, edits, message):
    with pytest.raises(LearnedFileError) as info:
        load_learned(_write(tmp_path, _inverse_mutated(**edits)))
    assert message in str(info.value)


def _stated_mutated(**edits):
    doc = json.loads(json.dumps(strict(_stated_file().document())))
    for key, value in edits.items():
        *parents, last = key.split(".")
        d = doc
        for k in parents:
            d = d[int(k)] if isinstance(d, list) else d[k]
        key = int(last) if isinstance(d, list) else last
        if value is KeyError:
            del d[key]
        else:
            d[key] = value
    return doc


S = "inverse.state"


@pytest.mark.parametrize(("edits", "message"), [
    ({"inverse.weighting": 3}, "inverse.weighting: expected an object or null, got the number"),
    ({"inverse.weighting.smooth_hz": 0.0}, "inverse.weighting: WeightingSettings: smooth_hz "
     "must be > 0"),
    ({"inverse.weighting.noise_high_hz": 130.0}, "inverse.settings: WeightingSettings."
     "noise_high_hz 130.0 must lie below the Nyquist rate 125 Hz"),
    ({"inverse.weighting.window_s": KeyError}, "missing key 'inverse.weighting.window_s'"),
    ({"inverse.weighting.noise_low_hz": "50"}, "inverse.weighting.noise_low_hz: expected a "
     "finite number, got the string '50'"),
    ({"inverse.state": KeyError}, "missing key 'inverse.state'"),
    ({S: []}, "inverse.state: expected an object, got a list"),
    ({f"{S}.pairs": {}}, "inverse.state.pairs: expected a list, got an object"),
    ({f"{S}.excited": None}, "inverse.state.pairs: pairs of the re-identification without "
     "the excited run"),
    ({f"{S}.excited.u_m": [[0, 0, 0]]}, "inverse.state.excited.u_m: expected 363 rows"),
    ({f"{S}.pairs.1.de_m.5.2": "x"}, "inverse.state.pairs[1].de_m[5][2]: expected a finite "
     "number, got the string 'x'"),
    ({f"{S}.pairs.0.du_m.7": [0, 0]}, "inverse.state.pairs[0].du_m[7]: expected 3 numbers"),
    ({f"{S}.pairs.0.du_m.7.0": 10**400}, "inverse.state.pairs[0].du_m[7][0]: expected a "
     "finite number"),
    ({f"{S}.pairs.0.du_m.7.0": True}, "inverse.state.pairs[0].du_m[7][0]: expected a "
     "finite number, got a boolean"),
    ({f"{S}.pairs.0.mask": "01"}, "inverse.state.pairs[0].mask: expected a string of 363 "
     "characters 0 or 1 (one a cycle of the grid), got 2 characters"),
    ({f"{S}.pairs.0.mask": "2" * 363}, "got 363 characters with others"),
    ({f"{S}.pairs.1": KeyError}, None),  # one pair fewer: a valid state
    ({f"{S}.pairs.0.mask": KeyError}, "missing key 'inverse.state.pairs[0].mask'"),
    ({f"{S}.supervisor.rms_m": -1.0}, "inverse.state.supervisor.rms_m must be ≥ 0"),
    ({f"{S}.supervisor": "best"}, "inverse.state.supervisor: expected an object or null"),
    ({f"{S}.supervisor.e_m": None}, "inverse.state.supervisor.e_m: expected 363 rows of the "
     "learning's grid, got null"),
    ({f"{S}.weighting.prior": [1.0, 2.0]}, "inverse.state.weighting.prior: expected 687 "
     "finite powers ≥ 0 (the weighting's S_j on this learning's bins)"),
    ({f"{S}.weighting.prior.3": -1.0}, "inverse.state.weighting.prior: expected 687"),
    ({f"{S}.weighting.noise": -1.0}, "inverse.state.weighting.noise must be ≥ 0"),
    ({f"{S}.weighting.history": {}}, "inverse.state.weighting.history: expected a list"),
    ({f"{S}.weighting.history.0.mean_gain": "x"}, "inverse.state.weighting.history[0]."
     "mean_gain: expected a finite number"),
    ({f"{S}.weighting.history.0": 1}, "inverse.state.weighting.history[0]: expected an "
     "object, got the number 1"),
    ({"inverse.weighting": None}, "inverse.state.weighting.prior: a weighting state in a "
     "learning without weighting"),
])
def test_a_corrupt_weighting_or_run_state_is_refused_naming_the_cause(tmp_path, edits,
                                                                       message):
    if message is None:
        assert len(load_learned(_write(tmp_path, _stated_mutated(**edits))).learning
                   .inverse_state().pairs) == 1
        return
    with pytest.raises(LearnedFileError) as info:
        load_learned(_write(tmp_path, _stated_mutated(**edits)))
    assert message in str(info.value)


@pytest.mark.parametrize(("doc", "message"), [
    ("{not json", "not a JSON document"),
    ("[1, 2]", "expected a JSON object, got a list"),
    ({"format": "plugcell-tracked-path"}, "format 'plugcell-tracked-path': not a learned "
     "correction (expected 'plugcell-learned-path'"),
    (_mutated(format_version=4), "format_version 4: this plugcell reads versions 1, 2, 3"),
    (_mutated(**{"context.robot": KeyError}), "missing key 'context.robot'"),
    (_mutated(**{"context.payload_kg": "36"}),
     "context.payload_kg: expected a finite number, got the string '36'"),
    (_mutated(**{"context.speeds_mm_s": [100, None]}),
     "context.speeds_mm_s[1]: expected a finite number, got null"),
    (_mutated(**{"context.speeds_mm_s": [-5]}), "context.speeds_mm_s: expected one speed > 0"),
    (_mutated(**{"context.tool_mm_deg": [0, 0, 0]}), "context.tool_mm_deg: expected 6 numbers"),
    (_mutated(**{"context.residual_layer": 0}), "context.residual_layer: expected true or "
     "false, got the number 0"),
    (_mutated(**{"settings.gain": 2.5}), "settings: LearningSettings.gain (L) must lie in (0, 2)"),
    (_mutated(**{"settings.order": 4.0}), "settings.order: expected an integer"),
    (_mutated(steps=-1), "steps must be ≥ 0, got -1"),
    (_mutated(**{"offset.u_mm": [[0, 0, 0]] * 3}), "offset.u_mm: expected 363 rows (the grid "
     "of a 1 s motion), got 3 rows"),
    (_mutated(**{"offset.t0_s": -0.2}), "offset: t0_s -0.2 and cycle_s 0.004 are not the "
     "settings' grid"),
    (_mutated(runs={}), "runs: expected a list of objects, got an object"),
    (_mutated(**{"best.u_mm": [[0, 0, 0]]}), "best.u_mm: expected 363 rows"),
    (_mutated(**{"best.steps": -2}), "best: measured_rms_mm 0.1 and steps -2 must be ≥ 0"),
    (_mutated(**{"best.measured_rms_mm": None}), "best.measured_rms_mm: expected a finite "
     "number, got null"),
    (_mutated(law="q"), "law: expected one of p, inverse, got 'q'"),
    (_mutated(law=None), "law: expected one of p, inverse, got None"),
])
def test_a_corrupt_file_is_refused_naming_the_cause(tmp_path, doc, message):
    with pytest.raises(LearnedFileError) as info:
        load_learned(_write(tmp_path, doc))
    assert str(info.value).startswith(str(tmp_path / "l.json") + ": ")
    assert message in str(info.value)


def test_an_offset_row_that_is_wrong_or_beyond_the_bound_is_named(tmp_path):
    doc = _document()
    doc["offset"]["u_mm"][7] = [0, "x", 0]
    with pytest.raises(LearnedFileError, match=r"offset.u_mm\[7\]\[1\]: expected a finite "):
        load_learned(_write(tmp_path, doc))
    doc["offset"]["u_mm"][7] = [0, 0]
    with pytest.raises(LearnedFileError, match=r"offset.u_mm\[7\]: expected 3 numbers"):
        load_learned(_write(tmp_path, doc))
    doc["offset"]["u_mm"][7] = [0, 6.0, 0]
    with pytest.raises(LearnedFileError, match=r"offset.u_mm\[7\]: \[0, 6.0, 0\] is beyond "
                       r"the settings' bound ±5 mm"):
        load_learned(_write(tmp_path, doc))


@pytest.mark.parametrize("leaf, value", [(("context", "duration_s"), 1e6),
                                         (("settings", "pre_s"), 1e9),
                                         (("settings", "post_s"), 1e308)])
def test_a_learning_window_too_long_to_hold_is_refused_before_it_is_allocated(
        tmp_path, leaf, value):
    """A mutated duration or margin would make a grid of 2.5·10⁸ cycles and more (CI run
    16: the worker was killed; 1e308 raised OverflowError, not the file's error)."""
    doc = _document()
    doc[leaf[0]][leaf[1]] = value
    with pytest.raises(LearnedFileError, match=r"cycles; at most 1048576"):
        load_learned(_write(tmp_path, doc))


def test_an_inverse_pad_too_long_to_hold_is_refused(tmp_path):
    """The inverse law pads the FFT by ``pad_s`` on each side: a mutated pad of 10⁹ s was
    allocated by the first step (a segmentation fault under a memory limit)."""
    doc = json.loads(json.dumps(strict(_inverse_file().document())))
    doc["inverse"]["settings"]["pad_s"] = 1e9
    with pytest.raises(LearnedFileError, match=r"the inverse law's pads of 2 × 1e\+09 s .*"
                                               r"cycles; at most 1048576"):
        load_learned(_write(tmp_path, doc))


def test_a_missing_or_binary_file_is_named(tmp_path):
    with pytest.raises(LearnedFileError, match="no such file"):
        load_learned(tmp_path / "none.json")
    (tmp_path / "b.json").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(LearnedFileError, match="not a UTF-8 text file"):
        load_learned(tmp_path / "b.json")


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.text(max_size=300))
def test_any_text_is_a_learned_file_error_or_a_correction(tmp_path, text):
    with contextlib.suppress(LearnedFileError):
        load_learned(_write(tmp_path, text))


JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() |
                    st.text(max_size=8),
                    lambda inner: st.lists(inner, max_size=4) |
                    st.dictionaries(st.text(max_size=6), inner, max_size=4), max_leaves=8)


def _leaves(doc, prefix=()):
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _leaves(v, (*prefix, k))
    elif isinstance(doc, list) and doc and not isinstance(doc[0], list | dict):
        yield prefix
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:3]):
            yield from _leaves(v, (*prefix, i))
    yield prefix


DOCUMENTS = {"p": _document(),
             "inverse": json.loads(json.dumps(strict(_inverse_file().document()))),
             "stated": json.loads(json.dumps(strict(_stated_file().document())))}
LEAVES = [(k, p) for k, d in DOCUMENTS.items() for p in _leaves(d) if p]


@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from(LEAVES), JSON | st.just(KeyError))
def test_any_mutation_of_a_valid_file_is_refused_or_loads(tmp_path, leaf, value):
    """Of a P-type file, of an inverse-law file with its plant, and of one (version 3)
    with the weighting's and the re-identification's state."""
    which, where = leaf
    doc = copy.deepcopy(DOCUMENTS[which])
    d = doc
    for k in where[:-1]:
        d = d[k]
    if value is KeyError:
        del d[where[-1]]
    else:
        d[where[-1]] = value
    try:
        text = json.dumps(doc)
    except ValueError:
        return
    try:
        f = load_learned(_write(tmp_path, text))
    except LearnedFileError:
        return
    assert f.learning.u.shape == (f.learning.grid.size, 3)
    assert np.all(np.isfinite(f.learning.u))
    plant = f.learning.plant
    if plant is not None:  # a plant that loads is one the law can use
        assert np.all(np.isfinite(plant.response(np.array([0.0, 10.0]))))
        f.learning.step(np.zeros_like(f.learning.u))
        s = f.learning.inverse_state()  # a state that loads fits the learning
        G = f.learning.grid.size
        assert all(np.shape(x) == (G, 3) for p in s.pairs for x in p[:2])
        assert all(np.all(np.isfinite(x)) for p in s.pairs for x in p[:2])
