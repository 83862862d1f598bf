"""The ``plugcell`` command.

Each sub-command is declared here by a light :class:`Command` (its name, its one-line
help and where its options are defined) and lives in its own module under
:mod:`plugcell.apps.commands`.  The module's ``configure(parser)`` adds the options and sets
``func`` (``func(args) -> int`` exit code).  Only the module of the sub-command being
run is imported, so ``plugcell calibrate --help`` does not load Zenoh, FastAPI or the
service framework (``benchmarks/cli_startup.py`` measures the start-up).

A new sub-command is a module with ``configure(parser)`` (heavy imports inside the
functions that run it, not at the top) and one :class:`Command` line in
:data:`COMMANDS`; ``tests/cli/test_cli_entry.py`` checks that every such module is
declared.
"""

from __future__ import annotations

import argparse
import importlib
import os
import select
import sys
from collections.abc import Sequence
from dataclasses import dataclass

from plugcell import __version__

#: Environment variables that set OpenBLAS's thread count (:func:`main`).
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")

#: Exit status after the reader of stdout went away (``plugcell … | head``): 128 + SIGPIPE,
#: what a shell reports for a program that SIGPIPE ended.
EXIT_BROKEN_PIPE = 141


@dataclass(frozen=True)
class Command:
    """A sub-command of ``plugcell``, declared without importing its module.

    Attributes
    ----------
    name : str
        The word on the command line (``plugcell NAME …``).
    help : str
        One line for ``plugcell --help``.
    configure : str
        ``"module:function"``; ``function(parser)`` adds the options and ``func``.
    """

    name: str
    help: str
    configure: str

    def load(self, parser: argparse.ArgumentParser) -> None:
        """Import the module and let it configure ``parser``."""
        module, _, function = self.configure.partition(":")
        getattr(importlib.import_module(module), function)(parser)


#: The sub-commands, in the order ``plugcell --help`` lists them.
COMMANDS: tuple[Command, ...] = (
    Command("kin", "robot kinematics: forward/inverse kinematics, robot descriptions",
            "plugcell.apps.commands.kin:configure"),
    Command("motion", "trajectories: plan PTP/LIN/CIRC moves with limits and blends, checked "
            "before motion, sampled every cycle", "plugcell.apps.commands.motion:configure"),
    Command("path", "run a path file with the laser tracker correcting it while the robot "
            "moves", "plugcell.apps.commands.path:configure"),
    Command("twin", "the digital twin: error budget, simulated campaigns",
            "plugcell.apps.commands.twin:configure"),
    Command("demo", "run the thesis demonstration on simulated devices over services",
            "plugcell.apps.commands.demo:configure"),
    Command("serve", "run a device service (camera, drill, …) in this process",
            "plugcell.apps.commands.serve:configure"),
    Command("services", "list the services of the cell (= plugcell cell ls)",
            "plugcell.apps.commands.services:configure"),
    Command("call", "create a process at a service and print its updates as JSON lines",
            "plugcell.apps.commands.call:configure"),
    Command("wire", "make service A subscribe to partner B (= plugcell cell wire)",
            "plugcell.apps.commands.wire:configure_wire"),
    Command("unwire", "make service A drop partner B (= plugcell cell unwire)",
            "plugcell.apps.commands.wire:configure_unwire"),
    Command("router", "run a Zenoh router so a cell can span machines",
            "plugcell.apps.commands.router:configure"),
    Command("journal", "show the journal of the cell's processes",
            "plugcell.apps.commands.journal:configure"),
    Command("bench", "benchmarks: transport (5.3), calibration (8.2), compensation (6.5.1)",
            "plugcell.apps.commands.bench:configure"),
    Command("compensate",
            "model-based compensation of Cartesian targets -> joint targets (thesis 6.5.1)",
            "plugcell.apps.commands.compensate:configure"),
    Command("calibrate", "identify a robot's error model from tracker measurements",
            "plugcell.apps.commands.calibrate:configure"),
    Command("export", "write a calibrated robot as URDF, UR kinematics YAML or plugcell TOML",
            "plugcell.apps.commands.export:configure"),
    Command("drift", "drift watch: re-measure reference nests, estimate and correct the drift "
            "of BASE", "plugcell.apps.commands.drift:configure"),
    Command("plan", "choose the poses of a calibration campaign (optimal, reachable, visible)",
            "plugcell.apps.commands.plan:configure"),
    Command("reproduce", "recompute the thesis's calibration tables",
            "plugcell.apps.commands.reproduce:configure"),
    Command("cell", "the cell controller: discover, wire, save/load, run programs, monitor; "
            "serve it with its web UI", "plugcell.apps.commands.cell:configure"),
    Command("controller", "deprecated: plugcell cell serve",
            "plugcell.apps.commands.controller:configure_deprecated"),
    Command("certs", "create a cell's CA and per-service TLS certificates",
            "plugcell.apps.commands.certs:configure"),
    Command("opcua", "the cell as an OPC UA server (for MES, SCADA, HMI)",
            "plugcell.apps.commands.opcua:configure"),
    Command("rsi", "KUKA RSI with plugcell as the sensor: controller files, streaming",
            "plugcell.apps.commands.rsi:configure"),
    Command("egm", "ABB EGM with plugcell as the sensor: controller files, streaming",
            "plugcell.apps.commands.egm:configure"),
)


