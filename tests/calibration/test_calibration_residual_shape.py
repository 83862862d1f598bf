"""The transferable arm-shape stage of the learned residual layer (issue 19 (b)):
the joint-1 frame, its rotation covariance, the two stages' domains and the side file."""

from __future__ import annotations

import hashlib
from dataclasses import replace

import numpy as np
import pytest

from plugcell.calibration.residual_model import (
    ShapeStage,
    from_joint1_frame,
    joint1_rotation,
    shape_features,
    to_joint1_frame,
)
from plugcell.io.residual_models import FORMAT_VERSION, ResidualFileError, load_residual
from plugcell.kinematics.transforms import so3_exp


class _Linear:
    """A stand-in regressor: a fixed linear function of the features."""

    def __init__(self, w: np.ndarray) -> None:
        self.w = w

    def predict(self, X: np.ndarray) -> np.ndarray:
        return X @ self.w


def _stage(threshold: float = 0.5) -> ShapeStage:
    from sklearn.neighbors import NearestNeighbors

    rng = np.random.default_rng(3)
    q = rng.uniform(-1.5, 1.5, size=(300, 6))
    ests = tuple(_Linear(w) for w in rng.normal(scale=1e-4, size=(6, 4)))
    return ShapeStage(joints=(1, 2), estimators=ests,
                      neighbours=NearestNeighbors(n_neighbors=1).fit(shape_features(q, (1, 2))),
                      threshold=threshold, params={}, physical_mm=0.4, cv_mm=0.3, useful=True)


def test_joint1_rotation_is_the_exponential_about_base_z():
    a = np.array([-3.0, -0.4, 0.0, 1.2, 7.0])
    np.testing.assert_allclose(joint1_rotation(a), so3_exp(np.outer(a, [0.0, 0.0, 1.0])),
                               atol=1e-15)


def test_joint1_frame_round_trip_rotates_every_three_vector():
    rng = np.random.default_rng(0)
    q1 = rng.uniform(-4, 4, 20)
    v = rng.normal(size=(20, 6))
    w = to_joint1_frame(q1, v)
    np.testing.assert_allclose(from_joint1_frame(q1, w), v, atol=1e-15)
    R = joint1_rotation(q1)
    np.testing.assert_allclose(w[:, 3:], np.einsum("nji,nj->ni", R, v[:, 3:]), atol=1e-15)
    # z components and lengths are untouched (a rotation about z)
    np.testing.assert_allclose(w[:, [2, 5]], v[:, [2, 5]], atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(w[:, :3], axis=1),
                               np.linalg.norm(v[:, :3], axis=1), atol=1e-15)


def test_shape_stage_turns_with_joint_1_and_ignores_the_wrist():
    """The same arm shape at another joint-1 angle: the correction is the same vector
    turned by the angle difference (what makes it carry over to another azimuth); the
    wrist joints do not enter."""
    st = _stage(threshold=10.0)
    rng = np.random.default_rng(1)
    q = rng.uniform(-1.5, 1.5, size=(30, 6))
    c0, inside, _ = st.predict(q)
    assert inside.all()
    a = 2.1
    q2 = q.copy()
    q2[:, 0] += a
    q2[:, 3:] = rng.uniform(-3, 3, size=(30, 3))
    c1, _, _ = st.predict(q2)
    Rz = so3_exp(np.array([0.0, 0.0, a]))
    np.testing.assert_allclose(c1[:, :3], c0[:, :3] @ Rz.T, atol=1e-18)
    np.testing.assert_allclose(c1[:, 3:], c0[:, 3:] @ Rz.T, atol=1e-18)


def test_shape_stage_falls_back_outside_its_region():
    st = _stage(threshold=0.2)
    q = np.random.default_rng(3).uniform(-1.5, 1.5, size=(300, 6))[:4]  # training poses
    q[2:, 1] += [3.0, -3.0]             # shoulder far outside
    c, inside, dist = st.predict(q)
    assert inside.tolist() == [True, True, False, False]
    assert np.all(c[~inside] == 0) and np.all(dist[~inside] > 0.2)


def test_fitted_layer_has_a_shape_stage_and_the_side_file_keeps_it(tmp_path):
    from calibration_testlib import harmonic_campaign

    from plugcell.calibration import Calibrator
    from plugcell.calibration.residual_model import ResidualLearner
    from plugcell.io.residual_models import residual_path, save_residual

    desc, cal = harmonic_campaign(400, seed=1)
    res = Calibrator(desc, "serial").fit(cal)
    grid = ({"max_leaf_nodes": 15, "min_samples_leaf": 20},)
    layer = ResidualLearner(grid=grid, trees=40).fit(res.model, cal, robot=desc.name)
    assert layer.shape is not None and layer.shape.joints == (1, 2)
    assert layer.summary()["shape_stage"]["frame"] == "joint 1"
    pred = layer.predict(cal.q[:50])
    assert pred.local is not None and np.all(pred.in_domain >= pred.local)
    plain = ResidualLearner(grid=grid, trees=40, shape_joints=()).fit(res.model, cal,
                                                                     robot=desc.name)
    assert plain.shape is None
    p = plain.predict(cal.q[:50])
    np.testing.assert_array_equal(p.local, p.in_domain)
    params = tmp_path / "p.json"
    entry = save_residual(layer, residual_path(params))
    back = load_residual(entry, params, robot=desc.name, model=res.model)
    assert back.shape is not None and back.shape.threshold == layer.shape.threshold
    np.testing.assert_array_equal(back.predict(cal.q[:50]).correction, pred.correction)
    # a side file of an unknown format version is refused
    import skops.io as sio

    blob = residual_path(params).read_bytes()
    obj = sio.loads(blob, trusted=sio.get_untrusted_types(data=blob))
    assert FORMAT_VERSION == 4 and obj["format_version"] == 3  # weight 1: format 3
    obj["format_version"] = 99
    bad = sio.dumps(obj)
    (tmp_path / "bad.skops").write_bytes(bad)
    with pytest.raises(ResidualFileError, match="format version 99"):
        load_residual({**entry, "file": "bad.skops", "sha256": hashlib.sha256(bad).hexdigest()},
                      params, robot=desc.name, model=res.model)
    # format 1 (no shape stage) still loads
    obj["format_version"] = 1
    obj.pop("shape")
    entry1 = save_residual(plain, tmp_path / "one.skops")
    o1 = sio.loads((tmp_path / "one.skops").read_bytes(),
                   trusted=sio.get_untrusted_types(data=(tmp_path / "one.skops").read_bytes()))
    o1["format_version"] = 1
    blob1 = sio.dumps(o1)
    (tmp_path / "one.skops").write_bytes(blob1)
    back1 = load_residual({**entry1, "sha256": hashlib.sha256(blob1).hexdigest()}, params,
                          robot=desc.name, model=res.model)
    assert back1.shape is None


