"""Path deviation of the twin at speed: a 1 m straight line (LIN) on the Smart H4 twin.

    .venv/bin/python benchmarks/twin_path_deviation.py [--speeds 50,100,250] [--payload 36]
        [--seed 0] [--plot FILE.png]

The line is planned with ``plugcell.motion`` on the robot's *nominal* model, sampled at
the 4 ms interface cycle and streamed, without any correction, to the dynamic twin
(``plugcell.sim.twin.dynamics``: dead time, cascade servo, friction, backlash, encoder
counts, first structural modes) whose link angles go through the twin's static physics
(true geometry, gravity and payload compliance, transmission error, link bending).

The deviation is measured as ISO 9283 measures path accuracy on a taught path: against
the straight line through the TCP's true rest positions at the start and at the end
(the points a user teaches), in planes perpendicular to it — ``perpendicular``, max and
3σ over the motion (3σ: three standard deviations of the distance about its mean plus
that mean, ``mean + 3σ``) — and along it: the TCP's position along the line minus the
commanded one at the same time (the following error, dead time included): max of its
magnitude, its mean (the lag) and 3σ about the mean.  ``dynamic`` is the perpendicular
deviation from the path the same robot takes quasi-statically (the static twin at the
commanded joints), i.e. what the motion adds.  Deterministic: any machine prints the same figures.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from plugcell.kinematics import forward
from plugcell.motion import LIN, CartesianLimits, JointLimits, plan
from plugcell.sim.twin.dynamics import DynamicTwin
from plugcell.sim.twin.scenario import TwinScenario

CYCLE = 0.004
#: Start of the line (joint readings, deg): TCP in front of the robot, in the
#: thesis's working volume; the line runs 1 m along the robot's y axis.
START_DEG = [-15.0, -75.0, -190.0, 0.0, 75.0, 0.0]
DIRECTION = np.array([0.0, 1.0, 0.0])
LENGTH = 1.0
#: Joint limits of a 200 kg-class robot (as benchmarks/motion_sampling.py) and the TCP's
#: acceleration and jerk (our estimates, KUKA's default CP acceleration is of this size).
JOINTS = JointLimits(np.radians([100, 90, 90, 170, 120, 190]),
                     np.radians([300, 250, 300, 500, 500, 700]),
                     np.radians([2000, 1500, 2000, 4000, 4000, 5000]))
ACCELERATION, JERK = 2.0, 20.0
REST_BEFORE, SETTLE = 0.1, 0.5

#: Published figures for robots of this class (docs/twin.md, "The twin in time").
PUBLISHED = [
    ("ISO 9283 AT_p, large robots' product specifications (order of)", "0.2 – 2 mm"),
    ("Slamani, Nubiola & Bonev 2012, ABB IRB 1600, dynamic radial error 700 mm/s",
     "±0.25 mm"),
]


def run(speed_mm_s: float, payload: float, seed: int) -> dict[str, np.ndarray | float]:
    """One line at ``speed_mm_s``: the deviations and the traces for the plot."""
    scenario = TwinScenario(robot="smart_h4", seed=seed, payload_kg=payload)
    dyn = DynamicTwin(scenario)
    desc = dyn.twin.description
    q0 = np.radians(START_DEG)
    fk0 = forward(desc, None, q0, "nominal")
    tool = np.linalg.inv(fk0.flange) @ fk0.tcp
    T1 = fk0.tcp.copy()
    T1[:3, 3] += LENGTH * DIRECTION
    v = speed_mm_s * 1e-3
    cart = CartesianLimits(v, ACCELERATION, JERK, 1.0, 4.0, 40.0)
    traj = plan(desc, q0, [LIN(target=T1)], JOINTS, cart)
    t_move = traj.cycle_times(CYCLE)
    q_move = traj.sample(t_move, 0).q
    pre, post = round(REST_BEFORE / CYCLE), round(SETTLE / CYCLE)
    q_cmd = np.vstack([np.repeat(q0[None], pre, 0), q_move, np.repeat(q_move[-1:], post, 0)])
    t = (np.arange(len(q_cmd)) - pre) * CYCLE
    dyn.reset(q0)
    out = dyn.run(q_cmd)
    tcp = (dyn.true_flanges(out["link"]) @ tool)[:, :3, 3]
    # the quasi-static path: the static twin at the commanded joints (gears on the
    # flank of the motion, as RobotTwin.move_joints leaves them)
    lost = dyn.twin.reveal_truth().profile.lost_motion
    static = (dyn.true_flanges(q_cmd - 0.5 * lost * np.sign(q_move[-1] - q0)) @ tool)[:, :3, 3]
    commanded = _nominal_tcp(desc, q_cmd, tool)
    s_cmd = (commanded - commanded[0]) @ DIRECTION  # commanded distance along the line
    a, b = tcp[pre - 1], tcp[-1]  # taught: the true rest positions at start and end
    u = (b - a) / np.linalg.norm(b - a)
    rel = tcp - a
    along = rel @ u
    perp_vec = rel - along[:, None] * u
    perp = np.linalg.norm(perp_vec, axis=1)
    srel = static - a
    s_along = srel @ u
    s_perp = srel - s_along[:, None] * u
    order = np.argsort(s_along)
    dyn_vec = perp_vec - np.stack([np.interp(along, s_along[order], s_perp[order, k])
                                   for k in range(3)], axis=1)
    window = (t >= 0) & (t <= traj.duration + 0.2)
    following = along - s_cmd * (np.linalg.norm(b - a) / LENGTH)
    pw, fw = perp[window], following[window]
    return {"speed": speed_mm_s, "duration": traj.duration,
            "perp_max": pw.max(), "perp_3s": pw.mean() + 3 * pw.std(),
            "along_max": np.abs(fw).max(), "along_mean": fw.mean(), "along_3s": 3 * fw.std(),
            "dyn_max": np.linalg.norm(dyn_vec[window], axis=1).max(),
            "t": t, "along": along, "perp": perp, "following": following, "window": window}


def _nominal_tcp(desc, q: np.ndarray, tool: np.ndarray) -> np.ndarray:
    """The controller's TCP positions (nominal model) of commanded joints, vectorised."""
    return (forward(desc, None, q, "nominal").flange @ tool)[:, :3, 3]


