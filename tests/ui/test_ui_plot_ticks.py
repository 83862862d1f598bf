"""The tracked path's plot labels its axes with "nice" ticks (``deviation_plot.js``'s
``ticks``, run in node): steps of 1, 2 or 5 × 10^k, inside the range, increasing, as many
decimals as the step needs, so that no two labels read the same and they do not crowd."""

from __future__ import annotations

import itertools
import json
import math
import shutil
import subprocess

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.apps.ui.app import STATIC

PLOT = STATIC / "js" / "deviation_plot.js"

pytestmark = pytest.mark.skipif(not shutil.which("node"), reason="needs node (make test's npm)")

_RUN = f"""
import {{ ticks }} from {json.dumps(PLOT.as_uri())};
let text = "";
process.stdin.on("data", (d) => (text += d));
process.stdin.on("end", () => {{
  const out = JSON.parse(text).map(([lo, hi, n]) => ticks(lo, hi, n));
  process.stdout.write(JSON.stringify(out));
}});
"""


def _ticks(cases: list[tuple[float, float, int]]) -> list[dict]:
    done = subprocess.run(["node", "--input-type=module", "-e", _RUN], input=json.dumps(cases),
                          capture_output=True, text=True, timeout=60, check=True)
    return json.loads(done.stdout)


def test_ticks_of_the_plots_ranges() -> None:
    # a circle's deviations (0–0.35 mm) and its 12.3 s, and a path starting later
    dev, time, late = _ticks([(0, 0.3462 * 1.08, 4), (0, 12.3, 6), (3.2, 3.9, 6)])
    assert [f"{v:.{dev['decimals']}f}" for v in dev["values"]] == ["0.0", "0.1", "0.2", "0.3"]
    assert [round(v, 9) for v in time["values"]] == [0, 2, 4, 6, 8, 10, 12]
    assert time["decimals"] == 0
    assert [f"{v:.1f}" for v in late["values"]] == [f"{3.2 + 0.1 * i:.1f}" for i in range(8)]


_case = st.tuples(
    st.floats(-1e3, 1e3, allow_nan=False), st.floats(1e-6, 1e4), st.integers(3, 8)
).map(lambda c: (c[0], c[0] + c[1], c[2]))


@settings(max_examples=15, deadline=None)
@given(st.lists(_case, min_size=1, max_size=40))
def test_ticks_are_nice_inside_increasing_and_read_differently(cases) -> None:
    for (lo, hi, n), t in zip(cases, _ticks(cases), strict=True):
        values, decimals = t["values"], t["decimals"]
        assert 2 <= len(values) <= 2.5 * n + 2, (lo, hi, n, values)
        step = values[1] - values[0]
        mantissa = step / 10 ** math.floor(math.log10(step) + 1e-9)
        assert min(abs(mantissa - m) for m in (1, 2, 5, 10)) < 1e-3, (step, mantissa)
        assert all(b - a == pytest.approx(step, rel=1e-6) for a, b in itertools.pairwise(values))
        assert lo - step * 1e-6 <= values[0] and values[-1] <= hi + step * 1e-6
        labels = [f"{v:.{decimals}f}" for v in values]
        assert len(set(labels)) == len(labels), labels
