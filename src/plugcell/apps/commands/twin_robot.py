"""``plugcell twin rsi`` / ``twin egm``: the dynamic twin as a KUKA controller streaming
RSI, or an ABB controller's EGM loop, standalone.

::

    plugcell twin rsi --port P [--ip 127.0.0.1] [--mode absolute|relative]
                      [--correction joint|cartesian [--frame base|tool]]
                      [--cycle IPO_FAST|IPO] [--timeout 100]
                      [--bind HOST[:PORT]] [--robot R] [--seed S] [--payload-kg M]
                      [--joints Q1,…,Q6] [--lockstep S] [--reflector NAME [--cell C]]
                      [--lin DX,DY,DZ … | --program FILE [--library DIR …]]
                      [--speed MM_S] [--path-delay S] [--end-after S] [--duration S]
                      [--stats FILE] [--rt-priority N] [--cpu CPUS] [--mlock]
    plugcell twin egm [--port 6510] [--ip 127.0.0.1] [--timeout 1.0] [--bind HOST[:PORT]]
                      [--mode joint|pathcorr (--lin DX,DY,DZ … | --program FILE
                      [--library DIR …]) [--speed MM_S] [--path-delay S] [--end-after S]]
                      [--robot R] [--seed S] [--payload-kg M] [--joints Q1,…,Q6]
                      [--reflector NAME [--cell C]] [--duration S] [--stats FILE]
                      [--rt-priority N] [--cpu CPUS] [--mlock]

It stands where a KUKA controller running plugcell's KRL program (``plugcell rsi
files``) stands: from ``RSI_ON`` on it sends ``<Rob>`` every cycle to the PC's ``--ip``
and ``--port`` (the ethernet file's ``IP_NUMBER`` and ``PORT``) and applies the answers
to the dynamic twin (:class:`~plugcell.sim.controller.rsi_robot.RsiRobot` on a
:class:`~plugcell.sim.twin.dynamics.DynamicTwin`), so that ``plugcell rsi run`` and
``plugcell serve robot --rsi`` can be tried without a controller.  It prints one line
with its own address when it streams, one summary line when it ends, and exits 0 at
``--duration`` or SIGTERM/SIGINT, 3 when RSI stopped at ``Timeout`` (the reason on
stderr), 2 for bad options.  ``--lin`` gives the controller a program of its own (issue
37's mode (b), *the robot drives, the PC corrects*: LIN moves between ``RSI_ON`` and
``RSI_OFF``, :mod:`~plugcell.sim.controller.own_program`) and ``--program FILE`` one
from a file (a path file as ``plugcell path run --path`` reads it, or a ``.pdl`` robot
program's straight moves; the arm starts at its first point), on which the answers'
corrections are superimposed; the summary then says whether the program ended, the
largest shift of its TCP and how far its T-MAC truly is from where the program means it
at the end; ``--end-after S`` ends the stream (exit 0) S seconds after the program
ended, as a controller whose program is done, so that a script waits for the twin
instead of sleeping.  A tracker's look at that world (a query) gets the pose at
that instant.  ``--lockstep S`` waits up to S seconds for each answer: the
arm then moves as with a real-time PC on a machine that is not one (``plugcell demo
--link rsi``).  ``--reflector NAME`` publishes the arm's true T-MAC pose to
the cell's simulated world as it moves, for a simulated tracker
(:class:`~plugcell.sim.controller.reflector.ReflectorFeed`).  ``--stats FILE`` writes, at
the end, the robot side's counts and every packet's round trip (its send to the first
answer, ns; −1: unanswered) as JSON, for ``benchmarks/stream_in_service.py``.
``--rt-priority N``, ``--cpu CPUS``, ``--mlock`` schedule the controller's cycle thread
as the link's options do (:func:`~plugcell.apps.commands.streaming.realtime_of`,
:class:`~plugcell.devices.robot.stream.realtime.LoopScheduling`; the process's other
threads one priority below and on those CPUs); what the kernel granted or refused is a
line on stderr, and a refusal (not root, no ``CAP_SYS_NICE``) leaves the twin running at
normal priority.

``twin egm`` is the same twin behind an ABB controller's EGM loop in joint mode
(:class:`~plugcell.sim.controller.egm_twin.TwinEgmRobot`: the feedback pose the nominal
model's forward kinematics of the joints); ``--timeout`` is its ``\\CommTimeout`` (s).
``--mode pathcorr --lin …`` (or ``--program FILE``) is a controller running its
own program with ``EGMMoveL``
(mode (b)) and the PC's path corrections applied in its path coordinate system (y
and z), on the dynamic twin (:class:`~plugcell.sim.controller.egm_twin.TwinEgmPathRobot`).
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time

import numpy as np

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.cellargs import add_cell_args
from plugcell.apps.commands.streaming import add_realtime_options, realtime_of

#: Python's thread switch interval in the twin's process (s): the reflector feed computes
#: for milliseconds, and the cycle thread must get the interpreter back within a fraction
#: of a 4 ms cycle (the default is 5 ms).
SWITCH_INTERVAL_S = 0.0005


def _side_options(r: argparse.ArgumentParser, common, what: str, default_port: int | None,
                  start: str) -> None:
    """The options every robot side has: the PC's address, the twin, the world, how long."""
    common(r)
    r.add_argument("--port", type=int, required=default_port is None, default=default_port,
                   help=f"the PC's UDP port, where plugcell listens ({what})")
    r.add_argument("--ip", default="127.0.0.1", help="the PC's address (default 127.0.0.1)")
    r.add_argument("--bind", default="127.0.0.1:0", metavar="HOST[:PORT]",
                   help="the controller's own address (default 127.0.0.1, any port)")
    r.add_argument("--payload-kg", type=float, default=0.0, metavar="KG",
                   help="payload on the flange (default 0)")
    r.add_argument("--joints", metavar="Q1,…,Q6",
                   help=f"where the arm stands at {start}, degrees (default: the robot's home)")
    r.add_argument("--reflector", metavar="NAME",
                   help="publish the T-MAC's true pose as it moves to the simulated world of "
                   "--cell under NAME, for a simulated tracker")
    r.add_argument("--reflector-rate", type=float, default=25.0, metavar="HZ",
                   help="largest rate of those publications while the arm moves (default 25)")
    r.add_argument("--lin", action="append", default=[], metavar="DX,DY,DZ",
                   help="the controller's own program (mode (b), the robot drives): a LIN "
                   "moving the TCP by DX,DY,DZ mm in the base frame; repeat for more moves "
                   "(default: it holds still and follows the PC)")
    r.add_argument("--program", metavar="FILE",
                   help="the controller's own program (mode (b)) from a file: a path file "
                   "(plugcell path run --path's CSV) or a robot program's straight moves "
                   "(.pdl); the arm starts at its first point")
    r.add_argument("--library", action="append", default=[], metavar="DIR",
                   help="folders of the libraries a .pdl --program imports")
    r.add_argument("--calibration", metavar="PARAMS.json",
                   help="with a program of its own: report how far the T-MAC truly is from "
                   "where the program means it, in this calibration's frames (BASE, PROBE: "
                   "what a tracker in the calibrated cell sees)")
    r.add_argument("--speed", type=float, default=100.0, metavar="MM_S",
                   help="the program's TCP speed, mm/s, where it gives none (default 100)")
    r.add_argument("--path-delay", type=float, default=1.0, metavar="S",
                   help=f"seconds the program waits at {start} before its LINs (default 1)")
    add_cell_args(r)
    r.add_argument("--duration", type=float, default=0.0,
                   help="seconds to stream, then stop (default: until interrupted)")
    r.add_argument("--end-after", type=float, default=None, metavar="S",
                   help="with a program of its own: stop streaming S seconds after the "
                   "program ended, as a controller whose program is done (default: stream "
                   "until --duration or interrupted); a script can then wait for the twin")
    r.add_argument("--stats", metavar="FILE",
                   help="at the end, write the robot side's counts and every answer's round "
                   "trip (ns) to FILE as JSON (benchmarks)")
    add_realtime_options(r, "the controller's cycle thread")


