"""Bad input everywhere (issue 10 §4), a few thousand seeded cases per parser; the
benchmark ``benchmarks/fuzz_parsers.py`` runs ≥ 100 000 each.  A parser may only
refuse with its documented error, with a message; anything else is a crash."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from fuzz_parsers import fuzz

pytestmark = pytest.mark.timeout(120)

CASES = {"activate": 5000, "compute": 5000, "measurements": 3000, "description": 2000,
         "language": 1500, "nests": 3000}


@pytest.mark.parametrize("target", sorted(CASES))
def test_parser_refuses_bad_input_precisely(target: str) -> None:
    report = fuzz(target, CASES[target], seed=7)
    assert report["crashes"] == 0
    assert report["refused"] > 0 and report["accepted"] > 0  # the mutations reach both sides
    # no hang: a parser that blows up on some input spends its CPU time there (the wall
    # time of a case also counts the time other processes had the CPU)
    assert report["slowest_case_cpu_ms"] < 2000


def test_measurement_text_parser_bare_carriage_return() -> None:
    fuzz("measurements_text", 3000, seed=7)
