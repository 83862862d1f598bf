"""What a campaign's poses do not determine: the null space of the identification Jacobian.

A campaign can fit well and still leave directions of the parameters free: a surface
scan that holds the tool orientation constant moves the target on the flange (PROBE)
exactly like the tracker's frame (BASE) moves it, ``p_i = R_B (p_F,i + R_F t_P) + t_B``
with ``R_F`` constant, so only ``R_B R_F t_P + t_B`` is seen.  Least squares then lets
the two wander along that direction (on public tracker data: PROBE 502 m from the
flange, BASE 519 m away, a fit of 0.053 mm).  This module finds such directions and says
in words what they are.

**The undetermined subspace.**  ``H_s = H_w S⁻¹`` is the weighted identification
Jacobian (rows: poses × 3 or 6, orientation rows × the rotation weight) with every
column scaled to unit norm (``S = diag‖h_j‖``: metres, radians and compliances compare);
its SVD ``H_s = U Σ Vᵀ``.  A right singular vector ``v_k`` with

    σ_k < τ · σ₁,       τ = :data:`NULL_TOL` = 10⁻⁴

is *undetermined*.  Why 10⁻⁴: a least-squares step moves the scaled parameters along
``v_k`` by ``u_kᵀ r / σ_k``; with ``r`` the rest the model leaves, ε per row
(``‖r‖ = ε √M``, M rows), that is at most ``ε √M / σ_k``, i.e. each parameter moving
the poses by up to ``ε / σ_k`` (a scaled unit is a column's own effect spread over the
M rows).  A calibrated model leaves ε ≈ 0.1 mm of unmodelled rest (the twin 0.13 mm,
the UR10 0.39 mm, the thesis 0.4 mm), and a frame or a link that moves by more than the
arm's own size, L ≈ 1 m, is no estimate at all: ``ε / σ_k > L`` for
``σ_k < ε / L = 10⁻⁴`` (σ₁ is of order 1 for unit columns).  That is what the
constant-orientation scan does (σ/σ₁ ≈ 2·10⁻⁶ along PROBE/BASE on the twin: 0.1 mm /
2·10⁻⁶ = 50 m).  Weak but real directions stay determined: the thesis calls κ ≤ 100
well conditioned (eq. 4.10, the calibrator warns beyond it), and the weakest direction
in the test suite's campaigns that determine everything is 5·10⁻⁴ (a robot on a 3 m
track: BASE tilt against the track's twist, separated by the track's travel).

The identification keeps the undetermined combinations at their initial values: every
step is the least-squares step restricted to the orthogonal complement of the
undetermined subspace (:func:`~.linalg.restricted_basis`) — the minimum-norm
(truncated-SVD) step, ``x = V_r Σ_r⁻¹ U_rᵀ r`` at the first iteration.

**In words.**  A quantity ``c(g)`` of the frames (PROBE position and orientation in the
flange frame, BASE position and orientation in the measurement frame, each axis a
functional with gradient ``a = ∂c/∂g``, by central differences of the exact frames) is
determined when ``a`` lies in the determined subspace.  Its *undetermined share*
``η = ‖V₀ᵀ Ŝ a‖`` (``Ŝ a = S⁻¹ a / ‖S⁻¹ a‖``, ``V₀`` the undetermined basis) is 0 for a
determined quantity and 1 for a quantity the poses do not see at all; it is named when
``η > `` :data:`SHARE`.  The undetermined directions that move no frame are reported as
model parameters (keys whose unit vector has share ``> SHARE`` in them).

**The remedy for the PROBE position**, "vary the tool orientation by at least N°":
with the flange turning by small rotations ``φ_i`` about its mean orientation, a PROBE
offset change ``δt`` (BASE taking up its constant part) changes the predicted points by
``R̄ [φ_i − φ̄]× δt``, of rms ``φ_rms |δt|`` for rotations about the axes across ``δt``.
Least squares over ``n`` poses with position noise σ per coordinate gives
``std(δt) ≈ σ / (√n · φ_rms)``.  The PROBE position is known to the measurement noise
(``std(δt) ≤ σ`` — no worse than one measurement) when ``φ_rms ≥ 1/√n`` rad; for
rotations spread uniformly up to ``φ_max`` (``φ_rms = φ_max/√3``) that is

    N = φ_max ≥ √(3/n) rad        (1 300 poses: 2.8°; 300: 5.7°; 100: 9.9°),

independent of σ itself, which cancels.  The detection threshold τ is weaker than this
(a direction is flagged only when it is practically free), so a campaign between the
two is not flagged but its PROBE is known only to some times the noise.

Pure math (numpy), SI units.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from plugcell.calibration.initial import _project_rotation
from plugcell.calibration.linalg import null_space
from plugcell.calibration.model import ErrorModel, fold_frames
from plugcell.kinematics.transforms import so3_log

Array = NDArray[np.float64]

#: Relative singular value below which a direction of the scaled Jacobian is undetermined.
NULL_TOL = 1e-4
#: Undetermined share above which a frame quantity or a parameter is named.
SHARE = 0.3
#: Orientations within the campaign's spread plus this (rad) count as the campaign's own.
ORIENTATION_TOL = math.radians(0.1)
#: Central-difference step of the frame gradients (parameter units: m or rad).
FD_STEP = 1e-6

#: The frame quantities, in the order of :func:`frame_gradients`' rows (3 axes each).
COMPONENTS: tuple[str, ...] = ("probe_position", "probe_orientation", "base_position",
                               "base_orientation")
#: How a user reads them.
WORDS: dict[str, str] = {"probe_position": "PROBE position",
                         "probe_orientation": "PROBE orientation",
                         "base_position": "BASE position", "base_orientation": "BASE orientation"}
AXES = ("x", "y", "z")

__all__ = [
    "COMPONENTS",
    "NULL_TOL",
    "ORIENTATION_TOL",
    "SHARE",
    "Undetermined",
    "analyse_determinacy",
    "frame_gradients",
    "orientation_spread",
    "required_spread",
    "with_probe",
]


@dataclass(frozen=True, eq=False)
class Undetermined:
    """What the calibration poses do not determine (module docstring), as recorded.

    Attributes
    ----------
    components : tuple of str
        Frame quantities not determined, from :data:`COMPONENTS`.
    probe_axes : tuple of str
        The flange-frame axes (``"x"``, ``"y"``, ``"z"``) along which the PROBE position
        is not determined.
    parameters : tuple of str
        Model parameter keys in undetermined directions that move no frame.
    given : tuple of str
        Frames the user gave (``"base"``, ``"probe"``): an undetermined one keeps the
        given value, which counts as known.
    orientation_spread_rad : float, rad
        Largest angle of the campaign's flange orientations from their mean.
    required_spread_rad : float, rad
        ``√(3/n)``: the spread that determines the PROBE position to the noise.
    flange_orientation : (3, 3) array
        The campaign's mean flange orientation in the robot base frame.
    n_poses : int
        Calibration poses.
    n_directions : int
        Dimension of the undetermined subspace.
    tolerance : float
        τ of the test.
    messages : tuple of str
        The warnings, one per undetermined quantity.
    """

    components: tuple[str, ...]
    probe_axes: tuple[str, ...]
    parameters: tuple[str, ...]
    given: tuple[str, ...]
    orientation_spread_rad: float
    required_spread_rad: float
    flange_orientation: Array
    n_poses: int
    n_directions: int
    tolerance: float
    messages: tuple[str, ...]

    def unknown(self, component: str) -> bool:
        """``component`` is undetermined and was not given by the user (so any result
        that depends on it depends on a value nobody measured).

        Parameters
        ----------
        component : str
            One of :data:`COMPONENTS`.

        Returns
        -------
        bool
            True when a result depending on it must not be trusted.
        """
        frame = component.split("_")[0]
        return component in self.components and frame not in self.given

    def orientation_offset(self, flange_rotations: Array) -> Array:
        """Angle of flange orientations from the campaign's mean one.

        Parameters
        ----------
        flange_rotations : (N, 3, 3) array
            Flange orientations in the robot base frame.

        Returns
        -------
        (N,) array, rad
            ``‖log(R̄ᵀ R_i)‖``.
        """
        R = np.asarray(flange_rotations, dtype=float).reshape(-1, 3, 3)
        return np.linalg.norm(so3_log(self.flange_orientation.T @ R), axis=-1)

    def away(self, flange_rotations: Array) -> NDArray[np.bool_]:
        """Flange orientations beyond the campaign's: farther from its mean than its own
        spread plus :data:`ORIENTATION_TOL` — where what the poses did not determine
        shows (a PROBE offset error δ moves the tool point by about ``|δ|·angle``).

        Parameters
        ----------
        flange_rotations : (N, 3, 3) array
            Flange orientations in the robot base frame.

        Returns
        -------
        (N,) bool array
            True where the orientation lies beyond the campaign's.
        """
        return self.orientation_offset(flange_rotations) > (self.orientation_spread_rad
                                                             + ORIENTATION_TOL)


def required_spread(n_poses: int) -> float:
    """The orientation spread that determines the PROBE position to the measurement noise,
    ``φ_max = √(3/n)`` rad (module docstring).

    Parameters
    ----------
    n_poses : int
        Calibration poses n.

    Returns
    -------
    float, rad
        ``√(3/n)``.
    """
    return math.sqrt(3.0 / max(int(n_poses), 1))


def orientation_spread(flange_rotations: Array) -> tuple[Array, float]:
    """The mean flange orientation and the largest angle of a pose from it.

    ``R̄ = proj_SO(3)(Σ_i R_i)``, spread ``max_i ‖log(R̄ᵀ R_i)‖``.

    Parameters
    ----------
    flange_rotations : (N, 3, 3) array
        Flange orientations.

    Returns
    -------
    mean : (3, 3) array
        R̄.
    spread : float, rad
        The largest angle from it.
    """
    R = np.asarray(flange_rotations, dtype=float)
    mean = _project_rotation(R.sum(axis=0))
    return mean, float(np.linalg.norm(so3_log(mean.T @ R), axis=-1).max())


def _frames(model: ErrorModel) -> Array:
    """``[t_P, φ_P, t_B, φ_B]`` (12,): PROBE (flange link folded in) and BASE."""
    f = fold_frames(model)
    P, B = f.probe_ref, f.base_ref
    return np.concatenate([P[:3, 3], so3_log(P[:3, :3]), B[:3, 3], so3_log(B[:3, :3])])


def frame_gradients(model: ErrorModel, keys: Sequence[str]) -> Array:
    """Gradients of the frame quantities with respect to the parameters ``keys``.

    Rows: PROBE translation (3, m, flange frame — the flange link's constant part folded
    in, :func:`~.model.fold_frames`), PROBE rotation (3, rad, a small rotation on the
    right, flange frame), BASE translation (3, m), BASE rotation (3, rad, on the left,
    measurement frame).  Central differences of the exact frames,
    ``(c(g + h e_j) − c(g − h e_j)) / 2h`` with rotations as ``log(R₀ᵀ R)`` (PROBE) and
    ``log(R R₀ᵀ)`` (BASE), h = :data:`FD_STEP`.

    Parameters
    ----------
    model : ErrorModel
        The model at the point of linearisation.
    keys : sequence of str
        The parameters.

    Returns
    -------
    (12, len(keys)) array
        ∂c/∂g, metres or radians per parameter unit.
    """
    f0 = fold_frames(model)
    RP0, RB0 = f0.probe_ref[:3, :3], f0.base_ref[:3, :3]

    def c(m: ErrorModel) -> Array:
        f = fold_frames(m)
        P, B = f.probe_ref, f.base_ref
        return np.concatenate([P[:3, 3], so3_log(RP0.T @ P[:3, :3]), B[:3, 3],
                               so3_log(B[:3, :3] @ RB0.T)])

    out = np.zeros((12, len(keys)))
    for j, k in enumerate(keys):
        if model.space[k].kind not in ("base", "probe", "link"):
            continue  # compliance and thermal terms move no frame
        out[:, j] = (c(model.updated({k: FD_STEP})) - c(model.updated({k: -FD_STEP}))) / (
            2 * FD_STEP)
    return out


def analyse_determinacy(
    model: ErrorModel, H: Array, keys: Sequence[str], flange_rotations: Array, *,
    given: Sequence[str] = (), kept: Sequence[str] | None = None, tol: float = NULL_TOL,
) -> Undetermined | None:
    """The undetermined directions of ``H`` and what they are in words (module docstring).

    Parameters
    ----------
    model : ErrorModel
        The model ``H`` was evaluated at.
    H : (rows, k) array
        Weighted identification Jacobian (poses × 3 or 6 rows) of ``keys``.
    keys : sequence of str
        Its parameters.
    flange_rotations : (N, 3, 3) array
        The campaign's flange orientations in the robot base frame.
    given : sequence of str
        ``"base"`` and/or ``"probe"`` when the user gave them.
    kept : sequence of str, optional
        The columns identified after the column-by-column test (default: all): the model
        parameters are named from the undetermined directions of these columns only (a
        column the test dropped has its own warning, unless some are named: then the
        dropped ones join them in one warning); the frames from all of them.
    tol : float
        τ.

    Returns
    -------
    Undetermined or None
        ``None`` when every direction is determined.
    """
    keys = list(keys)
    H = np.asarray(H, dtype=float)
    scale = np.linalg.norm(H, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    _, V0 = null_space(H / scale, tol)
    if V0.shape[1] == 0:
        return None
    grads = frame_gradients(model, keys) / scale  # functionals in scaled coordinates
    norms = np.linalg.norm(grads, axis=1)
    rows = norms > 1e-12 * max(float(norms.max()), 1e-300)
    A = np.zeros_like(grads)
    A[rows] = grads[rows] / norms[rows, None]
    share = np.linalg.norm(A @ V0, axis=1)  # (12,)
    comps = tuple(c for i, c in enumerate(COMPONENTS) if share[3 * i:3 * i + 3].max() > SHARE)
    axes = tuple(a for i, a in enumerate(AXES) if share[i] > SHARE)
    # undetermined directions of the kept columns that move no frame: the model's own
    idx = list(range(len(keys))) if kept is None else [keys.index(k) for k in kept]
    _, Vk = null_space(H[:, idx] / scale[idx], tol)
    G = A[rows][:, idx] @ Vk
    if G.size:
        _, sg, Wt = np.linalg.svd(G, full_matrices=True)
        sg = np.concatenate([sg, np.zeros(Vk.shape[1] - len(sg))])
        Vk = Vk @ Wt[sg <= SHARE].T
    s = model.structure
    frame_keys = {k for k in keys if model.space[k].kind in ("base", "probe")
                  or (model.space[k].kind == "link" and model.space[k].link == s.desc.flange)}
    pshare = np.linalg.norm(Vk, axis=1) if Vk.size else np.zeros(len(idx))
    params = tuple(keys[i] for i, sh in zip(idx, pshare, strict=True)
                   if sh > SHARE and keys[i] not in frame_keys)
    if params and kept is not None:  # one warning: with the columns the column test dropped
        params += tuple(k for k in keys if k not in kept and k not in frame_keys)
    mean, spread = orientation_spread(flange_rotations)
    n = len(flange_rotations)
    und = Undetermined(components=comps, probe_axes=axes, parameters=params,
                       given=tuple(given), orientation_spread_rad=spread,
                       required_spread_rad=required_spread(n), flange_orientation=mean,
                       n_poses=n, n_directions=int(V0.shape[1] if comps else Vk.shape[1]),
                       tolerance=float(tol), messages=())
    msgs = _messages(und, model)
    if not msgs:
        return None
    return Undetermined(**{**und.__dict__, "messages": msgs})


def _messages(u: Undetermined, model: ErrorModel) -> tuple[str, ...]:
    """One warning per undetermined quantity, with its remedy."""
    out = []
    spread = math.degrees(u.orientation_spread_rad)
    need = math.degrees(u.required_spread_rad)
    probe_t = np.round(fold_frames(model).probe_ref[:3, 3] * 1e3, 1) + 0.0  # no "-0.0"
    comps = set(u.components)
    if "probe_position" in comps:
        along = "" if len(u.probe_axes) == 3 else (
            " along the flange's " + ", ".join(u.probe_axes) + " axis"
            + ("es" if len(u.probe_axes) > 1 else ""))
        kept = ("the --probe given" if "probe" in u.given
                else "its initial value, the robot description's tool point")
        out.append(
            f"PROBE position not determined{along}: the tool orientation (from the joint "
            f"readings) varies by only "
            f"{spread:.2g}° over the campaign, so the target's offset on the flange cannot be "
            f"told apart from the BASE position; kept at {kept} "
            f"({probe_t[0]:.1f}, {probe_t[1]:.1f}, {probe_t[2]:.1f} mm), BASE with it. Vary "
            f"the tool orientation by at least {need:.1f}° (which determines it to the "
            f"measurement noise with {u.n_poses} poses) or give --probe")
        comps.discard("base_position")
    if "probe_orientation" in comps:
        out.append("PROBE orientation not determined by these poses (kept at its initial "
                   "estimate); give --probe")
    for c in ("base_position", "base_orientation"):
        if c in comps:
            out.append(f"{WORDS[c]} not determined by these poses (kept at its initial "
                       "estimate); spread the poses over more of the working volume or give "
                       "--base")
    if u.parameters:
        names = ", ".join(model.space[k].name for k in u.parameters)
        out.append(f"model parameters not determined by these poses: {names} — the "
                   f"combination{'s' if u.n_directions > 1 else ''} the poses cannot see "
                   "stay at their nominal values; spread the joints and the tool orientation "
                   "wider")
    return tuple(out)



def with_probe(model: ErrorModel, probe: Array, undetermined: Undetermined | None) -> ErrorModel:
    """``model`` with a PROBE given by the user, BASE re-expressed when the campaign did not
    determine the PROBE position.

    The BASE and PROBE errors are folded (``BASE_ref = BASE``) or replaced
    (``PROBE_ref = probe``, relative to the calibrated flange; the flange link's errors
    stay in the chain).  When the PROBE position was undetermined, the campaign saw only
    ``R_B R̄_F t_P + t_B`` (``R̄_F`` its flange orientation, module docstring); BASE then
    moves by ``t_B' = t_B + R_B R̄_F (t_P − t_P')`` so that this stays as measured, with
    ``t_P`` the kept and ``t_P'`` the given offset (calibrated flange frame).

    Parameters
    ----------
    model : ErrorModel
        The calibrated model.
    probe : (4, 4) array, m
        The target (tool point) in the flange frame.
    undetermined : Undetermined or None
        What the calibration did not determine.

    Returns
    -------
    ErrorModel
        The model with that PROBE (and BASE).
    """
    probe = np.asarray(probe, dtype=float)
    v = np.array(model.values)
    for j, prm in enumerate(model.space):
        if prm.kind in ("base", "probe"):
            v[j] = 0.0
    base = model.base().copy()
    if undetermined is not None and "probe_position" in undetermined.components:
        shift = undetermined.flange_orientation @ (model.probe()[:3, 3] - probe[:3, 3])
        base[:3, 3] += base[:3, :3] @ shift
    # with zero PROBE errors, PROBE = PROBE_ref, relative to the calibrated flange
    return model.with_values(v).with_references(base=base, probe=probe)
