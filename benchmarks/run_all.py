"""Every benchmark, one after the other, each printing its table: ``make bench``.

    .venv/bin/python benchmarks/run_all.py [--full]

Without ``--full`` the transport benchmark runs in its quick mode, the learned
residual layer's benchmarks run small and write their pages to the temporary
directory (``--full`` regenerates docs/results/ur10-residual.md and twin-residual.md), the
calibration scaling stops at 10 000 poses and the web API fuzz sends 20 000
requests (not 100 000), so the whole run takes a few minutes on 2 cores; ``--full``
adds the planning comparisons (twin: ~5 min, IPA UR10 when its data are present).  Speed
is measured here, never asserted in tests.
"""

from __future__ import annotations

import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    full = "--full" in argv
    plugcell = [sys.executable, "-m", "plugcell"]
    scratch = Path(tempfile.gettempdir()) / "plugcell-bench"
    runs = [
        ("transport (thesis 5.3)",
         [*plugcell, "bench", "transport", *([] if full else ["--quick"])]),
        ("calibration (thesis 8.2)",
         [*plugcell, "bench", "calibration", "--max-poses", "100000" if full else "10000"]),
        ("service path per streamed frame", [sys.executable, str(HERE / "service_frames.py")]),
        ("journal: schema 1 against 2, recovery", [sys.executable, str(HERE / "journal.py")]),
        ("one round trip, step by step",
         [sys.executable, str(HERE / "round_trip_trace.py"),
          *([] if full else ["--cycles", "500"])]),
        ("one round trip, by function (cProfile, one process)",
         [sys.executable, str(HERE / "round_trip_profile.py"),
          *([] if full else ["--cycles", "1000"])]),
        ("one round trip's CPU by process and thread, beside raw Zenoh's",
         [sys.executable, str(HERE / "round_trip_cpu.py"),
          *([] if full else ["--cycles", "2000"])]),
        ("a small request's latency part by part: raw Zenoh, event-loop floor +, plugcell",
         [sys.executable, str(HERE / "durability_floor.py"),
          *([] if full else ["--cycles", "2000"])]),
        ("compensation (thesis 6.5.1)", [*plugcell, "bench", "compensation"]),
        ("robot programs on the twin: a drilling pattern and a milling contour",
         [sys.executable, str(HERE / "program_twin.py"),
          *(["--out", "docs/results/program-twin.md"] if full else [])]),
        ("robot programs compensated (10 000-target KRL, RAPID, URScript)",
         [sys.executable, str(HERE / "program_compensation.py"),
          *([] if full else ["--repeat", "1"])]),
        ("an idle cell: 20 services, CPU share",
         [sys.executable, str(HERE / "idle_cost.py"), *([] if full else ["--seconds", "15"])]),
        ("command start-up", [sys.executable, str(HERE / "cli_startup.py")]),
        ("OpenBLAS threads on small matrices", [sys.executable, str(HERE / "blas_threads.py")]),
        ("EGM path tangent under a late correction",
         [sys.executable, str(HERE / "path_tangent_lag.py")]),
        ("UR10 from ur_description: xacro in, calibration, UR kinematics out",
         [sys.executable, str(HERE / "urdf_roundtrip_ur10.py"),
          *([] if full else ["--out", str(scratch / "urdf_ur10.md")])]),
        ("trajectories: one 4 ms interpolation cycle (PTP; LIN with IK per sample)",
         [sys.executable, str(HERE / "motion_sampling.py"),
          *([] if full else ["--cycles", "200"])]),
        ("vendor joint conventions (cost of a coupling)",
         [sys.executable, str(HERE / "coupling.py")]),
        ("campaign planning: speed", [sys.executable, str(HERE / "planning_speed.py")]),
        *([("campaign planning: planned vs random on the twin",
            [sys.executable, str(HERE / "planning_twin.py")])] if full else []),
        *([("campaign planning: IPA UR10 real data",
            [sys.executable, str(HERE / "planning_ur10.py")])]
          if full and (HERE.parents[1] / "shared" / "data" / "ipa-robot-accuracy").is_dir()
          else []),
        # quick runs write their pages to the temporary directory, not over docs/results
        ("learned residual layer on the twin",
         [sys.executable, str(HERE / "residual_twin.py"),
          *([] if full else ["--poses", "300", "--out", str(scratch / "twin-residual.md")])]),
        ("drift watch over an 8-hour shift (twin)",
         [sys.executable, str(HERE / "drift_twin.py"),
          *([] if full else ["--out", str(scratch / "drift-watch.md")])]),
        ("learned residual layer on the IPA UR10 (skipped without the data)",
         [sys.executable, str(HERE / "residual_ur10.py"),
          *([] if full else ["--quick", "--out", str(scratch / "ur10-residual.md")])]),
        *([("a robot moved: short campaign with a prior, IPA UR10 (issue 36; skipped "
             "without the data)", [sys.executable, str(HERE / "short_campaign_ur10.py")])]
          if full else []),
        ("KUKA RSI: answer latency at 250 Hz beside a bare UDP echo (issue 37)",
         [sys.executable, str(HERE / "rsi_latency.py"),
          "--seconds", "600" if full else "20"]),
        ("the robot service over RSI running a program: the twin's round trips beside a "
         "bare UDP echo (issue 37)",
         [sys.executable, str(HERE / "rsi_latency.py"), "--in-service",
          "--seconds", "600" if full else "20"]),
        ("the robot service over EGM running a program: the twin's round trips beside a "
         "bare UDP echo (issue 37)",
         [sys.executable, str(HERE / "egm_latency.py"), "--in-service",
          "--seconds", "600" if full else "20"]),
        ("tracker stream at 1 kHz: sample → subscriber latency, share delivered (issue 38)",
         [sys.executable, str(HERE / "tracker_stream.py"), "--seconds", "10" if full else "3"]),
        ("twin path deviation at speed: 1 m LIN at 50/100/250 mm/s (issue 37)",
         [sys.executable, str(HERE / "twin_path_deviation.py"),
          *([] if full else ["--speeds", "250"])]),
        ("the twin that moves in time: a cycle, a pose, a move (issue 37)",
         [sys.executable, str(HERE / "twin_cycle_cost.py"),
          *([] if full else ["--cycles", "300", "--moves", "1"])]),
        ("wire decoder fuzz", [sys.executable, str(HERE / "fuzz_wire.py")]),
        ("signed requests (cost)", [sys.executable, str(HERE / "signing.py"),
                                    *(["--fuzz", "100000"] if full else [])]),
        ("OPC UA gateway: method call, subscription updates",
         [sys.executable, str(HERE / "opcua_gateway.py"),
          *(["--calls", "1000", "--cold", "10"] if full else [])]),
        ("web API fuzz",
         [sys.executable, str(HERE / "fuzz_web.py"), *([] if full else ["--cases", "20000"])]),
    ]
    print(f"machine: {platform.machine()}, {platform.processor() or 'cpu'}, "
          f"Python {platform.python_version()}, {platform.system()} {platform.release()}")
    failed = 0
    for title, cmd in runs:
        print(f"\n=== {title} ===", flush=True)
        t0 = time.monotonic()
        code = subprocess.call(cmd)
        print(f"({time.monotonic() - t0:.1f} s, exit {code})", flush=True)
        failed += code != 0
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