def plot(results: list[dict], path: Path, payload: float) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7.5, 6.0))
    for i, r in enumerate(results):
        w = r["window"]
        ax1.plot(r["along"][w] * 1e3, r["perp"][w] * 1e3, f"C{i}",
                 label=f"{r['speed']:g} mm/s")
        ax2.plot(r["t"][w], r["following"][w] * 1e3, f"C{i}", label=f"{r['speed']:g} mm/s")
    ax1.set_xlabel("position along the taught line (mm)")
    ax1.set_ylabel("perpendicular deviation (mm)")
    ax1.set_title(f"Smart H4 twin, {payload:g} kg, 1 m LIN, nominal model, no correction")
    ax1.legend(fontsize=8)
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("along the path: actual − commanded (mm)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--speeds", default="50,100,250", help="TCP speeds, mm/s")
    ap.add_argument("--payload", type=float, default=36.0, help="kg")
    ap.add_argument("--seed", type=int, default=0, help="the twin's scenario seed")
    ap.add_argument("--plot", type=Path, help="write a PNG of the deviations")
    args = ap.parse_args(argv)
    speeds = [float(s) for s in args.speeds.split(",")]
    results = [run(v, args.payload, args.seed) for v in speeds]
    print(f"Smart H4 twin (seed {args.seed}, {args.payload:g} kg), 1 m LIN along y, "
          f"cycle {CYCLE * 1e3:g} ms, nominal model, no correction")
    print("| speed mm/s | duration s | perpendicular max mm | perpendicular 3σ mm | "
          "along max mm | along mean mm | along 3σ mm | dynamic part max mm |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in results:
        print(f"| {r['speed']:g} | {r['duration']:.2f} | {r['perp_max'] * 1e3:.3f} | "
              f"{r['perp_3s'] * 1e3:.3f} | {r['along_max'] * 1e3:.3f} | "
              f"{r['along_mean'] * 1e3:.3f} | "
              f"{r['along_3s'] * 1e3:.3f} | {r['dyn_max'] * 1e3:.3f} |")
    print("\npublished, robots of this class:")
    for what, value in PUBLISHED:
        print(f"  {what}: {value}")
    if args.plot:
        print(f"plot: {args.plot}" if plot(results, args.plot, args.payload)
              else "plot: matplotlib is not installed")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
