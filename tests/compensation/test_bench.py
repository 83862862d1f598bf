"""The compensation benchmark runs and reports (a small n; the speed itself is measured by
``benchmarks/compensation.py``)."""

from __future__ import annotations

from plugcell.apps.bench.compensation import format_report, run


def test_bench_small():
    r = run(n=200)
    ms = r["model_stage"]
    assert r["n"] == 200 and ms["targets"] >= 190
    assert ms["converged"] == ms["targets"] and ms["residual_max"] < 1e-6
    assert ms["targets_per_s"] > 0 and r["with_nominal_ik"]["targets_per_s"] > 0
    assert "targets/s" in format_report(r)