def add_robot_sides(tw: argparse._SubParsersAction, common, rsi, egm) -> None:
    """Add ``twin rsi`` and ``twin egm`` to the ``twin`` subcommands (``common`` adds
    robot and seed; ``rsi(args)``/``egm(args)`` run them: :func:`run_rsi`/:func:`run_egm`
    with the scenario the options name)."""
    r = tw.add_parser(
        "rsi", help="run the twin as a KUKA controller streaming RSI (no controller needed)",
        description="The dynamic twin behind a simulated KUKA controller's RSI: sends <Rob> "
        "every cycle to the PC's --ip:--port and applies the <Sen> answers, as the "
        "controller running plugcell's KRL program does (docs/kuka-rsi.md).")
    _side_options(r, common, "the ethernet file's IP_NUMBER and PORT", None, "RSI_ON")
    r.add_argument("--correction", choices=("joint", "cartesian"), default="joint",
                   help="AKorr A1..A6 or RKorr X Y Z A B C (default joint)")
    r.add_argument("--frame", choices=("base", "tool"), default="base",
                   help="the Cartesian corrections' frame, POSCORR's RefCorrSys (default "
                   "base)")
    r.add_argument("--mode", choices=("absolute", "relative"), default="absolute",
                   help="RSI_ON(#ABSOLUTE) or #RELATIVE (default absolute, what "
                   "plugcell serve robot --rsi streams)")
    r.add_argument("--cycle", choices=("IPO_FAST", "IPO"), default="IPO_FAST",
                   help="4 ms or 12 ms (default IPO_FAST)")
    r.add_argument("--timeout", type=int, default=100,
                   help="the ETHERNET object's Timeout: late answers before RSI stops "
                   "(default 100)")
    r.add_argument("--lockstep", type=float, default=0.0, metavar="S",
                   help="simulate a sensor that always answers in time on a machine that "
                   "cannot: wait up to S seconds for each answer before counting it late "
                   "(default 0: the controller's deadline, the end of the cycle)")
    r.set_defaults(func=rsi)
    e = tw.add_parser(
        "egm", help="run the twin as an ABB controller's EGM loop (joint mode)",
        description="The dynamic twin behind a simulated ABB controller's EGM loop "
        "(EGMRunJoint): sends EgmRobot every 4 ms to the PC's --ip:--port and follows the "
        "joint targets of the EgmSensor answers (docs/abb-egm.md).")
    _side_options(e, common, "the UDP unit device's remote port; default 6510", 6510,
                  "EGMRunJoint")
    e.add_argument("--timeout", type=float, default=1.0, metavar="S",
                   help="\\CommTimeout: seconds without a sensor message before EGM stops "
                   "(default 1)")
    e.add_argument("--mode", choices=("joint", "pathcorr"), default="joint",
                   help="joint: EGMRunJoint (the PC drives); pathcorr: the controller runs "
                   "its own program (--lin) with EGMMoveL and adds the PC's path "
                   "corrections (the robot drives) (default joint)")
    e.set_defaults(func=egm)


