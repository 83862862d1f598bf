"""Benchmark: a whole robot program compensated (issue 35, goal ≤ 5 s for 10 000 targets).

    .venv/bin/python benchmarks/program_compensation.py [--targets N] [--repeat R]
                                                         [--dialects krl,rapid,urscript]
                                                         [--wrong-confdata]

Builds PARAMS.json from a fast twin calibration (Smart H4, 36 kg, model 5, 60 poses),
writes a milling-like program per dialect — ``N`` inline Cartesian targets along a path
through the working volume (joint-space interpolation between 40 configurations, the
nominal TCP of a spindle tool in a work-object frame) — and runs
``plugcell compensate --program`` on it in-process, ``R`` times.  Prints a table: the
best and median wall time per dialect and stage (read, compensate, write) and the
targets per second.  Speed is measured here, never asserted in tests.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _params(tmp: Path) -> tuple[Path, object]:
    from plugcell.io.params import params_json
    from plugcell.sim.twin.calibrated import calibrate_twin
    from plugcell.sim.twin.robot import RobotTwin
    from plugcell.sim.twin.scenario import TwinScenario

    result = calibrate_twin(RobotTwin(TwinScenario(seed=3, payload_kg=36.0)), 60,
                            joints_seed=4, tracker_seed=3)
    p = tmp / "params.json"
    p.write_text(params_json(result))
    return p, result


def _pocket(n: int, T0: np.ndarray) -> np.ndarray:
    """``n`` tool poses of a pocket milled in layers: a zig-zag raster over 400 × 300 mm,
    5 layers 10 mm apart, the spindle's orientation fixed (that of ``T0``)."""
    layers = 5
    per = int(np.ceil(n / layers))
    rows = max(2, int(np.sqrt(per * 300 / 400)))
    cols = int(np.ceil(per / rows))
    u = np.linspace(-200e-3, 200e-3, cols)
    v = np.linspace(-150e-3, 150e-3, rows)
    pts = []
    for k in range(layers):
        for r, vv in enumerate(v):
            for uu in (u if r % 2 == 0 else u[::-1]):
                pts.append((uu, vv, -10e-3 * k))
    pts = np.array(pts[:n])
    T = np.tile(T0, (n, 1, 1))
    T[:, :3, 3] = T0[:3, 3] + pts @ T0[:3, :3].T
    return T


def _programs(tmp: Path, n: int, dialects: list[str], wrong_confdata: bool = False
              ) -> dict[str, Path]:
    from plugcell.compensation import NominalModel, nominal_joints
    from plugcell.io.robots import load_robot
    from plugcell.io.units import notation_from_pose, pose_from_notation
    from plugcell.sim.twin.campaign import working_volume_joints
    from plugcell.sim.twin.profile import TwinProfile

    h4 = load_robot("smart_h4")
    q0 = working_volume_joints(h4, TwinProfile.load("smart_h4"), 40, np.random.default_rng(7))[4]
    out = {}
    for d in dialects:
        notation = {"krl": "kuka", "rapid": "abb", "urscript": "ur"}[d]
        if d == "krl":
            base_v, tool_v = [1200, -150, 300, 90, 0, 0], [12.5, -3, 215, 0, -30, 0]
        elif d == "rapid":
            base_v = [1200, -150, 300, 0.707107, 0, 0, 0.707107]
            tool_v = [12.5, -3, 215, 0.965926, 0, -0.258819, 0]
        else:
            base_v, tool_v = [1.2, -0.15, 0.3, 0, 0, 1.5708], [0.0125, -0.003, 0.215, 0,
                                                                -0.5236, 0]
        B = pose_from_notation(np.array(base_v, float), notation)
        tool = pose_from_notation(np.array(tool_v, float), notation)
        T = np.linalg.inv(B) @ _pocket(n, NominalModel(h4, tool).pose(q0)[0])
        ref = np.zeros((n, 7 if d == "rapid" else 6))
        if d == "rapid":
            ref[:, 3] = 1
        v = notation_from_pose(T, notation, ref)
        if d == "krl":
            lines = ["DEF mill( )", f"$BASE={{FRAME: X {base_v[0]},Y {base_v[1]},Z {base_v[2]},"
                     f"A {base_v[3]},B {base_v[4]},C {base_v[5]}}}",
                     "$TOOL={X 12.5,Y -3.0,Z 215.0,A 0.0,B -30.0,C 0.0}"]
            lines += [f"LIN {{X {x:.3f},Y {y:.3f},Z {z:.3f},A {a:.4f},B {b:.4f},C {c:.4f}}} "
                      "C_DIS" for x, y, z, a, b, c in v]
            lines.append("END")
            path = tmp / "mill.src"
        elif d == "rapid":
            lines = ["MODULE Mill", "  PERS tooldata tS:=[TRUE,[[12.5,-3,215],[0.965926,0,"
                     "-0.258819,0]],[8,[0,0,90],[1,0,0,0],0,0,0]];",
                     "  TASK PERS wobjdata wF:=[FALSE,TRUE,\"\",[[1200,-150,300],[0.707107,0,0,"
                     "0.707107]],[[0,0,0],[1,0,0,0]]];", "  PROC main()"]
            # confdata as a post-processor writes it: the quarters of axes 1, 4, 6
            q, _, _ = nominal_joints(NominalModel(h4, tool), B @ T)
            cf = np.floor(q[:, [0, 3, 5]] / (np.pi / 2)).astype(int)
            if wrong_confdata:  # a post that writes [0,0,0,0]: every target searched
                cf[:] = 0
            lines += [f"    MoveL [[{x:.3f},{y:.3f},{z:.3f}],[{a:.6f},{b:.6f},{c:.6f},{e:.6f}],"
                      f"[{c1},{c4},{c6},0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,z1,tS\\WObj:=wF;"
                      for (x, y, z, a, b, c, e), (c1, c4, c6) in zip(v, cf, strict=True)]
            lines += ["  ENDPROC", "ENDMODULE"]
            path = tmp / "Mill.mod"
        else:
            lines = ["def mill():", "  set_tcp(p[0.0125,-0.003,0.215,0,-0.5236,0])",
                     "  global Plane_1=p[1.2,-0.15,0.3,0,0,1.5708]"]
            lines += [f"  movel(pose_trans(Plane_1, p[{x:.6f},{y:.6f},{z:.6f},{a:.6f},{b:.6f},"
                      f"{c:.6f}]), a=1.2, v=0.25, r=0.001)" for x, y, z, a, b, c in v]
            lines.append("end")
            path = tmp / "mill.script"
        path.write_text("\n".join(lines) + "\n")
        out[d] = path
    return out


