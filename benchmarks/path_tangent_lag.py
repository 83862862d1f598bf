"""How far the PC's path tangent (EGM path correction's x axis) strays when the controller
applies a correction later than the PC assumes: :class:`~plugcell.kinematics.path_frame.
TangentTracker` with its lag bound (``lag_s`` 0.05 s, the default) against the rule before
it (``lag_s = 0``), on seeded synthetic paths sampled every 4 ms.

Each path is a circle of radius 100 mm (or a straight line) at ``speed``; a correction of
2.8 mm, normal to the path, ramps in over 0.5 s while it moves; the controller applies
sample ``k``'s correction ``1 + j`` samples late, ``j`` drawn from 0 … ``jitter`` each
sample (the PC assumes one).  Printed per case: the tracker's largest angle from the true
tangent over the run (degrees), its 99th percentile, and how many tangents it took.
Usage::

    python benchmarks/path_tangent_lag.py [--seeds 3]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from plugcell.kinematics.path_frame import TangentTracker

T = 0.004
N = 1000


def _path(shape: str, speed: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, true unit tangents and the correction's direction (normal), (N, 3)."""
    t = np.arange(N) * T
    if shape == "circle":
        r = 0.1
        a = speed * t / r
        p = np.stack([r * np.cos(a), r * np.sin(a), 0 * t], 1)
        tangent = np.stack([-np.sin(a), np.cos(a), 0 * t], 1)
        normal = np.stack([np.cos(a), np.sin(a), np.ones(N)], 1)
    else:
        p = np.stack([0 * t, speed * t, 0 * t], 1)
        tangent = np.tile([0.0, 1.0, 0.0], (N, 1))
        normal = np.tile([0.3, 0.0, 1.0], (N, 1))
    return p, tangent, normal / np.linalg.norm(normal, axis=1)[:, None]


def run(shape: str, speed: float, jitter: int, lag_s: float, seed: int
        ) -> tuple[float, float, int]:
    """(largest angle °, 99th percentile °, tangents taken) of one run."""
    p, tangent, normal = _path(shape, speed)
    t = np.arange(N) * T
    s = np.clip((t - 0.5) / 0.5, 0, 1)
    e = (s * s * (3 - 2 * s))[:, None] * normal * 2.8e-3
    lags = 1 + np.random.default_rng(seed).integers(0, jitter + 1, N)
    applied = np.array([e[max(k - lag, 0)] for k, lag in enumerate(lags)])
    assumed = np.array([e[max(k - 1, 0)] for k in range(N)])
    tr = TangentTracker(lag_s=lag_s)
    angles, taken, last = [], 0, None
    for k in range(N):
        got = tr.update(p[k] + applied[k] - assumed[k], t[k], assumed[k])
        if got is None:
            continue
        if last is None or not np.array_equal(got, last):
            taken += 1
        last = got.copy()
        angles.append(np.degrees(np.arccos(np.clip(got @ tangent[k], -1.0, 1.0))))
    a = np.array(angles)
    return float(a.max()), float(np.percentile(a, 99)), taken


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3, help="seeds per case (default 3)")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"--seeds must be at least 1, not {args.seeds}")
    print(f"largest angle from the true tangent, ° (99th percentile; tangents taken); the "
          f"worst of {args.seeds} seeds")
    print("| path | speed mm/s | late by | lag bound (0.05 s) | the rule before (0 s) |")
    print("|---|---:|---|---|---|")
    for shape in ("line", "circle"):
        for speed in (0.02, 0.1, 0.25):
            for jitter in (0, 3, 10):
                cells = []
                for lag_s in (0.05, 0.0):
                    runs = [run(shape, speed, jitter, lag_s, s) for s in range(args.seeds)]
                    worst = max(runs)
                    cells.append(f"{worst[0]:.1f} ({worst[1]:.1f}; {worst[2]})")
                late = "1 sample" if jitter == 0 else f"1–{1 + jitter} samples"
                print(f"| {shape} | {speed * 1e3:g} | {late} | {cells[0]} | {cells[1]} |",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
