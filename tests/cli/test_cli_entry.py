"""The ``plugcell`` entry point: lazy sub-commands and how it ends."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest
from loaded_modules import modules_loaded_by
from source_trees import parsed

import plugcell.apps.commands
from plugcell.apps.cli import COMMANDS, EXIT_BROKEN_PIPE, build_parser, chosen_command, main
from plugcell.sim.ports import free_port

#: Modules a parser must not need: the service stack, the web server, scipy.
HEAVY = ("zenoh", "fastapi", "uvicorn", "starlette", "scipy", "plugcell.framework",
         "cryptography", "matplotlib")


def _imported_after_parser(command: str | None, heavy: tuple[str, ...] = HEAVY) -> list[str]:
    """Modules (of ``heavy``) loaded by ``import plugcell.apps.cli`` + ``build_parser(command)``,
    in a fresh interpreter."""
    return modules_loaded_by(
        f"import plugcell.apps.cli as cli\ncli.build_parser({command!r})", heavy)


@pytest.mark.parametrize("command", [None, "kin", "calibrate", "compensate", "reproduce"])
def test_parser_does_not_import_the_service_stack(command):
    assert _imported_after_parser(command) == []


@pytest.mark.parametrize("command", [None, "calibrate"])
def test_help_needs_no_numpy(command):
    assert _imported_after_parser(command, ("numpy",)) == []


def test_top_level_parser_imports_no_command_module():
    loaded = modules_loaded_by("import plugcell.apps.cli as cli; cli.build_parser()",
                               ["plugcell.apps.commands"])
    assert [m for m in loaded if m != "plugcell.apps.commands"] == []


def test_chosen_command_is_the_first_word():
    assert chosen_command(["kin", "fk", "--robot", "x"]) == "kin"
    assert chosen_command(["--version"]) is None
    assert chosen_command(["-h", "calibrate"]) == "calibrate"
    assert chosen_command([]) is None


@pytest.mark.parametrize("cmd", COMMANDS, ids=[c.name for c in COMMANDS])
def test_every_declared_command_configures_its_parser(cmd, capsys):
    with pytest.raises(SystemExit) as exc:
        main([cmd.name, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: plugcell {cmd.name}")


def test_every_command_module_is_declared_once():
    """A command module defines ``configure*`` functions, each declared in COMMANDS, and
    no old-style ``register`` (which the lazy parser would never call)."""
    declared = {c.configure for c in COMMANDS}
    assert len(declared) == len(COMMANDS)
    assert len({c.name for c in COMMANDS}) == len(COMMANDS)
    found = set()
    for path in Path(plugcell.apps.commands.__file__).parent.glob("*.py"):
        tree = parsed(path.read_text(encoding="utf-8"))
        names = [n.name for n in tree.body if isinstance(n, ast.FunctionDef)]
        assert "register" not in names, f"{path.name}: register() is never called; " \
            "declare the command in plugcell.apps.cli.COMMANDS with a configure function"
        found |= {f"plugcell.apps.commands.{path.stem}:{n}" for n in names
                  if n.startswith("configure")}
    assert found == declared


def test_full_parser_builds():
    parser = build_parser("*")
    args = parser.parse_args(["kin", "fk", "--robot", "smart_h4", "--joints", "0,0,0,0,0,0"])
    assert args.func.__name__ == "_cmd_fk"


def test_unknown_command_lists_the_commands(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["bogus"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'bogus'" in err and "'calibrate'" in err


@pytest.mark.parametrize(("args", "code"), [
    (["kin", "describe", "--robot", "smart_h4"], EXIT_BROKEN_PIPE),  # more than 8 KiB
    (["kin", "robots"], EXIT_BROKEN_PIPE),                          # a few lines
    (["--help"], 0),  # argparse ignores a failed write of its help and exits 0
])
def test_a_closed_pipe_ends_quietly(args, code):
    """``plugcell … | head``: the reader is gone before plugcell writes (the read end is
    closed before the process starts, so every write fails with EPIPE)."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        proc = subprocess.run([sys.executable, "-m", "plugcell", *args], stdout=write_end,
                              stderr=subprocess.PIPE, text=True, timeout=60)
    finally:
        os.close(write_end)
    assert proc.stderr == ""
    assert proc.returncode == code


