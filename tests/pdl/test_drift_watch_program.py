"""drift_watch.pdl (issue 19): the program of the library that re-measures the reference
nests, has the compute service estimate the drift of BASE and re-registers it — run by
the language's interpreter against the real compute functions and a simulated tracker."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from language_fakes import execution

from plugcell.calibration import CalibrationData, Calibrator, ErrorModel
from plugcell.calibration.identifiability import random_configurations
from plugcell.devices.compute.expr import evaluate
from plugcell.devices.compute.functions import FUNCTIONS, FunctionContext
from plugcell.devices.compute.workspace import Workspace
from plugcell.io.params import params_json
from plugcell.io.robots import load_robot
from plugcell.kinematics.transforms import so3_exp
from plugcell.pdl import Program

PROGRAMS = Path(__file__).resolve().parents[2] / "src" / "plugcell" / "pdl" / "programs"
NESTS_MM = np.array([[1000.0, -1300.0, 0.0], [2400.0, 200.0, 50.0], [1200.0, 1500.0, 0.0],
                     [300.0, -200.0, 400.0]])


@pytest.fixture(scope="module")
def saved_params(tmp_path_factory):
    desc = load_robot("smart_h4")
    truth = ErrorModel.create(desc, "loop")
    q = random_configurations(truth, 60, seed=1)
    res = Calibrator(desc, "loop").fit(CalibrationData.from_poses(q, truth.predict(q)))
    d = tmp_path_factory.mktemp("params")
    return d, res


class Cell:
    """The compute service (real functions, one workspace) and a tracker that measures
    the nests after BASE drifted by ``D`` (tracker frame)."""

    def __init__(self, params_dir: Path, base: np.ndarray, D: np.ndarray) -> None:
        self.ws = Workspace("H4")
        self.ctx = FunctionContext(self.ws, robot="smart_h4", params_dir=params_dir)
        self.base, self.D = base, D
        self.aim: np.ndarray | None = None
        self.set_base: list[str] = []

    def _append(self, name: str, row: np.ndarray) -> None:
        try:
            old = self.ws.get(name)
        except Exception:
            old = np.zeros((0, row.size))
        self.ws.set(name, np.vstack([old, row[None, :]]))

    def respond(self, line: str):
        _, service_cmd = line.split(" ", 1)
        service, command, option, data = ([*service_cmd.split("#"), ""])[:4]
        service = service.strip()
        if service == "COMPUTE":
            if command == "Evaluate":
                evaluate(data, self.ws, FUNCTIONS, context=self.ctx)
                return True, None, ""
            if command == "Get Matrix":
                return True, self.ws.get(option), ""
            if command == "Set Matrix":
                self._append(option.split(":")[0], np.array([float(v) for v in data.split(",")]))
                return True, None, ""
        if service == "TRACKER":
            if command == "Set Base":
                self.set_base.append(data)
            elif command == "Move":
                self.aim = np.array([float(v) for v in data.split(",")[:3]]) / 1e3
            elif command == "Single Measurement":
                assert self.aim is not None and "to=COMPUTE:Set Matrix:mD:append" in option
                B = self.base
                true = self.D @ B @ np.r_[self.aim, 1.0]          # where the nest is now
                seen = np.linalg.inv(B) @ true                    # through the tracker's BASE
                self._append("mD", np.r_[seen[:3] * 1e3, 0.0, 0.0, 0.0])
            return True, None, ""
        return False, None, f"unexpected {line!r}"


def _run(saved_params, tmp_path, D, update=True):
    _d, res = saved_params
    (tmp_path / "h4.json").write_text(params_json(res))
    cell = Cell(tmp_path, res.model.base(), D)
    program = Program.from_source((PROGRAMS / "drift_watch.pdl").read_text(),
                                  "drift_watch.pdl", base_dir=PROGRAMS)
    nests = np.zeros((20, 6))  # ARRAY[20] OF POSITION, the first n_nests used
    nests[:4, :3] = NESTS_MM
    values = {"nests": nests, "n_nests": 4,
              "params_name": "h4", "threshold_mm": 0.05, "duration_ms": 1000,
              "update": update}
    ex, _, _ = execution(program, cell.respond, values=values)
    result = ex.run()
    assert result.ok, (result.error, ex.console)
    return cell, ex, res


def test_drift_above_the_threshold_alarms_and_re_registers_base(saved_params, tmp_path):
    D = np.eye(4)
    D[:3, :3] = so3_exp([0.0, 0.0, 3e-5])
    D[:3, 3] = [60e-6, -20e-6, 10e-6]
    cell, ex, res = _run(saved_params, tmp_path, D)
    assert ex.console[-1] == "drift_watch: ALARM, BASE re-registered", ex.console
    row = cell.ws.get("d")[0]
    assert row[1] == 1.0 and row[2] == 1.0
    np.testing.assert_allclose(row[3:6], [0.06, -0.02, 0.01], atol=1e-6)
    doc = json.loads((tmp_path / "h4.json").read_text())
    np.testing.assert_allclose(np.array(doc["base"]["matrix"]), D @ res.model.base(), atol=1e-9)
    assert len(doc["drift_history"]) == 1
    assert len(cell.set_base) == 2  # INITIALIZE, then the re-registered BASE


def test_small_drift_is_ok_and_nothing_changes(saved_params, tmp_path):
    D = np.eye(4)
    D[:3, 3] = [5e-6, 0.0, 0.0]
    cell, ex, _res = _run(saved_params, tmp_path, D)
    assert ex.console[-1] == "drift_watch: ok", ex.console
    doc = json.loads((tmp_path / "h4.json").read_text())
    assert "drift_history" not in doc and len(cell.set_base) == 1