def test_shape_stage_applies_when_the_set_up_stage_is_not_useful():
    """Each stage is judged by its own held-out cells: a set-up stage without gain is
    never applied, and the kept shape stage still corrects where it is in its domain."""
    from dataclasses import replace

    from calibration_testlib import harmonic_campaign

    from plugcell.calibration import Calibrator
    from plugcell.calibration.residual_model import ResidualLearner

    desc, cal = harmonic_campaign(400, seed=1)
    res = Calibrator(desc, "serial").fit(cal)
    grid = ({"max_leaf_nodes": 15, "min_samples_leaf": 20},)
    layer = ResidualLearner(grid=grid, trees=40).fit(res.model, cal, robot=desc.name)
    assert layer.useful and layer.shape is not None and layer.shape.useful
    q = cal.q[:50]
    idle = replace(layer, useful=False)
    pred = idle.predict(q)
    shape_corr, shape_in, _ = layer.shape.predict(q)
    assert pred.local is not None and not pred.local.any()
    assert shape_in.any()
    np.testing.assert_array_equal(pred.in_domain, shape_in)
    np.testing.assert_array_equal(pred.correction[:, :shape_corr.shape[1]], shape_corr)
    # without a shape stage, a layer without gain corrects nothing
    bare = replace(idle, shape=None).predict(q)
    assert not bare.in_domain.any() and np.all(bare.correction == 0)


def test_a_layer_learned_on_a_prior_stage_adds_it_and_its_file_keeps_it(tmp_path):
    """``fit(prior=…)`` (calibrate --residual-prior): the targets are what another
    set-up's arm-shape stage leaves, every prediction adds that stage's correction, and
    the side file (format 3) keeps it; a format-2 file (no prior) still loads."""
    import skops.io as sio
    from calibration_testlib import harmonic_campaign

    from plugcell.calibration import Calibrator
    from plugcell.calibration.residual_model import ResidualLearner, residual_targets
    from plugcell.io.residual_models import residual_path, save_residual

    desc, cal_a = harmonic_campaign(400, seed=1)
    _, cal_b = harmonic_campaign(300, seed=2)
    grid = ({"max_leaf_nodes": 15, "min_samples_leaf": 20},)
    a = ResidualLearner(grid=grid, trees=40).fit(Calibrator(desc, "serial").fit(cal_a).model,
                                                 cal_a, robot=desc.name)
    assert a.shape is not None
    model_b = Calibrator(desc, "serial").fit(cal_b).model
    b = ResidualLearner(grid=grid, trees=40).fit(model_b, cal_b, robot=desc.name,
                                                 prior=a.shape)
    assert b.prior is a.shape and b.summary()["prior_stage"] == a.shape.summary()
    E, _ = residual_targets(model_b, cal_b)
    c_all = a.shape.predict(cal_b.q)[0]
    left = np.linalg.norm(E[:, :3] - c_all[:, :3], axis=1).mean() * 1e3
    assert b.cv.physical_mm == pytest.approx(left)  # the baseline: what the prior leaves
    q = cal_b.q[:40]
    both, own = b.predict(q), replace(b, prior=None).predict(q)
    c, inside, _ = a.shape.predict(q)
    assert inside.any()
    np.testing.assert_allclose(both.correction[:, :c.shape[1]],
                               own.correction[:, :c.shape[1]] + c, atol=1e-15)
    np.testing.assert_array_equal(both.in_domain, own.in_domain | inside)
    params = tmp_path / "b.json"
    entry = save_residual(b, residual_path(params))
    back = load_residual(entry, params, robot=desc.name, model=model_b)
    assert back.prior is not None and back.prior.joints == a.shape.joints
    np.testing.assert_array_equal(back.predict(q).correction, both.correction)
    # a format-2 file: no prior stage, still read
    plain = replace(b, prior=None)
    entry2 = save_residual(plain, tmp_path / "two.skops")
    o2 = sio.loads((tmp_path / "two.skops").read_bytes(),
                   trusted=sio.get_untrusted_types(data=(tmp_path / "two.skops").read_bytes()))
    o2["format_version"] = 2
    o2["meta"].pop("prior_stage")
    blob2 = sio.dumps(o2)
    (tmp_path / "two.skops").write_bytes(blob2)
    back2 = load_residual({**entry2, "sha256": hashlib.sha256(blob2).hexdigest()}, params,
                          robot=desc.name, model=model_b)
    assert back2.prior is None
    np.testing.assert_array_equal(back2.predict(q).correction, own.correction)