def _run_once(params: Path, program: Path, out: Path) -> dict[str, float]:
    """The command's stages, timed: read, compensate, render + write."""
    from plugcell.apps.commands.files import read_compensation_model
    from plugcell.compensation import IdentifiedModel
    from plugcell.io.programs import read_program
    from plugcell.io.programs.filter import filter_targets

    class _A:
        robot = None

    t0 = time.perf_counter()
    result = read_compensation_model(params, _A(), True)
    t1 = time.perf_counter()
    prog, _ = read_program(program)
    t2 = time.perf_counter()
    fr = filter_targets(prog, lambda tool: IdentifiedModel(result.model, tool),
                        payload_kg=36.0)
    t3 = time.perf_counter()
    texts = prog.render(fr.edits)
    out.write_bytes(texts[0].encode("latin-1"))
    t4 = time.perf_counter()
    assert not fr.failed, fr.failed[0].reason
    warned = sum(r.reason.startswith("configuration") for r in fr.reports)
    if warned:
        print(f"({program.name}: {warned} targets without a solution in the program's arm "
              "configuration)")
    return {"params": t1 - t0, "read": t2 - t1, "compensate": t3 - t2, "write": t4 - t3,
            "total": t4 - t0, "n": len([r for r in fr.reports if r.compensated])}


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--targets", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dialects", default="krl,rapid,urscript")
    ap.add_argument("--wrong-confdata", action="store_true",
                    help="RAPID: confdata [0,0,0,0] everywhere (the configuration search's cost)")
    a = ap.parse_args(argv)
    dialects = a.dialects.split(",")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        t0 = time.perf_counter()
        params, _ = _params(tmp)
        progs = _programs(tmp, a.targets, dialects, a.wrong_confdata)
        print(f"set-up (twin calibration, {a.targets}-target programs): "
              f"{time.perf_counter() - t0:.1f} s; load average {os.getloadavg()[0]:.1f} on "
              f"{os.cpu_count()} cores")
        print(f"\n| dialect | targets | read s | compensate s | write s | total s (best / median"
              f" of {a.repeat}) | targets/s |")
        print("|---|---|---|---|---|---|---|")
        for dname, p in progs.items():
            runs = [_run_once(params, p, tmp / f"out{p.suffix}") for _ in range(a.repeat)]
            best = min(runs, key=lambda r: r["total"])
            med = statistics.median(r["total"] for r in runs)
            print(f"| {dname} | {best['n']} | {best['read']:.2f} | {best['compensate']:.2f} | "
                  f"{best['write']:.2f} | {best['total']:.2f} / {med:.2f} | "
                  f"{best['n'] / best['total']:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
