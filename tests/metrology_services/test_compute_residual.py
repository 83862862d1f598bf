"""The compute service with a learned residual layer (issue 19): load_params reads the
side file, compensate uses the hybrid model, save_params writes the side file too."""

from __future__ import annotations

import json

import numpy as np
import pytest

from plugcell.calibration import CalibrationData, Calibrator, ErrorModel
from plugcell.calibration.identifiability import random_configurations
from plugcell.calibration.residual_model import ResidualLearner
from plugcell.compensation import IdentifiedModel, NominalModel, compensate_joints
from plugcell.devices.compute.expr import EvaluationError, evaluate
from plugcell.devices.compute.functions import FUNCTIONS, FunctionContext
from plugcell.devices.compute.workspace import Workspace
from plugcell.io.params import params_json
from plugcell.io.residual_models import residual_path, save_residual
from plugcell.io.robots import load_robot


@pytest.fixture(scope="module")
def hybrid(tmp_path_factory):
    """A Smart H4 loop model with a learned layer, written as plugcell calibrate does."""
    desc = load_robot("smart_h4")
    truth = ErrorModel.create(desc, "loop")
    q = random_configurations(truth, 400, seed=3)
    dq = np.zeros_like(q)
    dq[:, 1] = 5e-4 * np.sin(2 * q[:, 1])     # a transmission error on joint 2
    data = CalibrationData.from_poses(q, truth.predict(q + dq))
    res = Calibrator(desc, "loop").fit(data)
    layer = ResidualLearner(grid=({"max_leaf_nodes": 15, "min_samples_leaf": 20},),
                            trees=40).fit(res.model, data, robot=desc.name)
    d = tmp_path_factory.mktemp("params")
    path = d / "h4_hybrid.json"
    entry = save_residual(layer, residual_path(path))
    path.write_text(params_json(res.with_residual_model(layer), residual_file=entry))
    return d, res, q


def _ws(params_dir) -> Workspace:
    w = Workspace("ROBOT")
    w.ctx = FunctionContext(w, robot="smart_h4", params_dir=params_dir)
    return w


def test_load_params_uses_the_layer_and_compensates_with_the_hybrid_model(hybrid, tmp_path):
    params_dir, res, q = hybrid
    ws = _ws(params_dir)
    evaluate("p = load_params('h4_hybrid')", ws, FUNCTIONS, context=ws.ctx)
    p = ws.get("p")
    assert p.result.residual_model is not None
    ws.set("nominal", np.rad2deg(q[:6]))
    evaluate("j = compensate_joints(p, nominal)", ws, FUNCTIONS, context=ws.ctx)
    qh = np.deg2rad(ws.get("j"))
    desc = p.description
    T = NominalModel(desc, tool=res.model.probe()).pose(q[:6])
    hyb = IdentifiedModel(res.model, residual=p.result.residual_model)
    qp = compensate_joints(IdentifiedModel(res.model), T, q[:6]).q
    # the hybrid joints put the hybrid model's tool on the target; the physical ones differ
    np.testing.assert_allclose(hyb.pose(qh)[:, :3, 3], T[:, :3, 3], atol=2e-6)
    assert 1e-6 < np.abs(qh - qp).max() < 5e-3
    # saved again under another name: the side file goes with it
    ws.ctx = FunctionContext(ws, robot="smart_h4", params_dir=tmp_path)
    evaluate("save_params(p, 'copy'); c = load_params('copy')", ws, FUNCTIONS, context=ws.ctx)
    doc = json.loads((tmp_path / "copy.json").read_text())
    assert doc["residual_model"]["file"] == "copy.residual.skops"
    assert (tmp_path / "copy.residual.skops").is_file()
    assert ws.get("c").result.residual_model is not None


def test_a_side_file_that_does_not_belong_is_refused(hybrid, tmp_path):
    params_dir, _, _ = hybrid
    doc = json.loads((params_dir / "h4_hybrid.json").read_text())
    doc["residual_model"]["sha256"] = "0" * 64
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    (tmp_path / doc["residual_model"]["file"]).write_bytes(
        (params_dir / doc["residual_model"]["file"]).read_bytes())
    ws = _ws(tmp_path)
    with pytest.raises(EvaluationError, match="SHA-256 differs"):
        evaluate("p = load_params('bad')", ws, FUNCTIONS, context=ws.ctx)