def _parse_side(args: argparse.Namespace):
    """(sensor address, bind address, start joints or None) of the options."""
    from plugcell.devices.robot.bridge import parse_address

    sensor = parse_address(f"{args.ip}:{args.port}")
    bhost, sep, bport = args.bind.rpartition(":")
    bind = (bhost, int(bport)) if sep and bport.isdigit() else (args.bind, 0)
    q0 = np.radians([float(v) for v in args.joints.split(",")]) if args.joints else None
    return sensor, bind, q0


def _within_limits(arm):
    """The arm, if it stands within its joint limits (ValueError naming them otherwise)."""
    problems = arm.twin.description.limit_violations(arm.measured, tol=1e-6)
    if problems:
        raise ValueError("--joints outside the joint limits: " + "; ".join(problems))
    return arm


def _arm_and_program(args: argparse.Namespace, scenario, q0, params=None):
    """The arm and the controller's own program (``None``: none) of ``--lin`` or
    ``--program`` (ValueError naming a bad option or the file's line)."""
    from plugcell.sim.controller.own_program import linear_program, parse_lins, program_path
    from plugcell.sim.twin.dynamics import DynamicTwin

    if args.program and args.lin:
        raise ValueError("--program or --lin: the controller runs one program")
    if args.program and args.joints:
        raise ValueError("--joints with --program: the program starts at its first point")
    if args.library and not args.program:
        raise ValueError("--library goes with a .pdl --program")
    if getattr(args, "calibration", None) and not (args.program or args.lin):
        raise ValueError("--calibration reports the error of a program of its own: give "
                         "--lin or --program")
    if not (np.isfinite(args.speed) and args.speed > 0):
        raise ValueError(f"the TCP speed must be positive: --speed {args.speed} mm/s")
    arm = _within_limits(DynamicTwin(scenario, params, q0=q0))
    if args.program:
        start, path = program_path(arm.twin.description, args.program, args.speed,
                                   args.library)
        return _within_limits(DynamicTwin(scenario, params, q0=start)), path
    if args.lin:
        return arm, linear_program(arm.twin.description, arm.measured, parse_lins(args.lin),
                                   args.speed * 1e-3)
    return arm, None


