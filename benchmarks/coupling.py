"""What a vendor joint convention costs: the coupled Fanuc M-20iA against the same robot
on its kinematic joints (``desc.uncoupled()``, readings mapped beforehand).

    .venv/bin/python benchmarks/coupling.py [--repeat 5]

Prints one table: forward kinematics and the manipulator Jacobian of 1 000
configurations, inverse kinematics of 50 poses, a calibration (model 3, 80 simulated
poses) and the compensation of 50 poses — best of ``--repeat`` runs each, the two
variants run alternately so that a loaded machine slows both alike.  The two
columns compute the same numbers (the tests check that); the difference is the cost of
θ_kin = M·q + offset and of J·M at the boundary.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from collections.abc import Callable

import numpy as np

from plugcell.calibration import CalibrationData, Calibrator, ErrorModel
from plugcell.calibration.identifiability import random_configurations
from plugcell.compensation import IdentifiedModel, compensate
from plugcell.io.robots import load_robot
from plugcell.kinematics import RobotDescription, forward, inverse, manipulator_jacobian


def _cases(desc: RobotDescription, q: np.ndarray) -> dict[str, Callable[[], object]]:
    """The timed operations on ``desc`` at joint values ``q`` (its own joint variables)."""
    T = forward(desc, None, q).flange
    truth = ErrorModel.create(desc, "serial", gravity=True)
    rng = np.random.default_rng(3)
    truth = truth.with_values(rng.normal(0, 3e-4, len(truth.space)) * np.array(
        [1e-3 if p.unit == "rad/(N·m)" else 1.0 for p in truth.space]))
    qc = q[:80]
    data = CalibrationData.from_poses(qc, truth.predict(qc))
    model = IdentifiedModel(Calibrator(desc, "serial+gravity").fit(data).model)
    targets = model.pose(q[:50])
    return {
        "forward kinematics, 1 000 configurations": lambda: forward(desc, None, q),
        "manipulator Jacobian, 1 000 configurations": (
            lambda: manipulator_jacobian(desc, None, q)),
        "inverse kinematics, 50 poses (seeded)": (
            lambda: inverse(desc, None, T[:50], seed=q[:50] + 0.05)),
        "calibration, model 3, 80 poses": lambda: Calibrator(desc, "serial+gravity").fit(data),
        # a few targets lie beyond the nominal reach (stretched arm): reported, not raised
        "compensation, 50 poses": lambda: compensate(model, targets, raise_errors=False),
    }


def _best_interleaved(a: Callable[[], object], b: Callable[[], object], repeat: int
                      ) -> tuple[float, float]:
    """Best time of ``a`` and of ``b``, run alternately (a loaded machine hurts both alike)."""
    ta, tb = [], []
    for _ in range(repeat):
        for f, out in ((a, ta), (b, tb)):
            t0 = time.perf_counter()
            f()
            out.append(time.perf_counter() - t0)
    return min(ta), min(tb)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="runs per case (best is shown)")
    args = ap.parse_args(argv)
    coupled = load_robot("fanuc_m20ia")
    kinematic = coupled.uncoupled()
    model = ErrorModel.create(coupled, "serial")
    q = random_configurations(model, 1000, seed=1)
    a = _cases(coupled, q)
    b = _cases(kinematic, coupled.kinematic_joints(q))
    print(f"machine: {platform.machine()}, {platform.processor() or 'cpu'}, "
          f"Python {platform.python_version()}; best of {args.repeat}, run alternately")
    print(f"{'fanuc_m20ia':44s} {'readings (coupled)':>19s} {'kinematic joints':>17s} "
          f"{'ratio':>6s}")
    for k in a:
        ta, tb = _best_interleaved(a[k], b[k], args.repeat)
        print(f"{k:44s} {ta * 1e3:16.2f} ms {tb * 1e3:14.2f} ms {ta / tb:6.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
