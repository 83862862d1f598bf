"""What limits the learning of a repeated path: the residual error run by run, in time and
in frequency, with the twin's truth (issue 38 §4; a diagnosis, not the learning's input).

    PYTHONPATH=src python benchmarks/learning_residual.py --shape line --speed 250 \\
        --learn 6 --save /tmp/line250.npz [--plot residual.png]
    PYTHONPATH=src python benchmarks/learning_residual.py --load /tmp/line250.npz

Runs one path of ``benchmarks/dynamic_correction.py`` (the same cell, settings and
learning) and records, per run ``k`` of the learning (0: the model's run): the *true*
error ``e_true(t) = p_true − p_cmd`` on the robot's cycles (the twin's truth: the
learning never sees it), the offset ``u_k`` the run used and the error the tracker
measured ``e_k`` on the learning's grid.  It prints, for the last run and per F0 axis:

* the rms in frequency bands (FFT over the motion, the path's start to its end + 0.2 s);
* the rms in time segments (the first and the last 0.5 s, the middle);
* the repeatable part and the part that changes from run to run (the mean and half the
  difference of the last two runs' true errors);
* how well the identified plant predicted each run's change:
  ``e_true,k+1 − e_true,k`` against ``P̂ (u_k+1 − u_k)`` (the plant's error, per band),
  and the same from the measured errors (what a re-identification could see).

``--plot`` draws the last run's residual per axis in time and its amplitude spectrum.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

BANDS = ((0.0, 2.0), (2.0, 8.0), (8.0, 16.0), (16.0, 20.0), (20.0, 30.0), (30.0, 125.0))
AXES = "xyz"


def record(shape: str, speed: float, learn_runs: int, seed: int = 0, **inverse) -> dict:
    """Run the path with the benchmark's learning; the arrays described above."""
    import dataclasses

    from dynamic_correction import INVERSE, LEARNING, case
    from plugcell.compensation.tracking.learning import path_error
    from plugcell.sim.tracked_path import TrackedCell

    cell = TrackedCell(seed=seed)
    rec: dict[str, list] = {"t": [], "true": [], "u": [], "e": [], "m": []}
    state: dict = {}

    def observe(k, learning, run) -> None:
        good = [x for x in run.measurements if x.ok]
        ts = np.array([x.time_s for x in good])
        ps = np.array([x.pose[:3, 3] for x in good]).reshape(-1, 3)
        e, m = path_error(ts, ps, run.t, run.path_pose[:, :3, 3],
                          learning.grid + run.motion[0], learning.settings.cycle_s)
        rec["t"].append(run.t - run.motion[0])
        rec["true"].append(run.true_pose[:, :3, 3] - run.path_pose[:, :3, 3])
        rec["u"].append(learning.u.copy())
        rec["e"].append(e)
        rec["m"].append(m)
        state["learning"] = learning
        state["motion"] = run.motion[1] - run.motion[0]

    settings = dataclasses.replace(LEARNING, inverse=dataclasses.replace(INVERSE, **inverse))
    r = case(cell, shape, speed, learn_runs, "model", settings, tracking=False, observe=observe)
    learning = state["learning"]
    p = learning.plant
    out = {k: np.array(v) for k, v in rec.items()}
    out.update(grid=learning.grid, duration=state["motion"], tau=r["tau"],
               perp_3s=np.array([r["rows"][k]["perp_3s"] for k in
                                 ["model"] + [f"learning {j}" for j in
                                              range(1, learn_runs + 1)]]),
               shape=shape, speed=speed)
    if p is not None:
        out.update(p_cycle=p.cycle_s, p_head=p.head, p_f=p.frequency_hz, p_z=p.damping,
                   p_res=p.residues, p_fit=p.fit)
    return out


def band_rms(x: np.ndarray, cycle_s: float) -> list[float]:
    """rms (per column summed) of ``x`` (n, 3) within each of :data:`BANDS`."""
    X = np.fft.rfft(x - x.mean(0), axis=0)
    f = np.fft.rfftfreq(x.shape[0], cycle_s)
    n = x.shape[0]
    out = []
    for lo, hi in BANDS:
        sel = (f >= lo) & (f < hi)
        w = np.where((f == 0) | (f == f[-1]), 1.0, 2.0)[sel]
        out.append(float(np.sqrt((w[:, None] * np.abs(X[sel]) ** 2).sum(0).sum() / n ** 2)))
    return out


def report(d: dict) -> None:
    T = 0.004
    t_all, true = d["t"], d["true"]
    dur = float(d["duration"])
    print(f"{d['shape']} at {float(d['speed']):g} mm/s, τ {float(d['tau']) * 1e3:.2f} ms; "
          "perp 3σ per run (mm): " + ", ".join(f"{x * 1e3:.4f}" for x in d["perp_3s"]))
    if "p_f" in d:
        print("plant: " + ", ".join(f"{f:.2f} Hz ζ {z:.3f}" for f, z in zip(d["p_f"], d["p_z"],
                                                                           strict=True))
              + f"; R² {float(d['p_fit']):.3f}")
    K = len(true) - 1
    w = (t_all[K] >= 0) & (t_all[K] <= dur + 0.2)
    last = true[K][w]
    print(f"\nrun {K}, true error over the motion, per axis: mean (µm) "
          + " ".join(f"{AXES[i]} {last[:, i].mean() * 1e6:+.1f}" for i in range(3)))
    print("| axis | " + " | ".join(f"{lo:g}–{hi:g} Hz" for lo, hi in BANDS) + " | all |")
    print("|---|" + "---:|" * (len(BANDS) + 1))
    for i in range(3):
        b = band_rms(last[:, i:i + 1], T)
        print(f"| {AXES[i]} | " + " | ".join(f"{x * 1e6:.1f}" for x in b)
              + f" | {last[:, i].std() * 1e6:.1f} |")
    tt = t_all[K][w]
    segs = [("first 0.5 s", tt < 0.5), ("middle", (tt >= 0.5) & (tt <= dur - 0.5)),
            ("last 0.5 s + 0.2", tt > dur - 0.5)]
    print("\nrms about the motion's mean (µm) by segment:")
    for name, s in segs:
        dev = last[s] - last.mean(0)
        print(f"  {name:18s} " + " ".join(f"{AXES[i]} {dev[:, i].std() * 1e6:6.1f}"
                                          for i in range(3)))
    if K >= 2:
        prev = true[K - 1][w]
        rep, chg = 0.5 * (last + prev), 0.5 * (last - prev)
        print("\nthe last two runs: repeatable (mean) / changing (half difference), per band (µm):")
        for i in range(3):
            parts = [" ".join(f"{x * 1e6:6.1f}" for x in band_rms(v[:, i:i + 1], T))
                     for v in (rep, chg)]
            print(f"  {AXES[i]} rep {parts[0]}   chg {parts[1]}")
    if "p_f" in d:
        plant_check(d)


