"""plugcell.compensation is pure math: it imports neither the twin, the framework, the
services nor the experiments (design.md)."""

from __future__ import annotations

import subprocess
import sys


def test_compensation_imports_no_twin_or_framework():
    code = (
        "import sys, plugcell.compensation\n"
        "bad = [m for m in sys.modules if m.startswith(('plugcell.sim.twin', 'plugcell.framework',"
        " 'plugcell.devices', 'plugcell.apps.reproduce', 'plugcell.io'))]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
