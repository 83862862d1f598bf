"""plugcell.calibration is pure math: it never imports the twin, the framework or the services."""

from __future__ import annotations

from loaded_modules import modules_loaded_by


def test_calibration_imports_no_twin_framework_or_io():
    assert modules_loaded_by(
        "import plugcell.calibration, plugcell.calibration.planning, "
        "plugcell.calibration.simulation",
        ["plugcell.sim.twin", "plugcell.framework", "plugcell.devices", "plugcell.io",
         "plugcell.apps.commands", "zenoh", "matplotlib"]) == []


def test_bench_calibration_reports_t150():
    from plugcell.apps.bench.calibration import measure

    d = measure(repeat=1, max_poses=150)
    assert d["t150_s"] > 0 and d["parameters"] == 50
    assert [s["poses"] for s in d["scaling"]] == [150]