def test_a_broken_pipe_elsewhere_is_not_hidden():
    """A BrokenPipeError while stdout is fine (a socket, a child's pipe) is a real error."""
    code = ("import sys, plugcell.apps.cli as cli\n"
            "def broken(argv):\n"
            "    raise BrokenPipeError(32, 'Broken pipe: a socket')\n"
            "cli._run = broken\n"
            "sys.exit(cli.main(['kin']))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 1
    assert "BrokenPipeError: [Errno 32] Broken pipe: a socket" in proc.stderr


def test_a_client_with_no_router_ends_with_where_it_looked(monkeypatch, capsys):
    """A connection error plugcell raises with its reason is one error line (exit 2)."""
    port = free_port()  # nobody listens on it
    monkeypatch.setenv("PLUGCELL_MODE", "client")
    monkeypatch.setenv("PLUGCELL_CONNECT", f"tcp/127.0.0.1:{port}")
    monkeypatch.setenv("PLUGCELL_MULTICAST", "0")
    monkeypatch.delenv("PLUGCELL_LISTEN", raising=False)
    assert main(["services", "--cell", "nowhere"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"plugcell: error: no router reached (tcp/127.0.0.1:{port}): a client "
                          "(PLUGCELL_MODE=client) joins the cell through a running "
                          "`plugcell router`; Zenoh: ")


@pytest.mark.parametrize("error", [ConnectionRefusedError(111, "Connection refused"),
                                   ConnectionResetError(104, "Connection reset by peer")])
def test_the_operating_systems_connection_errors_keep_their_traceback(monkeypatch, error):
    import plugcell.apps.commands.cell as cell

    def fail(args):
        raise error

    monkeypatch.setattr(cell, "run_ls", fail)
    with pytest.raises(type(error)):
        main(["services"])


@pytest.mark.parametrize(("alias", "action"), [("wire", "wire"), ("unwire", "unwire")])
def test_wire_and_unwire_are_the_cell_actions_under_a_short_name(alias: str, action: str):
    """``plugcell wire`` is ``plugcell cell wire``: one function, the same options and
    defaults, so one JSON shape and one exit-code rule."""
    from plugcell.apps.cli import build_parser

    short = build_parser(alias).parse_args([alias, "A", "B", "--json", "--via", "CTRL"])
    long = build_parser("cell").parse_args(["cell", action, "A", "B", "--json", "--via", "CTRL"])
    assert short.func is long.func
    mine = {k: v for k, v in vars(short).items() if k not in ("command", "cell_command")}
    theirs = {k: v for k, v in vars(long).items() if k not in ("command", "cell_command")}
    assert mine == theirs


def test_services_is_cell_ls_under_a_short_name():
    """``plugcell services`` is ``plugcell cell ls``: one function, the same options and
    defaults, so one JSON shape and one exit-code rule."""
    from plugcell.apps.cli import build_parser

    short = build_parser("services").parse_args(["services", "--json", "--commands"])
    long = build_parser("cell").parse_args(["cell", "ls", "--json", "--commands"])
    assert short.func is long.func
    mine = {k: v for k, v in vars(short).items() if k not in ("command", "cell_command")}
    theirs = {k: v for k, v in vars(long).items() if k not in ("command", "cell_command")}
    assert mine == theirs


@pytest.mark.parametrize(("given", "threads"), [
    ({}, 1),                               # one thread by default
    ({"OPENBLAS_NUM_THREADS": "2"}, 2),    # a count the environment names is kept
    ({"OMP_NUM_THREADS": "2"}, 2),
])
def test_openblas_runs_one_thread_unless_the_environment_names_a_count(given, threads):
    """``main`` sets ``OPENBLAS_NUM_THREADS=1`` before NumPy is imported (its BLAS then
    runs the count ``threadpoolctl`` reports) and for the processes it starts."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")}
    code = ("import os, subprocess, sys\n"
            "from plugcell.apps.cli import main\n"
            "try:\n    main(['--version'])\nexcept SystemExit:\n    pass\n"
            "import numpy, threadpoolctl\n"
            "blas = threadpoolctl.threadpool_info()\n"
            "print([p['num_threads'] for p in blas if p['user_api'] == 'blas'])\n"
            "print(subprocess.run([sys.executable, '-c', 'import os; "
            "print(os.environ.get(\"OPENBLAS_NUM_THREADS\"))'], capture_output=True, "
            "text=True).stdout.strip())\n")
    done = subprocess.run([sys.executable, "-c", code], env={**env, **given},
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    counts, child = done.stdout.splitlines()[-2:]
    assert counts == f"[{threads}]", done.stdout
    assert child == given.get("OPENBLAS_NUM_THREADS", "1" if not given else "None")
