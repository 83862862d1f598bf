"""The thesis end to end over services (chapters 7 and 8): what ``plugcell demo`` runs.

Every device is its own OS process in one cell (Zenoh peer mode on loopback, SQLite
journals): the simulated laser TRACKER, the COMPUTE service, the Smart H4 ``H4``
carrying 36 kg and the elbow robot ``KUKA`` (each with its simulated controller
process, its serial line to the PC at 19.2 kbit/s), and the cell CONTROLLER, which
wires them from the cell file of Fig. 7-3 (plus the second robot).  Everything
below is done by robot programs of the shipped library through those services:

1. **Calibration (8.2)** — ``calibration.pdl`` on H4: poses in the working volume,
   a 1 s tracker measurement at each, routed straight into the compute workspace
   (9.3); COMPUTE identifies model 5 and saves it.  The same program measures
   validation poses and COMPUTE validates the saved parameters on them.
2. **Two-stage compensation (8.3)** — ``comp_test.pdl``: the 78-point line test,
   MODEL_COM then SENSOR_COM, each checked by a 1 s measurement.
3. **Demonstration (8.4)** — the stabiliser's 24 holes (four bars of six) carry SMRs;
   the operator (this process) has the tracker measure them in the H4 frame,
   COMPUTE builds the 24 target frames (CalcTarget: best-fit plane and lines), the
   SMRs are taken out and H4 aligns its T-MAC with each target — nominal, model-based,
   sensor-based — while KUKA has the same tracker measure a fixed SMR every 3 s
   (``smr_watch.pdl``); the tracker's queue serves both.

What the simulation knows and the programs do not: the twins' hidden geometry. The
BASE and PROBE *estimates* the calibration program starts from are the truth
disturbed as appendix D's procedures leave them (about 1 mm, 0.02°); the part is
placed 2 mm and 0.2° off its CAD position.

With ``link="rsi"`` (``plugcell demo --link rsi``) step 1 runs with the program on the
PC: H4's robot service streams every move over KUKA RSI (``rsi=HOST:PORT``, the PC
drives) to the twin's RSI robot side in a process of its own (``plugcell twin rsi``:
the dynamic twin, moving in real time), which publishes its T-MAC as it moves; the
tracker measures it as before.  Real time, one robot, calibration and validation only.
"""

from __future__ import annotations

import json
import os
import re
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from plugcell.apps.demo.processes import CellProcesses
from plugcell.apps.reproduce.compensation_8_3 import ExperimentConfig, line_targets
from plugcell.calibration.planning import joint_tour
from plugcell.devices.robot.value_text import numbers_text, rows_text
from plugcell.framework import BlockingClient, ProcessStates, from_data
from plugcell.framework.journal import journal_files, read_journal
from plugcell.io.units import pose_from_robot, robot_from_pose
from plugcell.kinematics.pose_error import pose_error_exact
from plugcell.kinematics.rotations import zyz_to_matrix
from plugcell.metrology import accuracy_statistics
from plugcell.sim.controller.rsi_twin import BANNER as RSI_TWIN_READY
from plugcell.sim.ports import free_port
from plugcell.sim.twin.campaign import working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.world import ReflectorPublisher

__all__ = ["DemoConfig", "DemoError", "ProgressFactory", "run_demo"]

#: ``progress(label)`` → a callable ``(done, total)`` (e.g. :class:`ProgressBar`).
ProgressFactory = Callable[[str], Callable[[int, int], None]]

C = ProcessStates.Completed
PARAMS = "h4_36kg"
PAYLOAD_KG = 36.0
#: What the thesis reports (chapter 8) beside which the demo prints its figures.
THESIS = {
    "calibration.validation.mean_mm": 0.363,  # Table 8-3, model 5, 36 kg (validation)
    "compensation.sigma3_position_mm.model": 0.87,  # Table 8-5
    "compensation.sigma3_position_mm.sensor": 0.12,
    "compensation.iterations_per_point": 2.14,
}


