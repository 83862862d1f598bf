"""``plugcell compensate``: happy path and bad input named by file, line and column."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from plugcell.apps.cli import main
from plugcell.compensation import IdentifiedModel, compensate, target_poses
from plugcell.io.params import params_json
from plugcell.kinematics.rotations import matrix_to_angles, zyz_to_matrix


@pytest.fixture(scope="module")
def params_file(calibrated, tmp_path_factory):
    p = tmp_path_factory.mktemp("params") / "params.json"
    p.write_text(params_json(calibrated.result))
    return p


def _rows(calibrated, n=5):
    model = IdentifiedModel(calibrated.result.model)
    R = zyz_to_matrix(0.0, math.pi / 2, 0.0) @ model.probe[:3, :3]
    A = np.degrees(matrix_to_angles(R, "zyz"))
    ys = np.linspace(-600, 600, n)
    return [[f"P{k + 1}", 1500.0, y, 1000.0, *A] for k, y in enumerate(ys)]


def _write(path, header, rows):
    with path.open("w", newline="") as fh:
        fh.write("# a program\n")
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


def test_happy_path(calibrated, params_file, tmp_path, capsys):
    rows = _rows(calibrated)
    targets = _write(tmp_path / "t.csv", ["name", "x", "y", "z", "rx", "ry", "rz"], rows)
    out = tmp_path / "joints.csv"
    rc = main(["compensate", "--params", str(params_file), "--targets", str(targets),
               "--out", str(out), "--payload-kg", "36"])
    assert rc == 0
    assert "compensated 5 targets" in capsys.readouterr().out
    lines = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")]
    got = list(csv.DictReader(lines))
    assert [r["name"] for r in got] == [r[0] for r in rows]
    q = np.radians([[float(r[f"j{k}"]) for k in range(1, 7)] for r in got])
    # the same numbers as the library, and the model predicts the targets there
    model = IdentifiedModel(calibrated.result.model)
    arr = np.array([r[1:] for r in rows], float)
    T = target_poses(arr[:, :3] / 1e3, np.radians(arr[:, 3:]), "zyz")
    ref = compensate(model, T, 36.0)
    np.testing.assert_allclose(q, ref.q, atol=1e-7)  # 6 decimals of a degree
    p = model.pose(q, 36.0)[:, :3, 3]
    np.testing.assert_allclose(p, T[:, :3, 3], atol=1e-6)


def test_without_out_the_joints_go_to_stdout(calibrated, params_file, tmp_path, capsys):
    targets = _write(tmp_path / "t.csv", ["name", "x", "y", "z", "rx", "ry", "rz"],
                     _rows(calibrated))
    out = tmp_path / "joints.csv"
    argv = ["compensate", "--params", str(params_file), "--targets", str(targets),
            "--payload-kg", "36"]
    assert main([*argv, "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert captured.out == out.read_text()  # the same CSV, on stdout
    assert "compensated 5 targets" in captured.err and "wrote" not in captured.err


def test_payload_column_and_user_frame(calibrated, params_file, tmp_path):
    rows = [[*r[1:], 18.0] for r in _rows(calibrated, 3)]
    shifted = [[x - 100.0, y, z - 50.0, a, b, c, m] for x, y, z, a, b, c, m in rows]
    t = _write(tmp_path / "u.csv", ["x", "y", "z", "rx", "ry", "rz", "payload_kg"], shifted)
    out = tmp_path / "j.csv"
    rc = main(["compensate", "--params", str(params_file), "--targets", str(t), "--out",
               str(out), "--user-frame", "100,0,50,0,0,0"])
    assert rc == 0
    direct = _write(tmp_path / "d.csv", ["x", "y", "z", "rx", "ry", "rz", "payload_kg"], rows)
    out2 = tmp_path / "j2.csv"
    assert main(["compensate", "--params", str(params_file), "--targets", str(direct), "--out",
                 str(out2)]) == 0
    assert out.read_text().split("\n", 2)[2] == out2.read_text().split("\n", 2)[2]
    assert ",18," in out.read_text()


@pytest.mark.parametrize(
    ("header", "row", "message"),
    [
        (["x", "y", "z", "rx", "ry", "rz"], ["1500", "12", "5", "1000", "0", "90", "0"],
         "line 3: expected 6 values, got 7"),
        (["x", "y", "z", "rx", "ry", "rz"], ["1500", "12,5", "1000", "0", "90", "0"],
         "line 3, column 'y': not a number: '12,5'"),
        (["x", "y", "z", "rx", "ry", "rz"], ["1500", "abc", "1000", "0", "90", "0"],
         "line 3, column 'y': not a number: 'abc'"),
        (["x", "y", "z", "rx", "ry", "rz"], ["1500", "0", "nan", "0", "90", "0"],
         "line 3, column 'z': not finite"),
        (["x", "y", "z", "rx", "ry"], ["1500", "0", "1000", "0", "90"], "lacks ['rz']"),
        (["x", "y", "z", "rx", "ry", "rz", "speed"], ["1", "2", "3", "4", "5", "6", "7"],
         "unknown columns ['speed']"),
        (["x", "y", "z", "rx", "ry", "rz", "payload_kg"], ["1500", "0", "1000", "0", "90", "0",
                                                           "-3"], "negative mass"),
    ],
)
def test_bad_rows_are_named(params_file, tmp_path, capsys, header, row, message):
    t = _write(tmp_path / "bad.csv", header, [row])
    rc = main(["compensate", "--params", str(params_file), "--targets", str(t), "--out",
               str(tmp_path / "o.csv")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and message in err
    assert not (tmp_path / "o.csv").exists()


def test_unreachable_target_names_its_line(calibrated, params_file, tmp_path, capsys):
    rows = _rows(calibrated, 3)
    rows[1][1] = 6000.0  # 6 m away
    t = _write(tmp_path / "far.csv", ["name", "x", "y", "z", "rx", "ry", "rz"], rows)
    rc = main(["compensate", "--params", str(params_file), "--targets", str(t), "--out",
               str(tmp_path / "o.csv")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "1 of 3 targets" in err and "far.csv: line 4 (P2)" in err and "out of reach" in err


def test_bad_params_file(tmp_path, capsys):
    t = _write(tmp_path / "t.csv", ["x", "y", "z", "rx", "ry", "rz"], [[1, 2, 3, 4, 5, 6]])
    bad = tmp_path / "p.json"
    bad.write_text("{not json")
    assert main(["compensate", "--params", str(bad), "--targets", str(t), "--out",
                 str(tmp_path / "o.csv")]) == 2
    assert "not valid JSON" in capsys.readouterr().err
    bad.write_text('{"robot": "smart_h4"}')
    assert main(["compensate", "--params", str(bad), "--targets", str(t), "--out",
                 str(tmp_path / "o.csv")]) == 2
    assert "not a plugcell calibration" in capsys.readouterr().err
    missing = tmp_path / "none.json"
    assert main(["compensate", "--params", str(missing), "--targets", str(t), "--out",
                 str(tmp_path / "o.csv")]) == 2
    assert "cannot read" in capsys.readouterr().err


def test_bad_options(params_file, tmp_path, capsys):
    t = _write(tmp_path / "t.csv", ["x", "y", "z", "rx", "ry", "rz"], [[1, 2, 3, 4, 5, 6]])
    assert main(["compensate", "--params", str(params_file), "--targets", str(t), "--out",
                 str(tmp_path / "o.csv"), "--user-frame", "1,2,3"]) == 2
    assert "--user-frame" in capsys.readouterr().err
    assert main(["compensate", "--params", str(params_file), "--targets", str(t), "--out",
                 str(tmp_path / "o.csv"), "--payload-kg", "-1"]) == 2


def test_a_temperature_without_a_thermal_term_is_refused(params_file, tmp_path, capsys):
    """Issue 39 §8: --temperature-c could change nothing for these parameters (no κT, no
    temperature-aware residual layer): refused with the reason, nothing written."""
    t = _write(tmp_path / "t.csv", ["x", "y", "z", "rx", "ry", "rz"],
               [[1500, 0, 1000, 0, 90, 0]])
    out = tmp_path / "o.csv"
    assert main(["compensate", "--params", str(params_file), "--targets", str(t), "--out",
                 str(out), "--temperature-c", "25"]) == 2
    err = capsys.readouterr().err
    assert f"--temperature-c 25: {params_file} has no thermal term" in err, err
    assert "leave it out" in err and not out.exists()
    assert main(["compensate", "--params", str(params_file), "--targets", str(t), "--out",
                 str(out), "--temperature-c", "nan"]) == 2
    assert "must be a temperature" in capsys.readouterr().err
