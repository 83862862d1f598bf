"""The framework's benchmark scripts still run (a few cycles each, figures not judged).

They drive the framework's own seams — a service without its transport, two services
in one process under cProfile, the two-process trace, the journal — so a refactor of
the framework can break them without breaking a test; ``make bench`` would then fail
long after.  Each runs here in a tiny configuration and must print its table.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"

SCRIPTS = [
    ("service_frames.py", ["--frames", "256", "--repeat", "1"], "4 B |"),
    ("journal.py", ["--processes", "200", "--updates", "5", "--repeat", "1"], "per request µs"),
    ("round_trip_trace.py", ["--cycles", "30"], "round trip (sum of the medians)"),
    ("round_trip_trace.py", ["--cycles", "30", "--arrival"], "service: sample arrives"),
    ("round_trip_profile.py", ["--cycles", "30", "--top", "3"], "journal (its log, SQLite)"),
    ("round_trip_cpu.py", ["--cycles", "30", "--rounds", "1", "--switches"], "voluntary / forced"),
    ("motion_sampling.py", ["--cycles", "5", "--robots", "elbow6"], "LIN (IK per sample)"),
    ("rsi_latency.py", ["--seconds", "1"], "| goal (issue 37) | this run | met |"),
    ("egm_latency.py", ["--seconds", "1", "--cpu", "0", "--mlock"],
     "link and echo on CPU 0; robot side on CPU 0; memory locked (mlockall)"),
    ("rsi_latency.py", ["--in-service", "--link-thread", "--seconds", "2"],
     "| robot service over RSI |"),
    ("egm_latency.py", ["--in-service", "--seconds", "2"], "| robot service over EGM |"),
    ("stream_cycle_profile.py", ["--cycles", "50", "--profile", "--top", "3"], "| EGM | "),
    ("tracker_stream.py", ["--seconds", "0.5"], "| rate Hz | samples/message |"),
    ("twin_path_deviation.py", ["--speeds", "250"], "| speed mm/s | duration s |"),
    ("static_correction.py", ["--fast", "--points", "2", "--methods", "settling,iterative"],
     "| settling | 2/2 |"),
    ("program_compensation.py", ["--targets", "40", "--repeat", "1", "--dialects",
                                 "krl,rapid,urscript"], "| urscript | 40 |"),
    ("program_twin.py", [], "Milling contour, ABB RAPID"),
    ("idle_cost.py", ["--services", "2", "--seconds", "1", "--settle", "0.5", "--settings",
                      "lean", "--topology", "star"], "(router "),
    ("blas_threads.py", ["--repeat", "1", "--quick"], "| QR 900×72 |"),
    ("path_tangent_lag.py", ["--seeds", "1"], "| circle | 250 | 1–11 samples |"),
    ("cpu_busy.py", ["--", sys.executable, "-c", "sum(range(10**7))"], "| busy |"),
    ("kinematics_cycle.py", ["--calls", "20", "--repeat", "1", "--robots", "smart_h4,elbow6"],
     "| elbow6 |"),
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


@pytest.mark.slow
@pytest.mark.parametrize(("args", "says"), [
    (["--cpu", "x"], "CPU list 'x': 'x' is not a CPU number"),
    (["--cpu", "4096"], "'4096': CPU 4096 is not one this process may use"),
    (["--robot-cpu", "2-1"], "'2-1' is not a range of CPU numbers"),
    (["--rt-priority", "100"], "'100': expected a SCHED_FIFO priority 1..99"),
    (["--isolate", "--cell", "2"], "--isolate keeps the cell's services off the stream's CPUs: "
     "give --cpu"),
])
def test_the_latency_benchmark_refuses_bad_scheduling_options(args, says) -> None:
    done = subprocess.run([sys.executable, str(BENCHMARKS / "rsi_latency.py"), *args],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert says in done.stderr, done.stderr


@pytest.mark.parametrize(("script", "args", "says"), [
    ("blas_threads.py", ["--repeat", "0"], "--repeat must be at least 1, not 0"),
    ("path_tangent_lag.py", ["--seeds", "0"], "--seeds must be at least 1, not 0"),
    ("kinematics_cycle.py", ["--calls", "0"], "--calls and --repeat must be at least 1"),
    ("kinematics_cycle.py", ["--robots", "nope"], "--robots: unknown robot 'nope'"),
])
def test_a_count_below_one_is_refused(script, args, says) -> None:
    done = subprocess.run([sys.executable, str(BENCHMARKS / script), *args],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and says in done.stderr, done.stderr


def test_cpu_busy_reads_proc_stat_and_refuses_what_it_cannot_read() -> None:
    """cpu_busy.py: the shares of the ticks between two readings of /proc/stat's cpu line
    (hand-made readings); a line it cannot read, no time between, no command: refused."""
    sys.path.insert(0, str(BENCHMARKS))
    try:
        import cpu_busy
    finally:
        sys.path.remove(str(BENCHMARKS))
    before = cpu_busy.cpu_ticks("cpu  100 0 50 800 10 0 0 40 0 0\ncpu0 1 2 3 4 5 6 7 8\n")
    after = cpu_busy.cpu_ticks("cpu  400 0 100 1200 10 0 0 40 0 0\n")
    share = cpu_busy.shares(before, after)
    # 300 user, 50 system, 400 idle ticks passed: 750 in all
    assert share == pytest.approx({"user": 40.0, "nice": 0.0, "system": 100 / 15,
                                   "idle": 160 / 3, "iowait": 0.0, "irq": 0.0,
                                   "softirq": 0.0, "steal": 0.0})
    for text in ("", "cpu 1 2 3\n", "intr 5\n"):
        with pytest.raises(ValueError, match="no 'cpu' line"):
            cpu_busy.cpu_ticks(text)
    with pytest.raises(ValueError, match="no CPU time passed"):
        cpu_busy.shares(before, before)
    done = subprocess.run([sys.executable, str(BENCHMARKS / "cpu_busy.py"), "--"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "give the command to measure after --" in done.stderr


@pytest.mark.slow
def test_durability_floor_writes_its_rounds_and_plot(tmp_path: Path) -> None:
    """durability_floor.py runs every variant, raw Zenoh and plugcell included, and
    writes what it printed to JSON and a PNG; a missing folder is refused up front."""
    env = {**os.environ, "PLUGCELL_HOME": str(tmp_path)}
    script = str(BENCHMARKS / "durability_floor.py")
    out, png = tmp_path / "floor.json", tmp_path / "floor.png"
    native = shutil.which("cargo") is not None  # the Rust rows where they can be built
    done = subprocess.run([sys.executable, script, "--cycles", "30", "--warmup", "5",
                           "--repeat", "1", "--output", str(out), "--plot", str(png),
                           *(["--native"] if native else [])],
                          env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "protocol's work of one round trip" in done.stdout, done.stdout[-2000:]
    assert "issue 20's target, 1.5× raw Zenoh" in done.stdout
    rounds = json.loads(out.read_text())["one_way_ms"]
    assert list(rounds) == ["raw Zenoh", "nothing", "log append", "SQLite commit", "Journal",
                            "protocol's bytes", "protocol", "protocol + Journal",
                            *(["native protocol", "native protocol + log", "native handler",
                               "native core"] if native else []),
                            "plugcell"]
    assert all(len(r) == 1 and 0 < r[0] < 1000 for r in rounds.values()), rounds
    if native:  # the Python around the Rust core, timed in a tight loop
        edges = json.loads(out.read_text())["tight_python_around_rust_us"]
        assert set(edges) == {"handler", "Python API"} and 0 < edges["handler"] < 1000, edges
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    again = tmp_path / "again.png"
    redrawn = subprocess.run([sys.executable, script, "--replot", str(out), "--plot", str(again)],
                             env=env, capture_output=True, text=True, timeout=60)
    assert redrawn.returncode == 0 and again.read_bytes()[:8] == png.read_bytes()[:8]

    refused = subprocess.run([sys.executable, script, "--output",
                              str(tmp_path / "missing" / "floor.json")],
                             env=env, capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2
    assert "no folder" in refused.stderr and "floor.json" in refused.stderr
    not_a_run = subprocess.run([sys.executable, script, "--replot", str(png), "--plot",
                                str(tmp_path / "x.png")],
                               env=env, capture_output=True, text=True, timeout=60)
    assert not_a_run.returncode == 2 and "is not a run of this script" in not_a_run.stderr


IPA_DATA = next((p / "shared" / "data" / "ipa-robot-accuracy" for p in BENCHMARKS.parents[1:3]
                 if (p / "shared" / "data" / "ipa-robot-accuracy").is_dir()), BENCHMARKS / "none")


def test_short_campaign_skips_cleanly_without_the_data(tmp_path: Path) -> None:
    """short_campaign_ur10.py (issue 36) says so and exits 0 where the data are absent."""
    done = subprocess.run([sys.executable, str(BENCHMARKS / "short_campaign_ur10.py"),
                           "--data", str(tmp_path / "none"), "--out", str(tmp_path / "x.md")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "data not found" in done.stdout and not (tmp_path / "x.md").exists()


@pytest.fixture(scope="module")
def set_up_a(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Where the short-campaign scripts keep set-up A's fit (``--cache``): the first of
    their tests here fits it, the next reads it (the same model and ``--quick`` learner:
    the cache's key)."""
    return tmp_path_factory.mktemp("set-up-a") / "A.pkl"