#: How H4's programs reach the arm: the simulated controller over a serial line, or the
#: program on the PC streaming over KUKA RSI to the twin's RSI side.
LINKS = ("serial", "rsi")
#: How long the twin's RSI side waits for each answer in the demo (``plugcell twin rsi
#: --lockstep``): a shared machine that is not real-time answers late often (docs/kuka-rsi.md,
#: Performance), and every late answer shakes the arm — the controller holds the last
#: correction for that cycle, a velocity impulse that rings the arm's modes by
#: millimetres.  The demo shows the cell with a real-time PC.
RSI_LOCKSTEP_S = 1.0
#: The twin's RSI cycle (``#IPO_FAST``).
RSI_CYCLE_S = 0.004
#: The RSI ``Timeout`` of the twin and the service in the demo: a shared, loaded machine
#: answers late often (docs/kuka-rsi.md, Performance); the demo must not stop for it
#: (10 000, the largest the ETHERNET object takes: 40 s of late answers).
RSI_TIMEOUT = 10_000


class DemoError(RuntimeError):
    """A step of the demonstration failed; the message says which and why."""


@dataclass(frozen=True)
class DemoConfig:
    """Sizes and speed (defaults: the full run of issue 9; :meth:`fast` for CI).

    ``link="rsi"``: H4 over RSI in real time (``speed`` 1), calibration and validation
    only, measuring ``measure_ms`` at each pose; ``joint_speed`` (°/s) is the PC's
    planner's joint speed limit.  ``dynamics``: the simulated controllers' arms move in
    time (``dynamics=true`` of the robot services)."""

    seed: int = 0
    speed: float = 20.0
    calibration_poses: int = 150
    validation_poses: int = 50
    line_test: ExperimentConfig = field(default_factory=ExperimentConfig)
    bars: int = 4
    holes_per_bar: int = 6
    watch_period_ms: int = 3000
    link: str = "serial"
    measure_ms: int = 1000
    joint_speed: float = 40.0
    dynamics: bool = False

    def __post_init__(self) -> None:
        if self.link not in LINKS:
            raise ValueError(f"link {self.link!r}: expected one of {', '.join(LINKS)}")
        if self.dynamics and self.link != "serial":
            raise ValueError("dynamics is the simulated controllers' option: over RSI the "
                             "twin moves in time anyway")
        if self.link == "rsi" and self.speed != 1.0:
            raise ValueError(f"over RSI the twin moves in real time: speed must be 1, not "
                             f"{self.speed:g}")

    @classmethod
    def fast(cls, seed: int = 0, link: str = "serial") -> DemoConfig:
        if link == "rsi":
            return cls(seed=seed, speed=1.0, link=link, calibration_poses=15,
                       validation_poses=5, measure_ms=200, joint_speed=90.0)
        return cls(seed=seed, speed=50.0, calibration_poses=50, validation_poses=20,
                   line_test=ExperimentConfig.fast(), bars=2)

    @classmethod
    def full(cls, seed: int = 0, link: str = "serial") -> DemoConfig:
        if link == "rsi":
            return cls(seed=seed, speed=1.0, link=link)
        return cls(seed=seed)


