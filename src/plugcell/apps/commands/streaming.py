"""What ``plugcell rsi`` and ``plugcell egm`` share: the correction limits their options
give, the controller's files written and listed, the first-contact correction source
(``--sine AXIS:AMPLITUDE:PERIOD``, else hold) and the run itself (start the link, print its
counters every second, end on ``--duration`` or a failure)."""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from plugcell.apps.cli import CommandError


def add_limit_options(p: argparse.ArgumentParser, what: str, units: str) -> None:
    """``--max-step``, ``--max-offset``, ``--max-speed`` (one number or six, in ``units``)
    and ``--refuse``: the limits every correction of a stream is held to."""
    for name, when in (("step", "per cycle"), ("offset", "in total"), ("speed", "per second")):
        p.add_argument(f"--max-{name}", metavar="V[,V…]",
                       help=f"largest {what} {when}: {units}")
    p.add_argument("--refuse", action="store_true",
                   help=f"refuse (hold and fail) any {what} beyond the limits instead of "
                   "clamping it")


def _six(text: str | None, what: str, kind: str) -> tuple[float, ...] | None:
    """``--max-<what>``'s value: one number for all six axes, or six, each finite and > 0
    (robot units: degrees, or mm for the first three Cartesian axes); ``None`` if not
    given.  A bad value is a CommandError naming it as typed, with its unit."""
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise CommandError(f"--max-{what} {text!r}: expected numbers separated by commas") \
            from None
    if len(vals) == 1:
        vals *= 6
    if len(vals) != 6:
        raise CommandError(f"--max-{what} {text!r}: expected 1 or 6 numbers, got {len(vals)}")
    typed = text.split(",") * (6 if "," not in text else 1)
    for i, v in enumerate(vals):
        if not (math.isfinite(v) and v > 0):
            unit = "mm" if kind == "cartesian" and i < 3 else "deg"
            where = "" if "," not in text else f" (axis {i + 1})"
            raise CommandError(f"--max-{what} {text!r}: {typed[i].strip()} {unit}{where} is "
                               "not a finite number > 0")
    return vals


def named_as_options(exc: Exception, options: Mapping[str, tuple[str, Any]]) -> str:
    """``exc``'s message (``"field value: why"``, as the stream's configuration and the
    controller's files word it) with the field named as the option that gave it and the
    value as the option took it (``"timeout_packets 0: …"`` → ``"--timeout 0: …"``).

    Parameters
    ----------
    exc : Exception
        A StreamConfigError or ValueError of the configuration.
    options : mapping of str to (str, object)
        Field name → (option, its parsed value): the values of these options are the
        fields' own (same unit), so only the names change.

    Returns
    -------
    str
        The message for the user (``str(exc)`` if it names no field of ``options``).
    """
    msg = str(exc)
    name, _, rest = msg.partition(" ")
    if name not in options or ": " not in rest:
        return msg
    option, value = options[name]
    shown = f"{value:g}" if isinstance(value, float) else (
        repr(value) if isinstance(value, str) else str(value))
    return f"{option} {shown}: {rest.split(': ', 1)[1]}"


def limits_of(args: argparse.Namespace, kind: str) -> Any:
    """The limits the options of :func:`add_limit_options` give, in SI.

    Parameters
    ----------
    args : argparse.Namespace
        ``max_step``, ``max_offset``, ``max_speed`` (robot units: degrees per joint, or
        mm, mm, mm, °, °, °) and ``refuse``.
    kind : {"joint", "cartesian"}
        What the stream corrects.

    Returns
    -------
    CorrectionLimits
        Each limit given converted (° → rad, mm → m), the others :func:`default_limits`'s
        for ``kind``; policy ``"refuse"`` with ``--refuse``, else ``"clamp"``.
    """
    from plugcell.devices.robot.stream.limits import CorrectionLimits, default_limits
    from plugcell.io.units import DEG, M_PER_MM

    scale = (DEG,) * 6 if kind == "joint" else (M_PER_MM,) * 3 + (DEG,) * 3
    base = default_limits(kind)  # type: ignore[arg-type]
    given = {}
    for name in ("step", "offset", "speed"):
        vals = _six(getattr(args, f"max_{name}"), name, kind)
        given[name] = (tuple(v * s for v, s in zip(vals, scale, strict=True)) if vals
                       else getattr(base, f"max_{name}"))
    return CorrectionLimits(given["step"], given["offset"], given["speed"],
                            "refuse" if args.refuse else "clamp")


def write_and_list(write: Callable[[], Iterable[Path]], out: Path,
                   options: Mapping[str, tuple[str, Any]] | None = None) -> None:
    """Write the controller's files (``write()``, into the folder ``out``) and print each
    path; a refused configuration or a folder that cannot be written is a CommandError
    (naming the option of a refused value: ``options``, :func:`named_as_options`)."""
    try:
        paths = write()
    except ValueError as exc:
        raise CommandError(named_as_options(exc, options or {})) from None
    except OSError as exc:
        raise CommandError(f"{out}: cannot write: {exc.strerror or exc}") from None
    for path in paths:
        print(path)


def add_run_options(p: argparse.ArgumentParser, robot: str) -> None:
    """The options of ``run`` before the stream's own: the robot's address
    (``robot``: what to call it) and where to listen."""
    p.add_argument("--robot-ip", required=True, help=robot)
    p.add_argument("--listen", default="0.0.0.0", help="address to listen on")


def add_run_controls(p: argparse.ArgumentParser) -> None:
    """The options of ``run`` after the stream's own: what to send (``--sine``), for how
    long, at which priority, and how to print the counters."""
    p.add_argument("--sine", metavar="AXIS:AMPLITUDE:PERIOD",
                   help="swing one axis once: e.g. A6:2:4 (2° over 4 s) or Z:5:4 (5 mm)")
    p.add_argument("--duration", type=float, default=0.0,
                   help="seconds to run (default: until interrupted)")
    add_realtime_options(p, "the link's thread")
    p.add_argument("--json", action="store_true", help="print the counters as JSON lines")