class CommandError(Exception):
    """A user-facing error: printed as ``plugcell: error: <message>``, exit code 2."""


def chosen_command(argv: Sequence[str]) -> str | None:
    """The sub-command named in ``argv``: its first word that is not an option.

    ``plugcell`` itself has only flag options (``--help``, ``--version``), so the first
    non-option word is the sub-command (or a typo argparse will report).
    """
    return next((a for a in argv if not a.startswith("-")), None)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``plugcell`` parser; only ``command``'s options are loaded (all: ``"*"``).

    Every sub-command is listed with its help; the others parse nothing, which is all
    ``plugcell --help`` and an unknown name need.
    """
    parser = argparse.ArgumentParser(
        prog="plugcell",
        description="Plug-and-produce robot work-cells made accurate.",
    )
    parser.add_argument("--version", action="version", version=f"plugcell {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for cmd in COMMANDS:
        p = sub.add_parser(cmd.name, help=cmd.help)
        if command in (cmd.name, "*"):
            cmd.load(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``plugcell`` with ``argv`` (default ``sys.argv[1:]``); returns the exit code.

    A reader of stdout that went away (``plugcell … | head``) ends the command quietly
    with :data:`EXIT_BROKEN_PIPE` instead of a ``BrokenPipeError`` traceback.

    OpenBLAS runs one thread (``OPENBLAS_NUM_THREADS=1``, for this process — set before
    NumPy is first imported — and the services it starts) unless the environment names
    a count (``OPENBLAS_NUM_THREADS``, ``GOTO_NUM_THREADS`` or ``OMP_NUM_THREADS``):
    plugcell's matrices are small (a calibration's 900 × 72 Jacobian, the learning's
    plant identification), and on busy cores OpenBLAS's threads spin waiting for each
    other — 32× and 40× slower than one thread with one other process busy on the
    2-core VM (``benchmarks/blas_threads.py``).
    """
    if not any(os.environ.get(v) for v in BLAS_THREAD_VARIABLES):
        os.environ["OPENBLAS_NUM_THREADS"] = "1"
    argv = sys.argv[1:] if argv is None else argv
    try:
        try:
            return _run(argv)
        finally:  # also after argparse's SystemExit (--help): a failed flush at exit warns
            sys.stdout.flush()
    except BrokenPipeError:
        if not _stdout_reader_gone():
            raise  # another pipe or socket broke: a real error, not `| head`
        # The Python recipe (library docs, signal, "Note on SIGPIPE"): stdout onto
        # devnull, so the interpreter's last flush has nowhere to fail, and exit quietly.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE


def _stdout_reader_gone() -> bool:
    """Whether stdout is a pipe whose reading end is closed (``poll`` reports POLLERR);
    ``True`` when that cannot be told (no ``poll``, stdout without a descriptor)."""
    try:
        fd = sys.stdout.fileno()
        poller = select.poll()
    except (AttributeError, OSError, ValueError):
        return True
    poller.register(fd, select.POLLOUT)
    return any(events & (select.POLLERR | select.POLLHUP) for _, events in poller.poll(0))


def _run(argv: list[str]) -> int:
    parser = build_parser(chosen_command(argv))
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 2
    try:
        return int(func(args) or 0)
    except CommandError as exc:
        print(f"plugcell: error: {exc}", file=sys.stderr)
        return 2
    except ConnectionError as exc:
        if exc.errno is not None:  # the OS's own (refused, reset …): keep the traceback
            raise
        print(f"plugcell: error: {exc}", file=sys.stderr)  # one plugcell raised with why
        return 2
    except KeyboardInterrupt:
        print("plugcell: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
