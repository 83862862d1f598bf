"""Fuzz the text parsers of plugcell (issue 10 §4): ``python benchmarks/fuzz_parsers.py
[TARGET|all] [CASES] [SEED]`` (default: all, 100 000 cases per target).

Targets and the only exception each may raise (anything else is a crash, printed
with the input, and the run exits 1); every refusal must carry a message:

* ``activate`` — :func:`plugcell.devices.robot.activate.parse_activate` →
  ``ActivateSyntaxError``;
* ``language`` — ``Program.from_source`` (robot language: parse + check) →
  ``ProgramError``;
* ``measurements`` — :func:`plugcell.io.measurements.read_measurements` (the file
  reader; inputs written as files, sometimes not UTF-8) → ``MeasurementFileError``;
* ``measurements_text`` — :func:`plugcell.io.measurements.parse_measurements` on the
  text itself (no newline translation) → ``MeasurementFileError``;
* ``description`` — :func:`plugcell.io.robots.load_robot_file` (a robot description
  file) → ``DescriptionError`` (or ``RobotNotFoundError``, never for an existing file);
* ``compute`` — :func:`plugcell.devices.compute.expr.parse` → ``EvaluationError``;
* ``nests`` — :func:`plugcell.io.nests.parse_nests` (drift-watch nest files) →
  ``NestFileError``.

Inputs: mutations of valid samples (character flips, insertions from the target's
alphabet, deletions, duplicated spans, splices, truncations) and random text.  The
slowest case is reported (wall time, and CPU time of the parsing thread, which the load of
other processes does not inflate), so a hang shows up as a time, not a stuck run.
"""

from __future__ import annotations

import json
import random
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from plugcell.devices.compute.expr import EvaluationError, parse
from plugcell.devices.robot.activate import ActivateSyntaxError, parse_activate
from plugcell.io.measurements import (
    MeasurementFileError,
    parse_measurements,
    read_measurements,
)
from plugcell.io.nests import NestFileError, parse_nests
from plugcell.io.robots import load_robot_file
from plugcell.kinematics.errors import DescriptionError
from plugcell.pdl import Program, ProgramError

PKG = Path(__file__).resolve().parents[1] / "src" / "plugcell"
PROGRAMS = PKG / "pdl" / "programs"

ACTIVATE_SEEDS = [
    "ACTIVATE CAMERA #SnapShot##500",
    "ACTIVATE TOOL #Drill#Air#550,1100",
    "ACTIVATE CAMERA #SnapShot##, 500",
    "activate TRACKER #Single Measurement#tr2euler; to=COMPUTE:Set Matrix:m#100",
    "  ACTIVATE\tCAMERA #Connect",
]
MEASUREMENT_SEEDS = [
    "# comment\nj1,j2,j3,j4,j5,j6,x,y,z,rx,ry,rz,payload_kg\n"
    "10.0,-80.0,-150.0,0.0,30.0,0.0,1712.43,-12.80,1203.55,179.9,0.2,-90.1,36\n"
    "11.0,-81.0,-151.0,1.0,31.0,1.0,1702.43,-11.80,1213.55,178.9,0.3,-90.0,0\n",
    "j1,j2,j3,j4,x,y,z\n1,2,3,4,1000,0,500\n5,6,7,8,1100,10,520\n",
    "j1,j2,x,y,z,temperature_c\n1,2,1000,0,500,21.5\n5,6,1100,10,520,22.25\n",
]
NEST_SEEDS = [
    "# nests\nname,x,y,z\nN1,1520.31,-840.07,12.55\nN2,2400,200,50\nN3,1200,1500,0\n",
    "name,x,y,z\nA,1,2,3\nB,4,5,6\nC,7,8,10\nD,-1e3,2.5e2,0\n",
]
COMPUTE_SEEDS = [
    "p = scale(mJ, k=-2.5e1)\nq = [1, 2; 3, .5]; 'text'",
    "p = scale(\n  [1, 2],\n  k=3)",
    "x = -[1 2 3; 4 5 6]\ny = f(x, 'a', b=2)",
]
ALPHABETS = {
    "activate": "ACTIVATE#, \t;:=.-_0123456789abcXYZ\x00\n\x7f€",
    "language": "ROUTINE BEGIN END IF THEN ELSE ENDIF := ( ) [ ] , ; ' -- . 0 1 9 e E + - * / "
                "< > = : INTEGER REAL STRING BOOLEAN\n\t\"$",
    "measurements": "0123456789.,-+eE#\n\r\" jxyzr_naINF\t",
    "measurements_text": "0123456789.,-+eE#\n\r\" jxyzr_naINF\t",
    "description": "[]{}=\",.#\n 0123456789-+eE_abcdefghijklmnopqrstuvwxyz'\t",
    "compute": "[](),;=.'\"\n +-*/^0123456789eEabkpqxyz_ \t#\\",
    "nests": "0123456789.,-+eE#\n\r\" nameNxyz_INF\t",
}