@pytest.mark.slow
@pytest.mark.skipif(not IPA_DATA.is_dir(), reason="IPA robot-accuracy data not present")
def test_short_campaign_runs_on_the_ipa_data(tmp_path: Path, set_up_a: Path) -> None:
    """One series, one campaign size, two folds, two campaign draws: the table (mean ± sd
    over the draws), the goal lines, the page with the CV's choice per fold and the
    plot."""
    out = tmp_path / "sc.md"
    done = subprocess.run([sys.executable, str(BENCHMARKS / "short_campaign_ur10.py"),
                           "--quick", "--series", "D", "--sizes", "25", "--folds", "2",
                           "--selection", "random", "--draws", "2", "--out", str(out),
                           "--cache", str(set_up_a)],
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "| D | (iii) --prior A" in done.stdout and "D, n = 25: prior" in done.stdout
    assert " ± " in done.stdout
    page = out.read_text()
    assert "## The goal" in page and "The CV's choice per fold" in page
    assert out.with_suffix(".png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_set_up_a_is_read_from_the_cache_only_for_the_same_learner(tmp_path: Path,
                                                                    monkeypatch) -> None:
    """``earlier``'s cache: the same model, poses and learner read back; another learner's,
    other poses' (or an older file without the key) fitted again and the file
    overwritten."""
    sys.path.insert(0, str(BENCHMARKS))
    try:
        import short_campaign_ur10 as sc
    finally:
        sys.path.remove(str(BENCHMARKS))
    from plugcell.calibration.residual_model import ResidualLearner

    fits: list[int] = []

    class Fitted:
        model = "model"

        def __init__(self, trees: int) -> None:
            self.trees = trees

        def with_residual_model(self, layer: int) -> tuple[str, int]:
            return ("A", layer)

    class Calibrator:  # counts the fits of set-up A
        def __init__(self, desc, model) -> None:
            pass

        def fit(self, data) -> Fitted:
            fits.append(1)
            return Fitted(len(fits))

    monkeypatch.setattr(sc, "Calibrator", Calibrator)
    monkeypatch.setattr(ResidualLearner, "fit", lambda self, model, data, robot: self.trees)
    cache, ur10 = tmp_path / "A.pkl", type("Robot", (), {"name": "ur10"})()
    A = type("Data", (), {"q": np.zeros((4, 6))})()
    assert sc.earlier(ur10, A, ResidualLearner(trees=100), cache) == ("A", 100)
    assert sc.earlier(ur10, A, ResidualLearner(trees=100), cache) == ("A", 100)
    assert len(fits) == 1  # read back
    assert sc.earlier(ur10, A, ResidualLearner(trees=50), cache) == ("A", 50)
    assert len(fits) == 2  # another learner: fitted again …
    assert sc.earlier(ur10, A, ResidualLearner(trees=50), cache) == ("A", 50)
    assert len(fits) == 2  # … and kept
    quick = type("Data", (), {"q": np.zeros((1, 6))})()  # other poses of A (--quick's)
    assert sc.earlier(ur10, quick, ResidualLearner(trees=50), cache) == ("A", 50)
    assert len(fits) == 3  # fitted again
    import pickle

    cache.write_bytes(pickle.dumps(("A", 100)))  # a file of the format before the key
    assert sc.earlier(ur10, A, ResidualLearner(trees=50), cache) == ("A", 50)
    assert len(fits) == 4


def test_stage_weight_skips_cleanly_without_the_data(tmp_path: Path) -> None:
    """short_campaign_stage_weight.py (issue 36 §2) says so and exits 0 without the data."""
    done = subprocess.run([sys.executable, str(BENCHMARKS / "short_campaign_stage_weight.py"),
                           "--data", str(tmp_path / "none")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "data not found" in done.stdout


@pytest.mark.slow
@pytest.mark.skipif(not IPA_DATA.is_dir(), reason="IPA robot-accuracy data not present")
def test_stage_weight_runs_on_the_ipa_data(set_up_a: Path) -> None:
    """Two folds, one campaign each: the stage's out-of-fold predictions recomputed by the
    script match the stage's recorded CV errors exactly, the weight ``--prior`` chose with
    the same grid is the script's w*, and the weight's line is printed."""
    done = subprocess.run([sys.executable, str(BENCHMARKS / "short_campaign_stage_weight.py"),
                           "--quick", "--series", "D", "--size", "50", "--folds", "2",
                           "--cache", str(set_up_a)],
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    lines = [x for x in done.stdout.splitlines() if x.startswith("  D fold")]
    assert len(lines) == 2 and all("CV check 0e+00 m" in x for x in lines), done.stdout
    for x in lines:
        assert re.search(r"-> w ([\d.]+) \(product w \1\)", x), x
    assert "w by the stage's CV" in done.stdout


#: py-spy's raw format: an idle worker, a worker's test, a service importing SciPy through
#: plugcell's calibration, and a docs example whose bash command line spans two lines.
SUITE_RAW = (
    'process 1:"";process 2:"python -u -c import sys;exec(eval(sys.stdin.readline()))" 500\n'
    'process 1:"";process 2:"python -u -c import sys;exec(eval(sys.stdin.readline()))";'
    "pytest_pyfunc_call (_pytest/python.py:187);test_x (test_x.py:3);"
    "forward (plugcell/kinematics/forward.py:417) 50\n"
    'process 1:"";process 3:"python -m plugcell serve robot --name R";'
    "<module> (plugcell/__main__.py:5);_find_and_load (<frozen importlib._bootstrap>:1176);"
    "<module> (plugcell/calibration/linalg.py:14);"
    "_find_and_load (<frozen importlib._bootstrap>:1176);<module> (scipy/linalg/__init__.py:202);"
    "<module> (scipy/linalg/_basic.py:9) 25\n"
    'process 1:"";process 4:"bash -c set -e\nplugcell kin fk --joints 0,0";'
    'process 5:"python -m plugcell kin fk --joints 0,0";'
    "main (plugcell/apps/cli.py:167);forward (plugcell/kinematics/forward.py:417) 25\n"
)


def test_suite_profile_reads_a_py_spy_recording(tmp_path: Path) -> None:
    raw = tmp_path / "suite.raw"
    raw.write_text(SUITE_RAW)
    done = subprocess.run([sys.executable, str(BENCHMARKS / "suite_profile.py"), str(raw)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "busy samples: 100 (4 s of CPU at 25 samples/s); importing: 1 s (25.0%)" in out
    assert "| pytest worker (the tests' own code) | 2.0 | 50.0% |" in out
    assert "| plugcell serve robot | 1.0 | 25.0% |" in out
    assert "| plugcell kin fk | 1.0 | 25.0% |" in out  # the bash line's newline kept apart
    assert "| scipy | 1.0 | 25.0% |" in out
    assert "| plugcell.calibration.linalg → scipy | 1.0 | 25.0% |" in out
    assert "| forward (plugcell/kinematics/forward.py:417) | 3.0 | 75.0% |" in out


@pytest.mark.parametrize(("text", "says"), [
    ("not a recording\n", "not py-spy's raw format"),
    ('process 1:"python" 40\n', "no busy sample in the recording"),
])
def test_suite_profile_refuses_what_it_cannot_read(tmp_path: Path, text: str,
                                                   says: str) -> None:
    raw = tmp_path / "suite.raw"
    raw.write_text(text)
    done = subprocess.run([sys.executable, str(BENCHMARKS / "suite_profile.py"), str(raw)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and says in done.stderr, done.stderr
    done = subprocess.run([sys.executable, str(BENCHMARKS / "suite_profile.py"),
                           str(tmp_path / "absent.raw")], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and "absent.raw" in done.stderr
