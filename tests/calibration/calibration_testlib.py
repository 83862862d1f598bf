"""Helpers shared by the calibration tests (importable: the test directory is on sys.path)."""

from __future__ import annotations

import numpy as np

from plugcell.calibration.model import ErrorModel
from plugcell.io.robot_schema import description_from_dict
from plugcell.kinematics import RobotDescription, pose_error
from plugcell.kinematics.transforms import so3_exp

_UR10_A = [0.0, -0.612, -0.5723, 0.0, 0.0, 0.0]
_UR10_D = [0.1273, 0.0, 0.0, 0.163941, 0.1157, 0.0922]
_UR10_ALPHA = [90.0, 0.0, 0.0, 90.0, -90.0, 0.0]


def ur10_toml() -> str:
    """:func:`ur10_description` without masses as a description file (for CLI tests)."""
    out = ['format_version = 1', 'name = "ur10-test"', 'actuated = ["1", "2", "3", "4", "5", "6"]',
           'flange = "6"', "home = [0.0, -90.0, 90.0, 0.0, 90.0, 0.0]"]
    for i in range(6):
        out += ["[[links]]", f'name = "{i + 1}"', f'parent = "{"base" if i == 0 else i}"',
                'joint = "actuated"', f"d = {_UR10_D[i]}", f"a = {_UR10_A[i]}",
                f"alpha = {_UR10_ALPHA[i]}", "limits = [-360.0, 360.0]"]
    return "\n".join(out) + "\n"


def ur10_description() -> RobotDescription:
    """A plain 6R robot without a loop: the UR10's nominal DH (issue 3), with masses."""
    a, d, alpha = _UR10_A, _UR10_D, _UR10_ALPHA
    mass = [7.1, 12.7, 4.3, 2.0, 2.0, 0.4]
    com = [[0, -0.02, 0], [0.3, 0, 0.15], [0.25, 0, 0.03], [0, 0, 0], [0, 0, 0], [0, 0, -0.02]]
    links = []
    for i in range(6):
        links.append({
            "name": str(i + 1), "parent": "base" if i == 0 else str(i), "joint": "actuated",
            "d": d[i], "a": a[i], "alpha": alpha[i], "limits": [-360.0, 360.0],
            "mass": mass[i], "com": com[i],
        })
    return description_from_dict({
        "name": "ur10-test", "actuated": [str(i + 1) for i in range(6)], "flange": "6",
        "links": links, "home": [0.0, -90.0, 90.0, 0.0, 90.0, 0.0],
    })



def random_frame(rng: np.random.Generator, angle: float = 1.0, dist: float = 1.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = so3_exp(rng.normal(size=3) * angle)
    T[:3, 3] = rng.normal(size=3) * dist
    return T


def harmonic_campaign(n: int, seed: int = 0, amplitude_rad: float = 4e-4,
                      noise_m: float = 10e-6, base: np.ndarray | None = None):
    """Poses of the UR10 test robot with an effect no physical model of the library has:
    a transmission error ``Δθ_j = A sin(2 q_j + j)`` on joints 2–4 (reducer
    eccentricity), plus tracker noise.  Returns (description, CalibrationData) in a
    tracker frame ``base`` (default a fixed offset frame), positions and orientations.
    """
    from plugcell.calibration import CalibrationData, ErrorModel

    desc = ur10_description()
    rng = np.random.default_rng(seed)
    q = np.column_stack([rng.uniform(-2.5, -0.5, n), rng.uniform(-2.2, -0.4, n),
                         rng.uniform(0.4, 2.2, n), rng.uniform(-2.5, 0.5, n),
                         rng.uniform(-2.0, 2.0, n), rng.uniform(-1.5, 1.5, n)])
    B = np.eye(4)
    B[:3, 3] = [2.0, -1.0, 0.3]
    B = B if base is None else base
    probe = np.eye(4)
    probe[:3, 3] = [0.02, 0.03, 0.08]
    m = ErrorModel.create(desc, "serial", base=B, probe=probe)
    dq = np.zeros_like(q)
    for j in (1, 2, 3):
        dq[:, j] = amplitude_rad * np.sin(2 * q[:, j] + j)
    T = m.predict(q + dq)
    T[:, :3, 3] += rng.normal(scale=noise_m, size=(n, 3))
    return desc, CalibrationData.from_poses(q, T)


#: Step of the central differences of the identification Jacobian (m, rad).
H_FD = 1e-6


def fd_columns(model: ErrorModel, batch, keys) -> np.ndarray:
    """Central differences of the predicted poses along the parameters ``keys``: the
    columns the identification Jacobian is checked against (pose error, m and rad)."""
    T0 = model.predict_batch(batch)
    cols = []
    for k in keys:
        # a joint compliance c_j (rad/(N·m)) multiplies torques of up to ~1e4 N·m: its
        # step is scaled so that it moves the joints by ~1e-6 rad like the others
        h = H_FD
        if k in model.compliance_keys:
            reg = batch.regressors[:, :, model.compliance_keys.index(k)]
            h = H_FD / max(1.0, float(np.abs(reg).max()))
        Tp = model.updated({k: h}).predict_batch(batch)
        Tm = model.updated({k: -h}).predict_batch(batch)
        cols.append((pose_error(Tp, T0) - pose_error(Tm, T0)) / (2 * h))
    return np.stack(cols, axis=-1)


def perturbed_model(desc: RobotDescription, family: str, rng: np.random.Generator, *,
                    scale: float = 2e-3, **create) -> ErrorModel:
    """An error model (``ErrorModel.create(desc, family, **create)``) with random BASE
    and PROBE and random values: ``scale`` for every parameter, 1e-4 of it for the joint
    compliances (rad/(N·m): against torques of ~1e3 N·m)."""
    m = ErrorModel.create(desc, family, **create)
    m = m.with_references(random_frame(rng, 1.0, 2.0), random_frame(rng, 0.5, 0.1))
    v = rng.normal(size=len(m.space)) * scale
    for i, p in enumerate(m.space):
        if p.unit == "rad/(N·m)":
            v[i] *= 1e-4
    return m.with_values(v)