class _Cell:
    """The demo's client: programs, matrices, the journal."""

    def __init__(self, client: BlockingClient, processes: CellProcesses,
                 progress: ProgressFactory | None = None) -> None:
        self.client = client
        self.processes = processes
        self.progress = progress

    def run(self, robot: str, program: str, values: dict[str, str], timeout: float,
            counted: tuple[str, int] | None = None) -> dict:
        """Run ``program`` on ``robot`` to its end; progress from the rows of the
        ``counted`` matrix (``name@ROBOT``, expected rows) while it runs.

        ACTIVATE without Wait completes once the program runs, so the robot service's
        queue stays free for PROGRAM_STATUS meanwhile."""
        started = self.client.create_process(
            robot, "ACTIVATE", "", [program, *(f"{k}={v}" for k, v in values.items())],
            timeout=60).result()
        if started.state is not C:
            raise DemoError(f"{robot} {program}: {started.reason}")
        bar = (self.progress(f"{robot} {program}") if self.progress and counted else None)
        deadline = time.monotonic() + timeout
        shown = -1
        while True:
            if time.monotonic() > deadline:
                raise DemoError(f"{robot} {program}: still running after {timeout:g} s")
            try:  # a look that times out on a loaded machine is looked at again
                status = self.status(robot)
                if status[0].upper() == program.upper() and status[1] != "RUNNING":
                    break
                if bar is not None and counted is not None:
                    shown = min(self.rows(counted[0]), counted[1])
                    bar(shown, counted[1])
            except TimeoutError:
                pass
            time.sleep(0.5)
        if status[1] != "FINISHED":
            console = "\n   ".join(status[4:][-8:])
            raise DemoError(f"{robot} {program}: {status[1]} {status[3]}\n   {console}")
        if bar is not None and counted is not None and shown < counted[1]:
            bar(counted[1], counted[1])
        return {"sim_s": float(status[2]), "console": status[4:]}

    def rows(self, name: str) -> int:
        """Rows of a workspace matrix (0 while it does not exist)."""
        final = self.client.create_process("COMPUTE", "Get Matrix", name).result()
        if final.state is not C or final.data is None:
            return 0
        return int(np.atleast_2d(np.asarray(from_data(final.data))).shape[0])

    def status(self, robot: str) -> list[str]:
        final = self.client.create_process(robot, "PROGRAM_STATUS").result()
        return [str(s) for s in from_data(final.data).reshape(-1)]

    def call(self, service: str, command: str, option: str = "", data: Any = None,
             timeout: float = 120.0) -> np.ndarray | None:
        final = self.client.create_process(service, command, option, data,
                                           timeout=timeout).result()
        if final.state is not C:
            raise DemoError(f"{service} {command} {option}: {final.reason}")
        return None if final.data is None else np.asarray(from_data(final.data), dtype=float)

    def matrix(self, name: str) -> np.ndarray:
        value = self.call("COMPUTE", "Get Matrix", name)
        assert value is not None
        return np.atleast_2d(value)

    def journal(self) -> list[dict[str, Any]]:
        return read_journal(journal_files(self.processes.cell, self.processes.home))


def _pose_stats(rows: np.ndarray, targets: np.ndarray) -> dict[str, float]:
    """Measured − target (6-vectors mm/deg) → the 8.3 statistics (mm, deg)."""
    if len(rows) == 0:
        return {"mean_mm": float("nan"), "sigma3_mm": float("nan"), "max_mm": float("nan"),
                "poses": 0}
    M = np.stack([pose_from_robot(r, "zyz") for r in rows])
    T = np.stack([pose_from_robot(t, "zyz") for t in targets])
    e = pose_error_exact(M, T)
    d = accuracy_statistics(e[:, :3], e[:, 3:]).as_dict("mm", "deg")
    pos = d["position"]
    assert isinstance(pos, dict)
    return {"mean_mm": pos["mean"], "sigma3_mm": pos["three_sigma"], "max_mm": pos["max"],
            "poses": len(rows), "norms_mm": (np.linalg.norm(e[:, :3], axis=1) * 1e3).tolist()}