def _schedule(args: argparse.Namespace, what: str):
    """The cycle thread's scheduling ``--rt-priority``/``--cpu``/``--mlock`` ask for
    (CommandError on a value that can never work)."""
    try:
        return realtime_of(args)
    except CommandError as exc:
        raise CommandError(f"twin {what}: {exc}") from None


def _start(world, robot, what: str) -> str:
    """Start the world's feed and the robot side: the process's threads scheduled first
    (:meth:`RealTime.prepare_process`: on the CPUs asked, one priority below the cycle
    thread), then the cycle thread (its own); what the kernel granted or refused, asked
    for, is a line on stderr, returned."""
    realtime = robot.scheduling.realtime
    prepared = realtime.prepare_process()
    world.start()
    robot.start()
    if not realtime.asked:
        return ""
    note = robot.scheduling.note + (f"; {prepared}" if prepared else "")
    print(f"twin {what}: cycle thread: {note}", file=sys.stderr, flush=True)
    return note


def _rsi_side(args: argparse.Namespace, scenario, realtime=None):
    """The arm and its RSI side the options describe (CommandError on bad ones)."""
    from plugcell.devices.robot.rsi.config import CorrectionLimits, RsiConfig, RsiConfigError
    from plugcell.sim.controller.rsi_robot import RsiRobot
    from plugcell.sim.twin.dynamics import DynamicParameters

    try:
        (host, port), bind, q0 = _parse_side(args)
        big = (1e3,) * 6  # the controller's AXISCORR/POSCORR limits are the sensor's here
        config = RsiConfig(robot_host=bind[0], listen_host=host, listen_port=port,
                           correction=args.correction, mode=args.mode, cycle=args.cycle,
                           frame=args.frame,
                           timeout_packets=args.timeout, limits=CorrectionLimits(big, big, big))
        arm, path = _arm_and_program(args, scenario, q0, DynamicParameters(cycle=config.cycle_s))
        return arm, RsiRobot(arm, config, bind=bind, lockstep_s=args.lockstep, path=path,
                             path_delay_s=args.path_delay if path else 0.0,
                             realtime=realtime), config
    except (ValueError, RsiConfigError, OSError) as exc:
        raise CommandError(f"twin rsi: {exc}") from None


def _largest(peak, correction: str) -> str:
    """``largest correction A1 2.00°`` (or ``Z 5.00 mm``) of the per-axis peaks (SI)."""
    from plugcell.devices.robot.rsi.codec import CARTESIAN_AXES, JOINT_AXES
    from plugcell.io.units import DEG, M_PER_MM

    i = int(np.argmax(peak / np.array([M_PER_MM] * 3 + [DEG] * 3)
                      if correction == "cartesian" else peak))
    if correction == "cartesian" and i < 3:
        return f"largest correction {CARTESIAN_AXES[i]} {peak[i] / M_PER_MM:.2f} mm"
    axes = JOINT_AXES if correction == "joint" else CARTESIAN_AXES
    return f"largest correction {axes[i]} {peak[i] / DEG:.2f}°"


class _World:
    """The twin's T-MAC in the cell's simulated world (``--reflector``), or nothing."""

    def __init__(self, args: argparse.Namespace, arm, what: str) -> None:
        from plugcell.apps.commands.cellargs import cell_of, transport_of

        self.truth = self.feed = None
        if args.reflector:
            from plugcell.sim.controller.reflector import ReflectorFeed, ReflectorTruth

            try:
                self.truth = ReflectorTruth(args.reflector, cell_of(args), 1.0,
                                            transport_of(args),
                                            current=arm.twin.true_reflector_in_tracker)
                self.feed = ReflectorFeed(self.truth, arm, rate_hz=args.reflector_rate)
            except ValueError as exc:
                raise CommandError(f"twin {what}: {exc}") from None

    def start(self) -> None:
        if self.feed is not None:
            self.feed.start()

    def close(self) -> None:
        if self.feed is not None:
            self.feed.stop()
        if self.truth is not None:
            self.truth.close()


def _until_stopped(args: argparse.Namespace, running, offset,
                   path_done=lambda: False) -> np.ndarray:
    """Run until ``--duration``, SIGTERM/SIGINT, ``running()`` turns false or — with
    ``--end-after S`` — S seconds after ``path_done()`` first turned true; the largest
    ``|offset()|`` of each axis, looked at every 50 ms."""
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    done = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: done.set())
    end = time.monotonic() + args.duration if args.duration else float("inf")
    end_after = getattr(args, "end_after", None)
    lingering = False
    peak = np.zeros(6)
    while not done.wait(0.05) and running() and time.monotonic() < end:
        peak = np.maximum(peak, np.abs(offset()))
        if end_after is not None and not lingering and path_done():
            lingering = True  # the program ended: linger, then stop
            end = min(end, time.monotonic() + end_after)
    return peak