def add_realtime_options(p: argparse.ArgumentParser, loop: str) -> None:
    """``--rt-priority``, ``--cpu``, ``--mlock``: the scheduling of ``loop`` (e.g. "the
    link's thread"), read by :func:`realtime_of` (:mod:`~plugcell.devices.robot.stream.
    realtime`)."""
    p.add_argument("--rt-priority", type=int, metavar="N",
                   help=f"run {loop} under SCHED_FIFO priority N (1-99; Linux, root or "
                   "CAP_SYS_NICE; refused: it runs at normal priority and says why)")
    p.add_argument("--cpu", metavar="CPUS",
                   help=f"run {loop} on these CPUs only (taskset -c syntax: 1, 2-3); keep "
                   "the cell's other services off them")
    p.add_argument("--mlock", action="store_true",
                   help="lock the process's memory (mlockall): no page fault from disk in "
                   "a cycle")


def realtime_of(args: argparse.Namespace) -> Any:
    """The link's scheduling ``--rt-priority``, ``--cpu`` and ``--mlock`` ask for.

    Returns
    -------
    RealTime
        For the link's ``realtime``.

    Raises
    ------
    CommandError
        A priority outside 1..99, a malformed CPU list, a CPU this machine does not have:
        the option and the reason.
    """
    from plugcell.apps.cli import CommandError
    from plugcell.devices.robot.stream.realtime import stream_realtime

    try:
        return stream_realtime(args.rt_priority, args.cpu or "", args.mlock)
    except ValueError as exc:  # named by the service's option: name the command's
        why = str(exc)
        for name, option in (("stream_cpu", "--cpu"), ("stream_rt_priority", "--rt-priority")):
            if why.startswith(name):
                why = option + why[len(name):]
        raise CommandError(why) from None


def sine_or_hold(sine: str | None, axes: Sequence[str], unit: Callable[[int], float],
                 allowed: Callable[[int], str] = lambda i: "") -> Any:
    """``Hold()``, or a ``SineOffset`` for ``--sine AXIS:AMPLITUDE:PERIOD``.

    Parameters
    ----------
    sine : str or None
        The option's text (None or empty: hold).
    axes : sequence of str
        The axis names of the stream's mode (``A1``…``A6`` or ``X``…``C``).
    unit : callable
        SI per unit of the amplitude of axis ``i`` (m per mm, rad per degree).
    allowed : callable
        Why axis ``i`` cannot swing in this mode ("" if it can).

    Returns
    -------
    CorrectionSource
        The source the link asks each cycle.

    Raises
    ------
    CommandError
        A malformed option, an unknown axis, a period ≤ 0 (one line naming it).
    """
    from plugcell.devices.robot.stream.source import Hold, SineOffset

    if not sine:
        return Hold()
    try:
        axis, amplitude, period = sine.split(":")
        amplitude_v, period_v = float(amplitude), float(period)
    except ValueError:
        raise CommandError(f"--sine {sine!r}: expected AXIS:AMPLITUDE:PERIOD") from None
    if axis not in axes:
        raise CommandError(f"--sine: axis {axis!r} is not one of {', '.join(axes)}")
    i = list(axes).index(axis)
    if why := allowed(i):
        raise CommandError(f"--sine: {why}")
    if period_v <= 0:
        raise CommandError(f"--sine: the period must be > 0, got {period_v}")
    return SineOffset(i, amplitude_v * unit(i), period_v)


def run_link(link: Any, args: argparse.Namespace, what: str, *,
             controller_delay: bool = False) -> int:
    """Start ``link``, print its counters each second until ``--duration`` (0: until
    Ctrl-C), then close it.

    Parameters
    ----------
    link : StreamLink
        An RSI or EGM link, not started.
    args : argparse.Namespace
        ``robot_ip``, ``duration`` (s) and ``json``.
    what : str
        The stream's settings for the first line (mode, cycle …).
    controller_delay : bool
        Print the controller's own count of late answers (RSI's ``<Delay>``).

    Returns
    -------
    int
        0, or 1 if the stream failed other than by the controller going silent (its
        program stopped: how a run ends).
    """
    from plugcell.devices.robot.stream.errors import StreamStoppedError

    host, port = link.start()
    time.sleep(0.01)  # the thread has set its scheduling
    print(f"listening on {host}:{port} for the robot at {args.robot_ip} ({what}; "
          f"{link.rt_note})", flush=True)
    end = time.monotonic() + args.duration if args.duration > 0 else None
    failed = None
    try:
        while end is None or time.monotonic() < end:
            time.sleep(1.0)
            st = link.stats()
            if args.json:
                print(json.dumps({**st.__dict__, "failure": str(link.failure or "")}),
                      flush=True)
            else:
                delay = f" controller Delay {st.controller_late}" if controller_delay else ""
                print(f"received {st.received} answered {st.answered} late {st.late} "
                      f"missed {st.missed} dropped {sum(st.dropped.values())} clamped "
                      f"{st.clamped}{delay} max latency {st.max_latency_ns / 1e6:.3f} ms",
                      flush=True)
            if link.failure is not None and link.failure is not failed:
                failed = link.failure
                print(f"stream failed: {failed}", flush=True)
    finally:
        link.close()
    # the controller ending the stream (program stopped: silence) is how a run ends; a
    # late PC, a refused correction or the controller's Timeout is a failure
    silent = isinstance(failed, StreamStoppedError) and "no packet" in str(failed)
    return 1 if failed is not None and not silent else 0
