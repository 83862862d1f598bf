"""Test-suite wide setup: the shared helpers of ``tests/support`` are importable by name,
every property-based test is deterministic (hypothesis draws from a fixed seed per
test and keeps no example database: the same examples on every machine and run), and the
count of the docs' examples (run, skipped with their reasons; ``tests/docs``) is in
pytest's summary, so that CI shows it.  The hooks are here, not in ``tests/docs``: under
pytest-xdist only this conftest's hooks run in the controller, which writes the summary.
"""

import sys
from pathlib import Path

from hypothesis import settings

sys.path.insert(0, str(Path(__file__).resolve().parent / "support"))

settings.register_profile("plugcell", derandomize=True, database=None)
settings.load_profile("plugcell")


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
