"""Names renamed to end a clash of meanings (issue #33; the list: docs/framework.md,
"Renamed in issue #33") still work under their old names, each with one warning line that
names the new one, and parse to exactly what the new name gives."""

from __future__ import annotations

import argparse

import pytest

from plugcell.apps.cli import CommandError, build_parser, main

IK = ["--robot", "smart_h4", "--pose", "1500,0,1300,0,90,0"]
PLAN = ["--robot", "smart_h4", "--poses", "5", "--out", "plan.csv"]


def _parse(argv: list[str]) -> argparse.Namespace:
    return build_parser(argv[0]).parse_args(argv)


def _same(a: argparse.Namespace, b: argparse.Namespace) -> bool:
    return vars(a) == vars(b)


@pytest.mark.parametrize(("new", "old", "warning"), [
    (["serve", "robot", "--line", "10.0.0.5:7000"],
     ["serve", "robot", "--controller", "10.0.0.5:7000"], "--controller is deprecated: use --line"),
    (["plan", *PLAN, "--payloads-kg", "0,36"], ["plan", *PLAN, "--payloads", "0,36"],
     "--payloads is deprecated: use --payloads-kg"),
    (["bench", "transport", "--payload-bytes", "4,32"],
     ["bench", "transport", "--payloads", "4,32"],
     "--payloads is deprecated: use --payload-bytes"),
    (["kin", "ik", *IK, "--start", "0,0,0,0,0,0"], ["kin", "ik", *IK, "--seed", "0,0,0,0,0,0"],
     "--seed is deprecated: use --start"),
])
def test_an_old_option_parses_as_the_new_one_with_a_warning(new, old, warning, capsys):
    assert _same(_parse(old), _parse(new))
    assert f"plugcell: warning: {warning}\n" == capsys.readouterr().err
    _parse(new)
    assert capsys.readouterr().err == ""


def test_plugcell_controller_is_cell_serve_with_a_warning(capsys):
    old = _parse(["controller", "--port", "0", "--wiring", "cell.json"])
    new = build_parser("cell").parse_args(["cell", "serve", "--port", "0", "--wiring",
                                           "cell.json"])
    keep = ("command", "cell_command", "func")
    assert {k: v for k, v in vars(old).items() if k not in keep} == {
        k: v for k, v in vars(new).items() if k not in keep}
    # the old command warns when it runs, then runs `cell serve` (here: refuses the port)
    assert main(["controller", "--port", "70000"]) == 2
    err = capsys.readouterr().err
    assert "plugcell: warning: plugcell controller is deprecated: use plugcell cell serve" in err
    assert "plugcell: error: --port 70000: not a TCP port" in err


def test_the_old_kind_controller_is_the_cell_controller(capsys):
    from plugcell.apps.kinds import KINDS, current_kind, load_kind

    assert current_kind("camera") == "camera" and capsys.readouterr().err == ""
    assert current_kind("controller") == "cell-controller"
    assert ("plugcell: warning: service kind 'controller' is deprecated: use 'cell-controller'"
            in capsys.readouterr().err)
    assert "controller" not in KINDS
    assert load_kind("cell-controller").declaration.kind == "cell-controller"


def test_the_robots_old_parameter_controller_is_line(capsys):
    from plugcell.apps.commands.serve import _params

    assert _params("robot", ["controller=10.0.0.5:7000"]) == {"line": "10.0.0.5:7000"}
    assert ("plugcell: warning: parameter 'controller' of robot is deprecated: use 'line'"
            in capsys.readouterr().err)
    assert _params("robot", ["line=10.0.0.5:7000"]) == {"line": "10.0.0.5:7000"}
    assert capsys.readouterr().err == ""
    with pytest.raises(CommandError, match="bad --param 'controller=x' for TrackerService"):
        _params("tracker", ["controller=x"])