def _plant(d: dict):
    from plugcell.compensation.tracking.plant import ModalPlant

    return ModalPlant(float(d["p_cycle"]), d["p_head"], d["p_f"], d["p_z"], d["p_res"],
                      float(d["p_fit"]))


def plant_check(d: dict) -> None:
    """The identified plant's prediction of each run's change, against the truth."""
    p = _plant(d)
    g = d["grid"]
    t0 = d["t"][0]
    # the learning's grid on the runs' cycles (both 4 ms, the grid from −pre)
    idx = np.round((g - t0[0]) / 0.004).astype(int)
    ok = (idx >= 0) & (idx < t0.size)
    mot = (g >= 0) & (g <= float(d["duration"]) + 0.2) & ok
    print("\nthe plant's prediction of each run's change (rms µm, over the motion + 0.2 s;"
          " true Δe, its part P̂ Δu misses, and the same with the measured Δe):")
    print("| runs | |Δu| | true Δe | true − P̂Δu | measured Δe | measured − P̂Δu | "
          "miss per band (true) " + " ".join(f"{lo:g}–{hi:g}" for lo, hi in BANDS) + " |")
    for k in range(len(d["u"]) - 1):
        du = d["u"][k + 1] - d["u"][k]
        pred = p.simulate(du)
        de_t = np.zeros_like(du)
        de_t[ok] = d["true"][k + 1][idx[ok]] - d["true"][k][idx[ok]]
        de_m = d["e"][k + 1] - d["e"][k]
        mm = mot & d["m"][k] & d["m"][k + 1]
        miss = (de_t - pred)[mot]

        def r(x):
            return float(np.sqrt((x ** 2).sum(1).mean())) * 1e6

        print(f"| {k}→{k + 1} | {r(du[mot]):.1f} | {r(de_t[mot]):.1f} | {r(miss):.1f} | "
              f"{r(de_m[mm]):.1f} | {r((de_m - pred)[mm]):.1f} | "
              + " ".join(f"{x * 1e6:.1f}" for x in band_rms(miss, 0.004)) + " |")


def plot(d: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    K = len(d["true"]) - 1
    dur = float(d["duration"])
    fig, axs = plt.subplots(2, 1, figsize=(10, 7))
    for k, lw in ((1 if K > 1 else 0, 0.5), (K, 0.8)):
        t = d["t"][k]
        w = (t >= -0.3) & (t <= dur + 0.4)
        for i in range(3):
            axs[0].plot(t[w], d["true"][k][w, i] * 1e3, lw=lw,
                        label=f"run {k} {AXES[i]}", alpha=1.0 if k == K else 0.4)
    axs[0].set_xlabel("time on the path (s)")
    axs[0].set_ylabel("true error (mm)")
    axs[0].legend(fontsize=7, ncol=2)
    t = d["t"][K]
    w = (t >= 0) & (t <= dur + 0.2)
    x = d["true"][K][w]
    f = np.fft.rfftfreq(x.shape[0], 0.004)
    X = np.abs(np.fft.rfft(x - x.mean(0), axis=0)) * 2 / x.shape[0]
    for i in range(3):
        axs[1].semilogy(f, X[:, i] * 1e3, lw=0.7, label=AXES[i])
    axs[1].set_xlim(0, 60)
    axs[1].set_ylim(1e-5, None)
    axs[1].set_xlabel("frequency (Hz)")
    axs[1].set_ylabel(f"|FFT| run {K} (mm)")
    axs[1].legend(fontsize=7)
    fig.suptitle(f"{d['shape']} at {float(d['speed']):g} mm/s: the residual after run {K}")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shape", default="line", choices=("line", "circle"))
    ap.add_argument("--speed", type=float, default=250.0, help="mm/s")
    ap.add_argument("--learn", type=int, default=6)
    ap.add_argument("--reidentify", type=int, default=None, choices=(0, 1),
                    help="InverseSettings.reidentify (default: the benchmark's)")
    ap.add_argument("--save", type=Path)
    ap.add_argument("--load", type=Path)
    ap.add_argument("--plot", type=Path)
    args = ap.parse_args(argv)
    if args.load:
        z = np.load(args.load, allow_pickle=False)
        d = {k: z[k] for k in z.files}
    else:
        extra = {} if args.reidentify is None else {"reidentify": args.reidentify}
        d = record(args.shape, args.speed, args.learn, **extra)
        if args.save:
            np.savez(args.save, **d)
    report(d)
    if args.plot:
        plot(d, args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