def _write_stats(path: str | None, cycles: int, answered: int, late: int,
                 rtts: list, stopped: str | None, **more: object) -> None:
    """``--stats FILE``: the counts, every packet's ``(sent, round trip)`` (ns; −1: no
    answer), why the robot side stopped (``null``: it did not) and ``more`` (``twin rsi
    --lin``/``--program``: ``shift_mm``, the corrections' shift of the program's TCP, and
    ``path_done``, whether the program had ended, and with ``--calibration``
    ``error_mm``, the T-MAC's true error from where the program means it, every 50 ms), as
    JSON."""
    if path:
        import json
        from pathlib import Path

        Path(path).write_text(json.dumps({"cycles": cycles, "answered": answered,
                                          "late": late, "rtt_ns": list(rtts),
                                          "stopped": stopped, **more}))


def _scenario_of(args: argparse.Namespace, scenario, what: str):
    if not (args.duration >= 0):
        raise CommandError(f"--duration must be 0 or positive, not {args.duration}")
    end_after = getattr(args, "end_after", None)
    if end_after is not None:
        if not (end_after >= 0):
            raise CommandError(f"--end-after must be 0 or positive seconds, not {end_after}")
        if not (args.lin or args.program):
            raise CommandError(f"twin {what}: --end-after ends the stream after the "
                               "controller's own program: give it with --lin or --program")
    try:
        return scenario.with_payload(args.payload_kg)
    except ValueError as exc:
        raise CommandError(f"twin {what}: {exc}") from None


class _PathWatch:
    """What the controller's own program looks like from outside, every 50 ms: the
    corrections' shift of its commanded TCP (mm) and, with ``--calibration``, the
    T-MAC's true error from where the program means it in the calibration's frames (mm,
    :func:`~plugcell.sim.controller.own_program.probe_error`)."""

    def __init__(self, args: argparse.Namespace, arm, what: str) -> None:
        from plugcell.apps.cli import CommandError

        self.arm = arm
        self.frames = None
        if getattr(args, "calibration", None):
            from plugcell.compensation import IdentifiedModel
            from plugcell.devices.robot.calibration_file import read_calibration

            try:
                model = IdentifiedModel(read_calibration(args.calibration).model)
            except ValueError as exc:
                raise CommandError(f"twin {what}: {exc}") from None
            self.frames = (model.base, model.tool)
        self.shifts: list[list[float]] = []
        self.errors: list[list[float]] = []
        self.done: list[bool] = []

    def look(self, shift, path_pose, tool, done: bool) -> None:
        from plugcell.sim.controller.own_program import probe_error

        self.done.append(bool(done))
        self.shifts.append([float(v) for v in np.asarray(shift) * 1e3])
        if self.frames is not None:
            e = probe_error(self.arm, path_pose, tool, self.frames)
            self.errors.append([float(v) for v in e * 1e3])

    def stats(self) -> dict:
        return {"shift_mm": self.shifts, "path_done": self.done,
                **({"error_mm": self.errors} if self.frames is not None else {})}

    def summary(self, done: bool) -> str:
        """``, path done, largest shift S mm[, T-MAC error 0.5 s after the path ended E1 mm,
        at the end E2 mm]``."""
        error = ""
        if self.errors:
            ended = [i for i, d in enumerate(self.done) if d]  # looked at every 50 ms
            after = ""
            if ended:
                e = self.errors[min(ended[0] + 10, len(self.errors) - 1)]
                after = f" 0.5 s after the path ended {np.linalg.norm(e):.3f} mm,"
            error = f", T-MAC error{after} at the end {np.linalg.norm(self.errors[-1]):.3f} mm"
        return (f", path {'done' if done else 'not done'}, largest shift "
                f"{max((np.linalg.norm(s) for s in self.shifts), default=0.0):.3f} mm"
                + error)


