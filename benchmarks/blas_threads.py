"""What OpenBLAS's threads cost plugcell's small matrices: each case in a fresh process,
once with OpenBLAS's default thread count (one per core) and once with one thread
(``OPENBLAS_NUM_THREADS=1``, what the ``plugcell`` command sets unless the environment
names a count: :func:`plugcell.apps.cli.main`).

Cases (seeded, the arithmetic of the product's own functions):

* ``identify_plant`` — the inverse learning law's plant identification
  (:func:`plugcell.compensation.tracking.plant.identify_plant`): three pairs of 1.2 s
  runs, 3 modes, as ``plugcell path run --learn-law inverse`` identifies after each run;
* ``QR 900×72`` — 40 QR factorisations of a calibration's Jacobian (300 poses × 3
  coordinates, 72 parameters), the Gauss–Newton step of ``plugcell calibrate``.

On a machine whose cores are busy (other processes, a CI beside it) OpenBLAS's threads
spin waiting for each other; on these sizes one thread is the faster.  Usage::

    python benchmarks/blas_threads.py [--repeat 3] [--quick]

prints a table of the median wall time of each case (s) and the ratio (``--quick``: one
mode and 4 factorisations, to check that it runs).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

CASES = {
    "identify_plant": """
import numpy as np
from plugcell.compensation.tracking.plant import ModalPlant, excitation, identify_plant
T = 0.004
J = np.array([[1.0, 0.3, 0.1], [-0.2, 0.9, 0.2], [0.1, -0.1, 1.1]])
head = np.zeros((3, 3, 3)); head[2] = 0.2 * J
true = ModalPlant(T, head, np.array([10.0]), np.array([0.05]), np.array([[0.05 * J, -0.03 * J]]))
u = np.stack([excitation(300, T, 1e-4, seed=s) for s in range(3)])
noise = 1e-7 * np.random.default_rng(0).standard_normal(u.shape)
y = np.stack([true.simulate(x) for x in u]) + noise
identify_plant(u, y, T, modes={modes}, taps=4)
""",
    "QR 900×72": """
import numpy as np
a = np.random.default_rng(0).standard_normal((900, 72))
for _ in range({qr}):
    np.linalg.qr(a)
""",
}


def _once(code: str, one_thread: bool) -> float:
    """Wall time (s) of ``code`` in a fresh interpreter, its imports excluded."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")}
    if one_thread:
        env["OPENBLAS_NUM_THREADS"] = "1"
    timed = ("import time, numpy, scipy.signal, scipy.optimize\n"
             "import plugcell.compensation.tracking.plant\n"
             "t0 = time.perf_counter()\n" + code + "\nprint(time.perf_counter() - t0)\n")
    done = subprocess.run([sys.executable, "-c", timed], env=env, capture_output=True,
                          text=True, check=True)
    return float(done.stdout.split()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs of each case (default 3)")
    parser.add_argument("--quick", action="store_true",
                        help="smaller cases (one mode, 4 factorisations): a check that it runs")
    args = parser.parse_args(argv)
    if args.repeat < 1:
        parser.error(f"--repeat must be at least 1, not {args.repeat}")
    print(f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}; median of {args.repeat} "
          f"runs, s ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})")
    print("| case | OpenBLAS's default threads | one thread | ratio |\n|---|---:|---:|---:|")
    sizes = {"modes": 1, "qr": 4} if args.quick else {"modes": 3, "qr": 40}
    for name, template in CASES.items():
        code = template.format(**sizes)
        many = statistics.median(_once(code, False) for _ in range(args.repeat))
        one = statistics.median(_once(code, True) for _ in range(args.repeat))
        print(f"| {name} | {many:.3f} | {one:.3f} | {many / one:.1f}× |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
