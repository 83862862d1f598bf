"""plugcell.compensation is pure math: it imports neither the twin, the framework, the
services nor the experiments (design.md)."""

from __future__ import annotations

from loaded_modules import modules_loaded_by


def test_compensation_imports_no_twin_or_framework():
    assert modules_loaded_by("import plugcell.compensation", [
        "plugcell.sim.twin", "plugcell.framework", "plugcell.devices", "plugcell.apps.reproduce",
        "plugcell.io"]) == []
