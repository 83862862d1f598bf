"""The framework's benchmark scripts still run (a few cycles each, figures not judged).

They drive the framework's own seams — a service without its transport, two services
in one process under cProfile, the two-process trace, the journal — so a refactor of
the framework can break them without breaking a test; ``make bench`` would then fail
long after.  Each runs here in a tiny configuration and must print its table.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"

SCRIPTS = [
    ("service_frames.py", ["--frames", "256", "--repeat", "1"], "4 B |"),
    ("journal.py", ["--processes", "200", "--updates", "5", "--repeat", "1"], "per request µs"),
    ("round_trip_trace.py", ["--cycles", "30"], "round trip (sum of the medians)"),
    ("round_trip_trace.py", ["--cycles", "30", "--arrival"], "service: sample arrives"),
    ("round_trip_profile.py", ["--cycles", "30", "--top", "3"], "journal (its log, SQLite)"),
    ("round_trip_cpu.py", ["--cycles", "30", "--rounds", "1", "--switches"], "voluntary / forced"),
    ("durability_floor.py", ["--cycles", "30", "--warmup", "5", "--repeat", "1"],
     "protocol's work of one round trip"),
    ("idle_cost.py", ["--services", "2", "--seconds", "1", "--settle", "0.5", "--settings",
                      "lean", "--topology", "star"], "(router "),
]


@pytest.mark.slow
@pytest.mark.parametrize(("script", "args", "expected"), SCRIPTS,
                         ids=[" ".join([s, *a]) for s, a, _ in SCRIPTS])
def test_benchmark_script_runs(script: str, args: list[str], expected: str,
                               tmp_path: Path) -> None:
    env = {**os.environ, "PLUGCELL_HOME": str(tmp_path)}
    done = subprocess.run([sys.executable, str(BENCHMARKS / script), *args], env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert expected in done.stdout, done.stdout[-2000:]
