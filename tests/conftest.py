"""Test-suite wide setup: the shared helpers of ``tests/support`` are importable by name,
the shipped robots most tests use are session fixtures (``h4``, ``elbow``, ``fanuc``),
every property-based test is deterministic (hypothesis draws from a fixed seed per
test and keeps no example database: the same examples on every machine and run), and the
count of the docs' examples (run, skipped with their reasons; ``tests/docs``) is in
pytest's summary, so that CI shows it.  The hooks are here, not in ``tests/docs``: under
pytest-xdist only this conftest's hooks run in the controller, which writes the summary.

OpenBLAS runs single-threaded in the tests and in every process they start (the
environment is inherited): the suite runs two pytest workers and their service
processes on two cores, and OpenBLAS's threads, which spin while they wait for work, then
take the cores from each other — 40 QR factorisations of a 900 × 72 Jacobian took 55 s
with two threads and 0.8 s with one on the shared 2-core VM at load 12.  A value the
caller set is kept.  (OpenMP's pools — scikit-learn's — are left alone: the learned
layer sets its own, and a test checks that it does.)
"""

import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy is imported

import pytest
from hypothesis import settings

from plugcell.io.robots import load_robot
from plugcell.kinematics import RobotDescription

sys.path.insert(0, str(Path(__file__).resolve().parent / "support"))

settings.register_profile("plugcell", derandomize=True, database=None)
settings.load_profile("plugcell")


@pytest.fixture(scope="session")
def h4() -> RobotDescription:
    """The Comau Smart H4 (a parallelogram loop), as shipped."""
    return load_robot("smart_h4")


@pytest.fixture(scope="session")
def elbow() -> RobotDescription:
    """The serial six-axis elbow6, as shipped."""
    return load_robot("elbow6")


@pytest.fixture(scope="session")
def fanuc() -> RobotDescription:
    """Fanuc M-20iA with Fanuc's joint readings (a [coupling])."""
    return load_robot("fanuc_m20ia")


#: Every page's examples as its test report carries them (``user_properties``), so that
#: the counts are whole when the pages run in pytest-xdist's workers.
RESULTS: list[tuple[str, str, str, float]] = []


def pytest_runtest_logreport(report) -> None:
    """Collect the examples' results a page's report carries."""
    if report.when == "call":
        for key, value in report.user_properties:
            if key == "docs_examples":
                RESULTS.extend(tuple(r) for r in value)


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    """One line with the counts, then each skipped example and its reason."""
    if not RESULTS:
        return
    tr = terminalreporter
    passed = [r for r in RESULTS if r[1] == "passed"]
    failed = [r for r in RESULTS if r[1] == "failed"]
    skipped = [r for r in RESULTS if r[1] == "skipped"]
    seconds = sum(r[3] for r in RESULTS)
    tr.write_sep("-", "docs examples")
    tr.write_line(f"docs examples: {len(passed) + len(failed)} run ({len(passed)} passed, "
                  f"{len(failed)} failed) in {seconds:.0f} s, {len(skipped)} skipped")
    for where, _, _, s in sorted(passed, key=lambda r: -r[3]):
        tr.write_line(f"  ran     {where} ({s:.1f} s)")
    for where, _, reason, _ in skipped:
        tr.write_line(f"  skipped {where}: {reason}")
    for where, _, _, s in failed:
        tr.write_line(f"  FAILED  {where} ({s:.1f} s)")


#: What a test is assumed to take when the order of the files is chosen (s): one marked
#: ``slow`` (a multi-process end-to-end test, a docs page) and one not.
ASSUMED_SLOW_S, ASSUMED_FAST_S = 20.0, 0.2


def _file(item: pytest.Item) -> str:
    return item.nodeid.split("::", 1)[0]


@pytest.hookimpl(trylast=True)  # after -m/-k have deselected
def pytest_collection_modifyitems(config, items: list[pytest.Item]) -> None:
    """The test files run longest-first, each file's tests together and in their order.

    ``make test`` hands each of its two pytest-xdist workers one file at a time
    (``--dist loadfile --no-loadscope-reorder``), in this order: with the long files first
    the last ones a worker takes are short and the two end together.  (xdist's own order,
    files with the most tests first, left the files of one or two long end-to-end tests
    for the end, where one worker ran them while the other had nothing left.)  How long a
    file takes is estimated from its tests: ``ASSUMED_SLOW_S`` for each marked slow,
    ``ASSUMED_FAST_S`` for each other one.
    """
    weight: dict[str, float] = {}
    for item in items:
        slow = item.get_closest_marker("slow") is not None
        f = _file(item)
        weight[f] = weight.get(f, 0.0) + (ASSUMED_SLOW_S if slow else ASSUMED_FAST_S)
    items.sort(key=lambda item: -weight[_file(item)])  # stable: a file's order is kept