def _stabiliser(desc_probe: np.ndarray, bars: int, per_bar: int,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CAD holes (robot frame, m), the holes as placed (2 mm, 0.2° off), the plane normal.

    The stabiliser lies where the T-MAC can face the tracker: its holes' frames have the
    orientation of the 8.3 line test (flange ZYZ 0, 90, 0 times the probe's rotation)."""
    R = zyz_to_matrix(0.0, np.pi / 2, 0.0) @ desc_probe[:3, :3]
    centre = np.array([1.6, 0.0, 1.1])
    holes = np.array([centre + (b - (bars - 1) / 2) * 0.12 * R[:, 0]
                      + (h - (per_bar - 1) / 2) * 0.10 * R[:, 1]
                      for b in range(bars) for h in range(per_bar)])
    axis = rng.normal(size=3)
    angle = np.radians(0.2)
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    Rm = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    placed = (holes - centre) @ Rm.T + centre + np.array([2.0, -1.5, 1.0]) * 1e-3
    return holes, placed, R[:, 2]


def run_demo(cfg: DemoConfig, out: Path, say: Callable[[str], None],
             progress: ProgressFactory | None = None) -> dict[str, Any]:
    """Run the three steps over service processes (over RSI: step 1); the result table
    (also in out/)."""
    out.mkdir(parents=True, exist_ok=True)
    home = out / "home"
    cell_name = f"demo{os.getpid()}"
    wall0 = time.monotonic()
    rng = np.random.default_rng(cfg.seed)
    h4 = RobotTwin(TwinScenario(robot="smart_h4", seed=cfg.seed, payload_kg=PAYLOAD_KG))
    kuka = RobotTwin(TwinScenario(robot="elbow6", seed=cfg.seed + 1))
    h4_truth, kuka_truth = h4.reveal_truth(), kuka.reveal_truth()
    result: dict[str, Any] = {"config": {**asdict(cfg), "line_test": cfg.line_test.as_dict()},
                              "cell": cell_name, "thesis": THESIS}
    robots = ("H4",) if cfg.link == "rsi" else ("H4", "KUKA")
    wiring = out / "cell.json"
    wiring.write_text(json.dumps({
        "format": "plugcell-cell-wiring", "version": 1, "cell": cell_name,
        "wires": [{"service": r, "partner": p} for r in robots
                  for p in ("TRACKER", "COMPUTE")]}, indent=2))
    with CellProcesses(cell_name, home) as procs:
        _start_cell(procs, cfg, wiring, say)
        with BlockingClient("DEMO", cell=cell_name) as client:
            cell = _Cell(client, procs, progress)
            _wait_wired(client, robots)
            say(f"   wired by the controller from the cell file: {', '.join(robots)} → "
                "TRACKER, COMPUTE")
            _calibrate(cell, cfg, h4, rng, result, say)
            if cfg.link == "rsi":
                result["rsi"] = _twin_counts(procs.stop("H4-TWIN"))
                say(f"   the twin's RSI side: {result['rsi']['cycles']} cycles of "
                    f"{RSI_CYCLE_S * 1e3:g} ms, {result['rsi']['answered']} answered, "
                    f"Delay {result['rsi']['delay']}")
            else:
                _compensate(cell, cfg, h4_truth.probe, result, say)
                _demonstrate(cell, cfg, h4_truth, kuka_truth, rng, result, say, client)
            result["journal"] = [str(p) for p in journal_files(cell_name, home)]
    result["wall_time_s"] = time.monotonic() - wall0
    (out / "demo.json").write_text(json.dumps(result, indent=2, default=float))
    return result


def _twin_counts(lines: list[str]) -> dict[str, int]:
    """The counts of ``plugcell twin rsi``'s last line (``… N cycles, A answered,
    Delay D``); DemoError if it did not print it."""
    for line in reversed(lines):
        m = re.search(r"(\d+) cycles, (\d+) answered, Delay (\d+)", line)
        if m:
            return {"cycles": int(m[1]), "answered": int(m[2]), "delay": int(m[3])}
    raise DemoError("the twin's RSI side ended without its counts: " + " / ".join(lines[-3:]))


def _start_cell(procs: CellProcesses, cfg: DemoConfig, wiring: Path,
                say: Callable[[str], None]) -> None:
    """Start the cell's processes and wait until each serves."""
    procs.serve("tracker", "TRACKER", seed=cfg.seed + 7, time_scale=1.0 / cfg.speed)
    procs.serve("compute", "COMPUTE")
    if cfg.link == "rsi":
        port = free_port("udp")
        say(f"== cell {procs.cell}: TRACKER, COMPUTE, H4 (Smart H4, 36 kg: the program on "
            f"the PC, every move streamed over KUKA RSI to 127.0.0.1:{port}), the twin's RSI "
            f"side (plugcell twin rsi), CONTROLLER (wiring {wiring}) — each its own "
            "process ==")
        procs.run("H4-TWIN", ["twin", "rsi", "--port", str(port), "--robot", "smart_h4",
                              "--seed", str(cfg.seed), "--payload-kg", f"{PAYLOAD_KG:g}",
                              "--timeout", str(RSI_TIMEOUT), "--lockstep",
                              f"{RSI_LOCKSTEP_S:g}", "--reflector", "H4",
                              "--cell", procs.cell], RSI_TWIN_READY)
        procs.serve("robot", "H4", rsi=f"127.0.0.1:{port}", robot="smart_h4",
                    rsi_timeout=RSI_TIMEOUT, joint_speed=cfg.joint_speed)
    else:
        say(f"== cell {procs.cell}: TRACKER, COMPUTE, H4 (Smart H4, 36 kg), KUKA (elbow), "
            f"CONTROLLER (wiring {wiring}) — each its own process ==")
        for name, robot, seed, payload in (("H4", "smart_h4", cfg.seed, PAYLOAD_KG),
                                           ("KUKA", "elbow6", cfg.seed + 1, 0.0)):
            procs.serve("robot", name, sim="true", robot=robot, seed=seed,
                        payload_kg=payload, speed=cfg.speed, link_baud=19200,
                        **({"dynamics": "true"} if cfg.dynamics else {}))
    procs.serve("cell-controller", "CONTROLLER", wiring=wiring)
    procs.wait_ready()


def _wait_wired(client: BlockingClient, robots: tuple[str, ...],
                timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    for robot in robots:
        while True:
            if client.wait_for(robot, 5.0):
                partners = {p.name for p in client.get(robot).partners}
                if {"TRACKER", "COMPUTE"} <= partners:
                    break
            if time.monotonic() > deadline:
                raise DemoError(f"the controller did not wire {robot} within {timeout:g} s")
            time.sleep(0.2)


def _calibrate(cell: _Cell, cfg: DemoConfig, h4: RobotTwin, rng: np.random.Generator,
               result: dict[str, Any], say: Callable[[str], None]) -> None:
    truth = h4.reveal_truth()
    base = robot_from_pose(truth.base, "zyz") + np.r_[rng.normal(0, 0.7, 3),
                                                          rng.normal(0, 0.02, 3)]
    probe = robot_from_pose(truth.probe, "zyz") + np.r_[rng.normal(0, 0.4, 3),
                                                            rng.normal(0, 0.02, 3)]
    runs = {}
    for step, n, pose_seed, identify in (
        ("calibration", cfg.calibration_poses, 1,
         f"params = calibrate(mJ, mT, model=5, payload={PAYLOAD_KG:g}); "
         f"save_params(params, '{PARAMS}'); s = summary(params)"),
        ("validation", cfg.validation_poses, 2,
         f"p = load_params('{PARAMS}'); v = validate(p, mJ, mT, payload={PAYLOAD_KG:g})"),
    ):
        q = working_volume_joints(h4.description, truth.profile, n,
                                  np.random.default_rng(1000 * cfg.seed + pose_seed))
        if cfg.link == "rsi":  # moves take their time: measure along a short tour
            q = q[joint_tour(q)]
        say(f"== {'1. Calibration (8.2)' if step == 'calibration' else '   validation'}: "
            f"calibration.pdl on H4, {n} poses, {cfg.measure_ms / 1000:g} s measurements "
            f"routed to COMPUTE{' (over RSI, real time)' if cfg.link == 'rsi' else ''} ==")
        t0 = time.monotonic()
        runs[step] = cell.run("H4", "calibration", {
            "configs": rows_text(np.rad2deg(q)), "n_configs": str(n),
            "base_est": numbers_text(base), "probe_est": numbers_text(probe),
            "duration_ms": str(cfg.measure_ms), "route": "TRUE",
            "identify": identify}, timeout=600 + 10 * n, counted=("mJ@H4", n))
        runs[step]["wall_s"] = time.monotonic() - t0
        say(f"   {runs[step]['sim_s']:.0f} s simulated in {runs[step]['wall_s']:.1f} s wall; "
            f"{next((c for c in runs[step]['console'] if c.startswith('serial')), '')}")
    s = cell.matrix("s@H4")[0]
    v = cell.matrix("v@H4")[0]
    identification = [p for p in cell.journal() if p.get("recipient") == "COMPUTE"
                      and "calibrate(" in str(p.get("input", ""))]
    ident_s = ((identification[-1]["finished_ns"] - identification[-1]["received_ns"]) * 1e-9
               if identification else float("nan"))
    result["calibration"] = {
        "poses": int(s[0]), "mean_mm": float(s[2]), "max_mm": float(s[4]),
        "before_mean_mm": float(s[1]),
        "validation": {"poses": int(v[0]), "before_mean_mm": float(v[1]),
                       "mean_mm": float(v[2]), "std_mm": float(v[3]), "max_mm": float(v[4])},
        "identification_s": ident_s,
        "simulated_s": runs["calibration"]["sim_s"], "wall_s": runs["calibration"]["wall_s"],
    }
    say(f"   model 5: calibration poses {s[1]:.2f} → {s[2]:.3f} mm mean; validation "
        f"{v[1]:.2f} → {v[2]:.3f} mm mean, {v[4]:.3f} mm max (thesis 0.363 mean); "
        f"identified in {ident_s:.2f} s")


def _compensate(cell: _Cell, cfg: DemoConfig, probe: np.ndarray, result: dict[str, Any],
                say: Callable[[str], None]) -> None:
    targets = np.array([robot_from_pose(T, "zyz")
                        for T in line_targets(cfg.line_test, probe).reshape(-1, 4, 4)])
    say(f"== 2. Two-stage compensation (8.3): comp_test.pdl on H4, {len(targets)} targets ==")
    t0 = time.monotonic()
    run = cell.run("H4", "comp_test", {
        "targets": rows_text(targets), "n_targets": str(len(targets)), "params_name": PARAMS,
        "payload_kg": f"{PAYLOAD_KG:g}", "sensor": "TRUE", "nominal": "FALSE"},
        timeout=600 + 30 * len(targets), counted=("mS@H4", len(targets)))
    model = _pose_stats(cell.matrix("mM@H4"), targets)
    sensor = _pose_stats(cell.matrix("mS@H4"), targets)
    iterations = cell.matrix("mI@H4").ravel()
    result["compensation"] = {
        "targets": len(targets),
        "sigma3_position_mm": {"model": model["sigma3_mm"], "sensor": sensor["sigma3_mm"]},
        "mean_position_mm": {"model": model["mean_mm"], "sensor": sensor["mean_mm"]},
        "errors_mm": {"model": model["norms_mm"], "sensor": sensor["norms_mm"]},
        "iterations_per_point": float(np.mean(iterations[iterations >= 0])),
        "not_corrected": int(np.sum(iterations < 0)),
        "simulated_s_per_point": run["sim_s"] / len(targets),
        "wall_s": time.monotonic() - t0,
    }
    say(f"   3σ position: model {model['sigma3_mm']:.3f} mm (thesis 0.87), sensor "
        f"{sensor['sigma3_mm']:.3f} mm (thesis 0.12); "
        f"{result['compensation']['iterations_per_point']:.2f} corrections a point; "
        f"{run['sim_s'] / len(targets):.1f} s simulated a point")


def _demonstrate(cell: _Cell, cfg: DemoConfig, h4_truth: Any, kuka_truth: Any,
                 rng: np.random.Generator, result: dict[str, Any],
                 say: Callable[[str], None], client: BlockingClient) -> None:
    n = cfg.bars * cfg.holes_per_bar
    say(f"== 3. Demonstration (8.4): {cfg.bars} bars × {cfg.holes_per_bar} holes, "
        "part localisation, H4 aligns, KUKA watches a fixed SMR ==")
    cad, placed, normal = _stabiliser(h4_truth.probe, cfg.bars, cfg.holes_per_bar, rng)
    assert client.participant.bus is not None
    bus = client.participant.bus.direct()  # the reflectors answer on Zenoh's threads
    smrs = []
    for i, p in enumerate(placed):  # SMRs in the holes, as the tracker sees them
        pub = ReflectorPublisher(bus, f"HOLE{i + 1:02d}", "smr")
        pub.publish(h4_truth.base @ np.r_[np.c_[np.eye(3), p], [[0, 0, 0, 1]]])
        smrs.append(pub)
    kuka_smr = np.array([0.9, 0.45, 0.3])  # m, KUKA base frame
    watch = ReflectorPublisher(bus, "KUKA_SMR", "smr")
    watch.publish(kuka_truth.base @ np.r_[np.c_[np.eye(3), kuka_smr], [[0, 0, 0, 1]]])
    try:
        targets, probe = _localise_part(cell, cfg, cad, normal)
    finally:
        for pub in smrs:  # the SMRs come out of the holes
            pub.close()
    flange = np.array([robot_from_pose(pose_from_robot(t, "zyz") @ np.linalg.inv(probe),
                                          "zyz") for t in targets])
    say(f"   {n} holes measured, {n} target frames by CalcTarget (COMPUTE)")
    t_start = time.time_ns()
    kuka_call = client.create_process("KUKA", "ACTIVATE", "", [
        "smr_watch", f"smr={numbers_text(np.r_[kuka_smr * 1e3, 0, 0, 0])}",
        f"base_est={numbers_text(robot_from_pose(kuka_truth.base, 'zyz'))}", "count=10000",
        f"period_ms={cfg.watch_period_ms}", "duration_ms=200"], timeout=60)
    if kuka_call.result().state is not C:
        raise DemoError(f"KUKA smr_watch: {kuka_call.result().reason}")
    try:
        run = cell.run("H4", "comp_test", {
            "targets": rows_text(targets), "flange_targets": rows_text(flange),
            "n_targets": str(n), "params_name": PARAMS, "payload_kg": f"{PAYLOAD_KG:g}",
            "sensor": "TRUE", "nominal": "TRUE"}, timeout=600 + 40 * n, counted=("mN@H4", n))
    finally:
        watch_final = client.create_process("KUKA", "DEACTIVATE", "", ["smr_watch"],
                                            timeout=30).result()
        watch.close()
    if watch_final.state is not C:
        raise DemoError(f"KUKA DEACTIVATE: {watch_final.reason}")
    result["demonstration"] = _demonstration_figures(cell, n, targets, t_start, run)
    d = result["demonstration"]
    say(f"   mean position error: nominal {d['mean_position_mm']['initial']:.2f} mm, model "
        f"{d['mean_position_mm']['model']:.3f} mm, sensor {d['mean_position_mm']['sensor']:.3f}"
        f" mm; tracker served H4 {d['tracker_served']['robot1']}×, KUKA "
        f"{d['tracker_served']['robot2']}× (waited {d['tracker_wait_s']['robot1']:.1f} s / "
        f"{d['tracker_wait_s']['robot2']:.1f} s)")


def _localise_part(cell: _Cell, cfg: DemoConfig, cad: np.ndarray,
                   normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Part localisation (8.4): the tracker measures every hole in the H4's frame and
    CalcTarget (COMPUTE) turns them into target frames.

    Returns
    -------
    targets : (n, 6) array
        The hole target frames in robot units (mm, ZYZ degrees), as COMPUTE holds them.
    probe : (4, 4) array, m
        The identified probe (the tool point whose frames the targets are).
    """
    # the operator has the tracker measure every hole (H4 frame)
    cell.call("COMPUTE", "Evaluate", "",
              f"clear('holes'); p = load_params('{PARAMS}'); b = frame(p, 'base'); "
              "pr = frame(p, 'probe')")
    cell.call("TRACKER", "Set Base", "euler2tr", cell.matrix("b")[0])
    cell.call("TRACKER", "Set Probe", "euler2tr", np.zeros(6))
    for p in cad:
        cell.call("TRACKER", "Move", "euler2tr", np.r_[p * 1e3, 0, 0, 0])
        cell.call("TRACKER", "Single Measurement",
                  "tr2euler; to=COMPUTE:Set Matrix:holes:append", 1000)
    last = cfg.bars * cfg.holes_per_bar - 1
    corners = f"row(holes, 1), row(holes, {cfg.holes_per_bar})"
    corners = (f"append(append(append({corners}), row(holes, {last - cfg.holes_per_bar + 2})),"
               f" row(holes, {last + 1}))")
    cell.call("COMPUTE", "Evaluate", "",
              f"corners = {corners}; targets = calc_targets(holes, corners, "
              f"[0, 0, 0, 0, 0, 0], per_bar={cfg.holes_per_bar}, "
              f"normal=[{numbers_text(normal)}])")
    targets = cell.matrix("targets")
    return targets, pose_from_robot(cell.matrix("pr")[0], "zyz")


def _demonstration_figures(cell: _Cell, n: int, targets: np.ndarray, t_start: int,
                           run: dict[str, Any]) -> dict[str, Any]:
    """The demonstration's figures: the H4's position errors at the hole targets for the
    nominal, model- and sensor-compensated poses, what the tracker served each robot
    since ``t_start`` (ns) and how long each waited, the spread of the KUKA's fixed SMR."""
    stats = {k: _pose_stats(cell.matrix(f"m{k[0].upper()}@H4"), targets)
             for k in ("nominal", "model", "sensor")}
    served, waited = _tracker_use(cell.journal(), t_start)
    watched = cell.matrix("mW@KUKA")
    return {
        "targets": n,
        "mean_position_mm": {"initial": stats["nominal"]["mean_mm"],
                             "model": stats["model"]["mean_mm"],
                             "sensor": stats["sensor"]["mean_mm"]},
        "initial_measured": stats["nominal"]["poses"],
        "errors_mm": {k: v["norms_mm"] for k, v in stats.items()},
        "tracker_served": {"robot1": served.get("H4", 0), "robot2": served.get("KUKA", 0)},
        "tracker_wait_s": {"robot1": waited.get("H4", 0.0), "robot2": waited.get("KUKA", 0.0)},
        "kuka_smr_spread_mm": float(np.linalg.norm(watched[:, :3].std(axis=0)))
        if len(watched) > 1 else float("nan"),
        "simulated_s": run["sim_s"],
    }


def _tracker_use(journal: list[dict[str, Any]], since_ns: int) -> tuple[dict[str, int],
                                                                        dict[str, float]]:
    """Measurements the tracker completed for each robot, and the time each waited in
    its queue (first update − received), from the tracker's journal."""
    served: dict[str, int] = {}
    waited: dict[str, float] = {}
    for p in journal:
        if p.get("recipient") != "TRACKER" or (p.get("received_ns") or 0) < since_ns:
            continue
        sender = str(p.get("sender"))
        if p.get("command") == "Single Measurement" and p.get("state") == "Completed":
            served[sender] = served.get(sender, 0) + 1
        updates = p.get("updates") or []
        if updates and p.get("received_ns"):
            first = min(u["t_ns"] for u in updates)
            waited[sender] = waited.get(sender, 0.0) + max(0, first - p["received_ns"]) * 1e-9
    return served, waited
