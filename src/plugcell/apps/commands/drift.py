"""``plugcell drift``: the drift watch — BASE re-registered from fixed reference nests.

    plugcell drift register --params PARAMS.json --measured NESTS.csv --out REF.csv
    plugcell drift check --params PARAMS.json --nests REF.csv --measured NOW.csv
                         [--threshold-mm 0.05] [--update] [--json]

``register``: right after calibration, the tracker measures the reference nests
fixed to the robot's foundation; with the identified BASE their positions in the
robot base frame are written to REF.csv (constants from then on).  ``check``: during
production the nests are measured again; the 6-DOF drift of BASE is estimated
(:func:`plugcell.metrology.drift.estimate_base_drift`), printed, and above the
threshold an alarm is raised (exit code 1); with ``--update`` BASE is re-registered
in PARAMS.json in place (the robot's parameters, a learned residual layer included,
stay valid) and the event is appended to its ``drift_history``.  Nests that no longer
agree with each other (rigid-fit rms above the tolerance) are reported and BASE is
not touched.  Bad files end with a one-line message and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.files import write_text


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``drift`` actions to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = __doc__.splitlines()[0] if __doc__ else None
    dsub = p.add_subparsers(dest="drift_command", metavar="ACTION", required=True)
    r = dsub.add_parser("register", help="nest positions in the robot base frame from a "
                                         "measurement right after calibration")
    r.add_argument("--params", type=Path, required=True, help="PARAMS.json (its BASE)")
    r.add_argument("--measured", type=Path, required=True,
                   help="nests measured by the tracker: name,x,y,z (mm, tracker frame)")
    r.add_argument("--out", type=Path, required=True, help="registration file to write")
    r.set_defaults(func=_register)
    c = dsub.add_parser("check", help="estimate the drift of BASE from re-measured nests")
    c.add_argument("--params", type=Path, required=True, help="PARAMS.json (its BASE)")
    c.add_argument("--nests", type=Path, required=True, help="registration file (drift register)")
    c.add_argument("--measured", type=Path, required=True,
                   help="the nests measured now: name,x,y,z (mm, tracker frame)")
    c.add_argument("--threshold-mm", type=float, default=0.05,
                   help="alarm above this displacement at the nests (default 0.05 mm)")
    c.add_argument("--fit-tolerance-mm", type=float, default=0.05,
                   help="rms of the nests' rigid fit above which a nest moved (0.05 mm)")
    c.add_argument("--update", action="store_true",
                   help="on an alarm, re-register BASE in PARAMS.json in place")
    c.add_argument("--json", action="store_true", help="print the estimate as JSON")
    c.set_defaults(func=_check)


def _params(path: Path) -> tuple[dict[str, Any], Any]:
    from plugcell.apps.commands.files import read_calibration

    return read_calibration(path)


def _nests(path: Path) -> tuple[list[str], np.ndarray]:
    from plugcell.io.nests import NestFileError, read_nests

    try:
        return read_nests(path)
    except NestFileError as exc:
        raise CommandError(str(exc)) from None



#: The first comment line of a registration file (written by ``drift register``).
REGISTERED = "plugcell drift register:"


def _registered(path: Path) -> bool:
    """Whether ``path`` is a registration file written by ``drift register``."""
    try:
        with path.open(encoding="utf-8", errors="replace") as f:
            head = [f.readline() for _ in range(5)]
    except OSError:
        return False
    return any(line.lstrip("# ").startswith(REGISTERED) for line in head)


def _register(args: argparse.Namespace) -> int:
    from plugcell.io.nests import format_nests
    from plugcell.metrology.drift import nests_in_base, too_close

    _, result = _params(args.params)
    names, measured = _nests(args.measured)
    close = too_close(measured)
    if close:
        raise CommandError(f"{args.measured}: {close.removeprefix('units: ')}")
    base = result.model.base()
    write_text(args.out, format_nests(names, nests_in_base(base, measured), (
        f"{REGISTERED} {len(names)} nests in the robot base frame (mm), from "
        f"{args.measured.name} with the BASE of {args.params.name}",)))
    print(f"registered {len(names)} nests in the robot base frame; wrote {args.out}")
    return 0


def _check(args: argparse.Namespace) -> int:
    from plugcell.metrology import MetrologyError
    from plugcell.metrology.drift import estimate_base_drift, likely_mix_up

    for opt in ("threshold_mm", "fit_tolerance_mm"):
        v = getattr(args, opt)
        if not (math.isfinite(v) and v > 0):
            raise CommandError(f"--{opt.replace('_', '-')} must be > 0, got {v}")
    d, result = _params(args.params)
    ref_names, ref = _nests(args.nests)
    names, measured = _nests(args.measured)
    missing = [n for n in ref_names if n not in names]
    if missing:
        raise CommandError(f"{args.measured}: nest(s) {missing} of {args.nests} not measured")
    order = [names.index(n) for n in ref_names]
    try:
        est = estimate_base_drift(result.model.base(), ref, measured[order],
                                  threshold_m=args.threshold_mm * 1e-3,
                                  fit_tolerance_m=args.fit_tolerance_mm * 1e-3)
        mix_up = likely_mix_up(result.model.base(), ref, measured[order])
    except MetrologyError as exc:
        raise CommandError(f"{args.nests}: {exc}") from None
    if not mix_up and _registered(args.measured) and not _registered(args.nests):
        mix_up = (f"swapped: {args.measured.name} was written by plugcell drift register and "
                  f"{args.nests.name} was not — --nests and --measured swapped?")
    if mix_up:  # not a drift: no alarm, nothing re-registered (exit 2)
        raise CommandError(f"drift of BASE not estimated ({est.displacement_m * 1e3:.1f} mm at "
                           f"the nests is no drift): {mix_up}")
    updated = False
    if est.alarm and args.update and est.consistent:
        from plugcell.io.params import rebase_document

        event = {"time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                 **{k: v for k, v in est.as_dict().items() if k != "base"}}
        d = rebase_document(d, result, est.base, event)
        write_text(args.params, json.dumps(d, indent=2) + "\n")
        updated = True
    if args.json:
        print(json.dumps({**est.as_dict(), "updated": updated}, indent=2))
    else:
        t, r = est.translation_m * 1e3, np.degrees(est.rotation_rad)
        state = (f"ALARM (> {args.threshold_mm:g} mm)" if est.alarm
                 else f"ok (≤ {args.threshold_mm:g} mm)")
        print(f"drift of BASE: {est.displacement_m * 1e3:.3f} mm at the nests — translation "
              f"[{t[0]:.3f}, {t[1]:.3f}, {t[2]:.3f}] mm, rotation "
              f"[{r[0]:.5f}, {r[1]:.5f}, {r[2]:.5f}]°, nest fit rms {est.rms_m * 1e3:.3f} mm: "
              f"{state}")
        if not est.consistent:
            print(f"warning: the nests disagree (fit rms {est.rms_m * 1e3:.3f} mm > "
                  f"{args.fit_tolerance_mm:g} mm): a nest moved? BASE not re-registered")
        if updated:
            print(f"re-registered BASE in {args.params}")
    return 1 if est.alarm else 0