def run_rsi(args: argparse.Namespace, scenario) -> int:
    """Run ``twin rsi`` (module docstring) for the twin ``scenario`` (a TwinScenario)."""
    from plugcell.sim.controller.own_program import path_shift

    realtime = _schedule(args, "rsi")
    arm, robot, config = _rsi_side(args, _scenario_of(args, scenario, "rsi"), realtime)
    watch = _PathWatch(args, arm, "rsi")
    world = _World(args, arm, "rsi")
    _start(world, robot, "rsi")
    h, pt = robot.address
    print(f"twin rsi: {arm.twin.description.name} streaming RSI ({config.correction}, "
          f"{config.mode}, {config.cycle}) from {h}:{pt} to {config.listen_host}:"
          f"{config.listen_port}", flush=True)
    own = bool(args.lin or args.program)  # the controller runs a program of its own

    def offset() -> np.ndarray:
        if own:
            k, q = robot.setpoint
            T_p = robot.path_poses[k]
            watch.look(path_shift(arm.twin.description, q, T_p), T_p, robot.tool,
                       k >= len(robot.path_poses) - 1)
        return robot.offset

    peak = _until_stopped(args, lambda: robot.running, offset, lambda: robot.path_done)
    robot.stop()
    world.close()
    st = robot.stats()
    _write_stats(args.stats, st.cycles, st.answered, st.delay, robot.rtts, robot.stopped,
                 **watch.stats())
    path = watch.summary(robot.path_done) if own else ""
    print(f"twin rsi: {st.cycles} cycles, {st.answered} answered, Delay {st.delay}, "
          f"{_largest(peak, config.correction)}{path}", flush=True)
    if robot.stopped:
        print(f"twin rsi: {robot.stopped}", file=sys.stderr, flush=True)
        return 3
    return 0


def run_egm(args: argparse.Namespace, scenario) -> int:
    """Run ``twin egm`` (module docstring) for the twin ``scenario`` (a TwinScenario)."""
    from plugcell.sim.controller.egm_twin import TwinEgmPathRobot, TwinEgmRobot

    scenario = _scenario_of(args, scenario, "egm")
    realtime = _schedule(args, "egm")
    try:
        sensor, bind, q0 = _parse_side(args)
        if not (args.timeout > 0):
            raise ValueError(f"--timeout must be positive seconds, not {args.timeout}")
        arm, path = _arm_and_program(args, scenario, q0)
        start = arm.measured.copy()
        if args.mode == "pathcorr":
            if path is None:
                raise ValueError("--mode pathcorr runs the controller's own program: give "
                                 "it with --lin DX,DY,DZ or --program FILE")
            robot = TwinEgmPathRobot(arm, sensor, path, path_delay_s=args.path_delay,
                                     comm_timeout_s=args.timeout, bind=bind, realtime=realtime)
        elif path is not None:
            given = "--program" if args.program else "--lin"
            raise ValueError(f"{given} is the controller's own program of --mode pathcorr "
                             f"(EGMRunJoint follows the PC)")
        else:
            robot = TwinEgmRobot(arm, sensor, comm_timeout_s=args.timeout, bind=bind,
                                 realtime=realtime)
    except (ValueError, OSError) as exc:
        raise CommandError(f"twin egm: {exc}") from None
    watch = _PathWatch(args, arm, "egm")
    world = _World(args, arm, "egm")
    _start(world, robot, "egm")
    h, pt = robot.address
    print(f"twin egm: {arm.twin.description.name} streaming EGM ({args.mode}) from {h}:{pt} "
          f"to {sensor[0]}:{sensor[1]}", flush=True)
    def moved() -> np.ndarray:
        if args.mode != "pathcorr":
            return robot.state()["joints"] - start
        watch.look(robot.shift(),  # the program's pose only for the error (an FK)
                   robot.path_pose() if watch.frames is not None else None,
                   arm.twin.description.tool, robot.path_done)
        return np.concatenate([robot.state()["correction"], np.zeros(3)])

    peak = _until_stopped(args, lambda: robot.stopped is None, moved,
                          lambda: args.mode == "pathcorr" and robot.path_done)
    robot.stop()
    world.close()
    _write_stats(args.stats, robot.sent, robot.answers, robot.unanswered, robot.rtts,
                 robot.stopped, **(watch.stats() if args.mode == "pathcorr" else {}))
    largest = (_largest(peak, "cartesian").replace("correction", "path correction")
               + watch.summary(robot.path_done)
               if args.mode == "pathcorr" else
               _largest(peak, "joint").replace("correction", "move"))
    print(f"twin egm: {robot.sent} samples, {robot.answers} answers, {robot.unanswered} "
          f"unanswered, {largest}", flush=True)
    if robot.stopped:
        print(f"twin egm: {robot.stopped}", file=sys.stderr, flush=True)
        return 3
    return 0
