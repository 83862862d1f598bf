"""The web UI's tracked-path view (issue 38): ``POST /api/tracked-path`` with the result
file of ``plugcell path run --out``, checked and turned into deviations from the
commanded path; every bad file refused naming why."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.apps.ui.metrology import FitInputError
from plugcell.apps.ui.tracked import MAX_POINTS, tracked_path_view


def document(n: int = 400, samples: int = 1500) -> dict:
    """A result file as path run writes it: a 40 mm line, the TCP 0.3 mm off it until
    the loop corrects it, a beam break window."""
    t = np.arange(n) * 0.004 - 0.5
    commanded = np.column_stack([np.full(n, 1473.3), -231.7 + 40 * np.clip(t, 0, 1),
                                 np.full(n, 2488.4)])
    off = np.where(t < 0.2, 0.3, 0.05)
    actual = commanded + np.column_stack([off, np.zeros(n), np.zeros(n)])
    corrected = commanded - np.column_stack([0.3 - off, np.zeros(n), np.zeros(n)])
    ts = np.linspace(t[0], t[-1], samples)
    measured = np.column_stack([ts, *[np.interp(ts, t, actual[:, i]) for i in range(3)]])
    return {"format": "plugcell-tracked-path", "format_version": 1, "path": "line.csv",
            "ended": "", "accuracy": [{"segment": 0, "state": "all", "cycles": 250,
                                       "perpendicular_max_mm": 0.3,
                                       "perpendicular_3sigma_mm": 0.31, "along_max_mm": 0.1}],
            "windows_without_tracking": [{"start_s": 0.3, "end_s": 0.6,
                                          "reason": "line_of_sight"}],
            "traces": {"t_s": t.tolist(), "commanded_mm": commanded.tolist(),
                       "corrected_mm": corrected.tolist(), "actual_mm": actual.tolist(),
                       "measured_mm": measured.tolist(), "segment": [0] * n,
                       "state": ["tracking"] * n}}


def test_the_deviations_from_the_commanded_path():
    view = tracked_path_view(document())
    actual = np.array(view["series"]["actual"])
    corrected = np.array(view["series"]["corrected"])
    measured = np.array(view["series"]["measured"])
    np.testing.assert_allclose(actual[actual[:, 0] < 0.19, 1], 0.3, atol=1e-9)
    np.testing.assert_allclose(actual[actual[:, 0] > 0.21, 1], 0.05, atol=1e-9)
    np.testing.assert_allclose(corrected[:, 1] + actual[:, 1], 0.3, atol=1e-9)
    assert len(measured) <= MAX_POINTS and measured[:, 1].max() == pytest.approx(0.3, abs=1e-6)
    assert view["max_mm"]["actual"] == pytest.approx(0.3)
    assert view["windows"] == [{"start_s": 0.3, "end_s": 0.6, "reason": "line_of_sight"}]
    assert view["accuracy"][0]["perpendicular_max_mm"] == 0.3 and view["title"] == "line.csv"


def test_long_runs_are_decimated():
    view = tracked_path_view(document(n=5000, samples=20000))
    assert all(len(v) <= MAX_POINTS for v in view["series"].values())
    assert view["series"]["actual"][0][0] == pytest.approx(-0.5)


def _break(doc, path, value):
    d = copy.deepcopy(doc)
    target = d
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return d


@pytest.mark.parametrize(("path", "value", "why"), [
    (("format",), "x", "not a tracked path's result (format 'plugcell-tracked-path')"),
    (("format_version",), 2, "format_version 2: this plugcell reads 1"),
    (("traces",), None, "traces: missing"),
    (("traces", "t_s"), [], "traces.t_s: a list of 1…900000 rows expected"),
    (("traces", "t_s"), [0.0] * 400, "traces.t_s: times must increase"),
    (("traces", "actual_mm"), [[0, 0, 0]] * 3, "traces.actual_mm: 3 rows, t_s has 400"),
    (("traces", "corrected_mm"), [[0, 0]] * 400,
     "traces.corrected_mm: rows of 3 finite numbers expected"),
    (("traces", "measured_mm"), [[0, "a", 0, 0]], "traces.measured_mm: rows of 4 numbers"),
])
def test_a_bad_file_is_refused_naming_why(path, value, why):
    with pytest.raises(FitInputError) as info:
        tracked_path_view(_break(document(), path, value))
    assert why in info.value.errors["document"]


JSON = st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=5),
                    lambda inner: st.lists(inner, max_size=4)
                    | st.dictionaries(st.text(max_size=12), inner, max_size=4), max_leaves=20)


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(["t_s", "commanded_mm", "corrected_mm", "actual_mm", "measured_mm",
                        "accuracy", "windows_without_tracking", "path", "ended"]), JSON)
def test_any_field_of_any_json_is_a_view_or_a_refusal(field, value):
    doc = document(n=20, samples=50)
    d = _break(doc, ("traces", field) if field.endswith(("_s", "_mm")) else (field,), value)
    try:
        view = tracked_path_view(d)
    except FitInputError as exc:
        assert exc.errors["document"]
        return
    assert set(view["series"]) == {"corrected", "actual", "measured"}


def test_the_api_answers_the_view_or_the_field_error(module_cell):
    from ui_testlib import HEADERS, make_client

    with make_client(module_cell) as client:
        ok = client.post("/api/tracked-path", json={"document": document()},
                         headers=HEADERS).json()
        bad = client.post("/api/tracked-path", json={"document": {"format": "x"}},
                          headers=HEADERS).json()
    assert ok["ok"] and ok["max_mm"]["actual"] == pytest.approx(0.3)
    assert bad == {"ok": False, "errors": {"document": bad["errors"]["document"]}}
    assert bad["errors"]["document"].startswith("not a tracked path's result")
