"""``plugcell compensate --program``: report, plan, output paths, option errors."""

from __future__ import annotations

import csv
import shutil

import numpy as np
from programlib import FIXTURES, model_for

from plugcell.apps.cli import main
from plugcell.io.plans import read_plan
from plugcell.io.programs import read_program
from plugcell.io.programs.filter import filter_targets

MOD = FIXTURES / "Module1.mod"


def test_measure_order_is_a_plan_of_the_visited_joints(calibrated_result, params_file,
                                                       tmp_path):
    plan = tmp_path / "plan.csv"
    assert main(["compensate", "--params", str(params_file), "--program", str(MOD),
                 "--measure-order", str(plan), "--payload-kg", "36"]) == 0
    p = read_plan(plan, n_joints=6)
    prog, _ = read_program(MOD)
    fr = filter_targets(prog, model_for(calibrated_result), payload_kg=36.0)
    # program order of the motions: jHome (kept, MoveAbsJ), Target_10, Target_20, Path{2}
    # (MoveC: Path{1} first), …
    by = {r.target.name: r for r in fr.reports}
    order = sorted((min(r.target.uses), r.target.name) for r in fr.reports if r.target.used)
    names = [n for _, n in order]
    assert names[:3] == ["jHome", "Target_10", "Target_20"]
    assert len(p) == len(names)
    np.testing.assert_allclose(p.joints[1], by["Target_10"].q, atol=1e-9)
    np.testing.assert_allclose(np.degrees(p.joints[0]), by["jHome"].target.values, atol=1e-9)
    np.testing.assert_allclose(p.payload_kg, 36.0)


def test_report_has_a_row_a_target(params_file, tmp_path):
    rep = tmp_path / "r.csv"
    assert main(["compensate", "--params", str(params_file), "--program", str(MOD),
                 "--report", str(rep)]) == 0
    rows = list(csv.DictReader(ln for ln in rep.read_text().splitlines()
                               if not ln.startswith("#")))
    assert [r["name"] for r in rows][:2] == ["Target_10", "Target_20"]
    st = {r["name"]: r for r in rows}
    assert st["Target_10"]["status"] == "compensated" and float(st["Target_10"]["dp_mm"]) > 1
    assert st["Unused"]["status"] == "kept" and "not used" in st["Unused"]["reason"]
    assert st["Target_10"]["where"].endswith("Module1.mod:11:32")
    assert st["Target_10"]["outside_region"] in ("0", "1")
    assert st["Target_10"]["ik_seed_deg"] == "home"
    assert len(st["MoveL line 28"]["ik_seed_deg"].split()) == 6  # the flipped wrist


def test_output_paths_and_option_errors(params_file, tmp_path, capsys):
    src = tmp_path / "Module1.mod"
    shutil.copy(MOD, src)
    assert main(["compensate", "--params", str(params_file), "--program", str(src),
                 "--out", str(src)]) == 2
    assert "would overwrite the program read" in capsys.readouterr().err
    assert main(["compensate", "--params", str(params_file), "--program", str(src)]) == 2
    assert "give --out" in capsys.readouterr().err
    odd = tmp_path / "prog.txt"
    odd.write_text("MODULE M\nENDMODULE\n")
    assert main(["compensate", "--params", str(params_file), "--program", str(odd),
                 "--out", str(tmp_path / "o.txt")]) == 2
    assert "cannot tell the dialect from the suffix '.txt'" in capsys.readouterr().err
    assert main(["compensate", "--params", str(params_file), "--program", str(odd),
                 "--dialect", "rapid", "--out", str(tmp_path / "o.txt")]) == 0
    t = tmp_path / "t.csv"
    t.write_text("x,y,z,rx,ry,rz\n1500,0,1000,0,90,0\n")
    assert main(["compensate", "--params", str(params_file), "--targets", str(t),
                 "--base", "a=1,2,3,4,5,6"]) == 2
    assert "go with --program" in capsys.readouterr().err
    assert main(["compensate", "--params", str(params_file), "--program", str(src),
                 "--out", str(tmp_path / "x"), "--tool", "tX=1,2,3"]) == 2
    assert "tX: expected 7 numbers (abb notation), got 3" in capsys.readouterr().err
    # a folder keeps the names
    out = tmp_path / "outdir"
    assert main(["compensate", "--params", str(params_file), "--program", str(src),
                 "--out", str(out)]) == 0
    assert (out / "Module1.mod").exists()


def test_each_configuration_agrees_exactly_when_it_has_no_mismatch():
    """``agrees`` (vectorised, used to search) and ``mismatch`` (the message) say the same,
    for KRL S/T, RAPID confdata and Fanuc turns, on random joints."""
    from plugcell.io.programs.core import Num
    from plugcell.io.programs.fanuc import FanucConfig
    from plugcell.io.programs.krl import KrlConfig
    from plugcell.io.programs.rapid import RapidConfig

    rng = np.random.default_rng(5)
    Q = rng.uniform(-4.5, 4.5, (4000, 6))
    Q[::7, 4] = 0.0
    cfgs = [KrlConfig(0, Num(0, 1, "6", 6.0), Num(2, 4, "35", 35.0)),
            KrlConfig(0, None, Num(2, 4, "'B000110'", 6.0)),
            RapidConfig(0, [Num(0, 1, "0", 0.0), Num(2, 4, "-1", -1.0), Num(5, 6, "1", 1.0),
                            Num(7, 8, "0", 0.0)]),
            FanucConfig(0, [Num(0, 1, "0", 0.0), Num(2, 4, "-1", -1.0), Num(5, 6, "1", 1.0)])]
    for cfg in cfgs:
        want = np.array([cfg.mismatch(q) == "" for q in Q])
        np.testing.assert_array_equal(cfg.agrees(Q), want)
        assert 0 < want.sum() < len(want)   # both cases met