def _seeds(target: str) -> list[str]:
    if target == "activate":
        return ACTIVATE_SEEDS
    if target.startswith("measurements"):
        return MEASUREMENT_SEEDS
    if target == "compute":
        return COMPUTE_SEEDS
    if target == "nests":
        return NEST_SEEDS
    if target == "language":
        return [(PROGRAMS / n).read_text() for n in ("example.pdl", "calibration.pdl")]
    return [p.read_text() for p in sorted((PKG / "robots").glob("*.toml"))]


def mutate(rng: random.Random, seeds: list[str], alphabet: str) -> str:
    """One fuzz input: a mutated seed (usually) or random text."""
    r = rng.random()
    if r < 0.05:
        return "".join(rng.choice(alphabet) for _ in range(rng.randrange(0, 80)))
    if r < 0.07:
        return "".join(chr(rng.randrange(0, 0x3000)) for _ in range(rng.randrange(0, 40)))
    text = rng.choice(seeds)
    for _ in range(rng.choice((1, 1, 1, 2, 3, 6))):
        n = len(text)
        op = rng.randrange(7)
        i = rng.randrange(n + 1)
        j = min(n, i + rng.randrange(1, 12))
        if op == 0 and n:  # replace one character
            text = text[:i] + rng.choice(alphabet) + text[i + 1:]
        elif op == 1:  # insert a few characters
            text = text[:i] + "".join(rng.choice(alphabet) for _ in range(rng.randrange(1, 5))) \
                + text[i:]
        elif op == 2:  # delete a span
            text = text[:i] + text[j:]
        elif op == 3:  # duplicate a span
            text = text[:j] + text[i:j] + text[j:]
        elif op == 4:  # splice with another seed
            other = rng.choice(seeds)
            k = rng.randrange(len(other) + 1)
            text = text[:i] + other[k:]
        elif op == 5:  # truncate
            text = text[:i]
        else:  # swap two lines
            lines = text.split("\n")
            if len(lines) > 1:
                a, b = rng.randrange(len(lines)), rng.randrange(len(lines))
                lines[a], lines[b] = lines[b], lines[a]
                text = "\n".join(lines)
    return text


def _checker(target: str, tmp: Path) -> tuple[Callable[[str], object], type[Exception]]:
    if target == "activate":
        return parse_activate, ActivateSyntaxError
    if target == "language":
        return (lambda t: Program.from_source(t, "<fuzz>", base_dir=PROGRAMS)), ProgramError
    if target == "measurements_text":
        return (lambda t: parse_measurements(t, name="fuzz.csv")), MeasurementFileError
    if target == "measurements":
        csv_path = tmp / "fuzz.csv"

        def read(text: str) -> object:
            raw = text.encode("utf-8", "surrogatepass")
            if raw and len(raw) % 17 == 0:  # now and then, not UTF-8
                raw = raw[:-1] + b"\xff"
            csv_path.write_bytes(raw)
            return read_measurements(csv_path)

        return read, MeasurementFileError
    if target == "compute":
        return parse, EvaluationError
    if target == "nests":
        return (lambda t: parse_nests(t, "fuzz.csv")), NestFileError
    path = tmp / "fuzz_robot.toml"

    def load(text: str) -> object:
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        return load_robot_file(path)

    return load, DescriptionError


TARGETS = ("activate", "language", "measurements", "measurements_text", "description",
           "compute", "nests")


class ParserCrashError(AssertionError):
    """An input made a parser raise something else than its documented error."""


def fuzz(target: str, cases: int, seed: int) -> dict[str, object]:
    """Run ``cases`` inputs against ``target``; :class:`ParserCrashError` on a crash."""
    rng = random.Random(f"{target}:{seed}")
    seeds = _seeds(target)
    accepted = refused = 0
    slowest = slowest_cpu = 0.0
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        check, allowed = _checker(target, Path(tmp))
        for _ in range(cases):
            text = mutate(rng, seeds, ALPHABETS[target])
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                check(text)
                accepted += 1
            except allowed as exc:
                if not str(exc).strip():
                    raise ParserCrashError(
                        f"{target}: refusal without a message for {text!r}"
                    ) from exc
                refused += 1
            except Exception as exc:  # a crash
                raise ParserCrashError(
                    f"{target}: {type(exc).__name__}: {exc} for input {text!r}"
                ) from exc
            slowest = max(slowest, time.perf_counter() - t0)
            slowest_cpu = max(slowest_cpu, time.thread_time() - c0)
    return {"target": target, "cases": cases, "seed": seed, "accepted": accepted,
            "refused": refused, "crashes": 0, "slowest_case_ms": round(slowest * 1e3, 2),
            "slowest_case_cpu_ms": round(slowest_cpu * 1e3, 2),
            "seconds": round(time.perf_counter() - started, 2)}


def main() -> int:
    which = sys.argv[1] if len(sys.argv) > 1 else "all"
    cases = int(sys.argv[2]) if len(sys.argv) > 2 else 100_000
    seed = int(sys.argv[3]) if len(sys.argv) > 3 else 20261122
    status = 0
    for target in TARGETS if which == "all" else (which,):
        try:
            print(json.dumps(fuzz(target, cases, seed)), flush=True)
        except ParserCrashError as exc:
            print(json.dumps({"target": target, "crash": str(exc)[:2000]}), flush=True)
            status = 1
    return status


if __name__ == "__main__":
    sys.exit(main())
