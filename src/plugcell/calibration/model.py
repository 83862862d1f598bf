"""The error model: predicts the measured target pose from joint readings (eq. 6.23).

An :class:`ErrorModel` is immutable (the *model* side, as in Pinocchio): a
kinematic structure (:mod:`.structure`), the space of candidate error parameters
and their current values Δg, the reference BASE and PROBE the BASE/PROBE errors
are relative to, and the payload mass the payload constants refer to.  For joint
readings ``q`` and payloads ``m`` it predicts::

    T(q, m) = BASE · T_n^0(θ(q) + Δθ(q, m)) · PROBE                   (6.23, 4.16)

    BASE   = BASE_ref · Tx(a0) Ty(b0) Rx(α0) Ry(β0) Rz(θ0) Tz(d0)      (6.24)
    PROBE  = Rx(−90°) · Rz(θ7) Tz(d7) Tx(a7) Rx(90° + α7) · PROBE_ref  (frame 7, 6.2.2)
    Δθ     = R(q, m) · c                                              (6.31, 6.40)

with θ(q) the kinematic joints of the readings q (the readings themselves unless
the description has a joint ``coupling``, θ = M·q + offset).

``T_n^0`` is the flange of the structure's chain with the nominal geometry plus
the link errors, the passive angles from the *exact* four-bar closure.  A
:class:`PoseBatch` (the *data* side) holds a set of readings with their
compliance regressors, computed once and reused by every iteration of an
identification.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.compliance import (
    compliance_regressors,
    gravity_parameters,
    harmonic_parameters,
    payload_parameters,
)
from plugcell.calibration.parameters import ErrorParameter, ParameterSpace
from plugcell.calibration.structure import (
    CLASS_THERMAL,
    KinematicStructure,
    kinematic_structure,
)
from plugcell.kinematics import GeometricParameters, RobotDescription, forward
from plugcell.kinematics.transforms import dh_hayati, rot_x, rot_y, rot_z, translation

Array = NDArray[np.float64]

__all__ = [
    "MIN_PAYLOAD_REF_KG",
    "ErrorModel",
    "PoseBatch",
    "base_transform",
    "fold_frames",
    "probe_transform",
]

_HALF_PI = 0.5 * math.pi


#: Key of the thermal expansion term: every length of the chain scales by
#: ``1 + κT·(T − T_ref)`` — the flange position in the robot base frame scales by it
#: (rotations do not depend on lengths), the PROBE is not scaled.
THERMAL_KEY = "kT"
THERMAL_PARAMETER = ErrorParameter(key=THERMAL_KEY, name="κT", kind="thermal", unit="1/K",
                                   priority=(CLASS_THERMAL, 0, 0))

def base_transform(base_ref: Array, a0: float, b0: float, alpha0: float, beta0: float,
                   theta0: float, d0: float) -> Array:
    """``BASE = BASE_ref · Tx(a0) Ty(b0) Rx(α0) Ry(β0) Rz(θ0) Tz(d0)`` (eq. 6.24 after BASE_ref).

    Parameters
    ----------
    base_ref : (4, 4) array, m
        Reference BASE the errors are relative to.
    a0, b0 : float, m
        Translations along the reference x, y.
    alpha0, beta0, theta0 : float, rad
        Rotations about the successive x, y, z.
    d0 : float, m
        Translation along the final z.

    Returns
    -------
    (4, 4) array, m
        BASE, the robot base frame in the measurement frame.
    """
    return (
        base_ref
        @ translation([a0, b0, 0.0])
        @ rot_x(alpha0)
        @ rot_y(beta0)
        @ rot_z(theta0)
        @ translation([0.0, 0.0, d0])
    )


def probe_transform(probe_ref: Array, theta7: float, d7: float, a7: float, alpha7: float) -> Array:
    """``PROBE = Rx(−90°) · Rz(θ7) Tz(d7) Tx(a7) Rx(90° + α7) · PROBE_ref`` (frame 7, 6.2.2).

    Parameters
    ----------
    probe_ref : (4, 4) array, m
        Reference PROBE the errors are relative to.
    theta7 : float, rad
        Rotation about the flange's y axis (the z of the virtual parent frame).
    d7 : float, m
        Translation along that axis.
    a7 : float, m
        Translation along the virtual frame's x.
    alpha7 : float, rad
        Twist about that x.

    Returns
    -------
    (4, 4) array, m
        PROBE, the target in the flange frame.
    """
    return rot_x(-_HALF_PI) @ dh_hayati(theta7, d7, a7, _HALF_PI + alpha7) @ probe_ref



#: The smallest payload reference a model can have (kg): the payload compliances scale
#: with m / m_ref (eq. 6.41), so a reference of a gram or less is no payload at all.
MIN_PAYLOAD_REF_KG = 1e-3

@dataclass(frozen=True, eq=False)
class PoseBatch:
    """Joint readings with their payloads, compliance regressors and temperatures.

    Attributes
    ----------
    q : (N, n_readings) array, rad
        Joint readings.
    payload_kg : (N,) array, kg
        Payloads.
    regressors : (N, n_actuated, n_c) array
        Compliance regressors ``R(q, m)`` of a model, ``Δθ = R c`` (joint deflections of
        the kinematic joints; columns in the order of ``ErrorModel.compliance_keys``).
    temperature_c : (N,) array, °C, or None
        Temperatures, ``None``: poses at the model's reference temperature.
    """

    q: Array
    payload_kg: Array
    regressors: Array
    temperature_c: Array | None = None

    def delta_t(self, reference_c: float) -> Array:
        """Temperature above the reference, ``ΔT_i = T_i − T_ref``.

        Parameters
        ----------
        reference_c : float, °C
            The reference temperature T_ref (the model's ``temperature_ref_c``).

        Returns
        -------
        (N,) array, K
            ΔT per pose; zeros when the batch has no temperatures.
        """
        if self.temperature_c is None:
            return np.zeros(len(self.q))
        return self.temperature_c - reference_c

    def __len__(self) -> int:
        return int(self.q.shape[0])


@dataclass(frozen=True, eq=False)
class ErrorModel:
    """Immutable error model (module docstring).  Build one with :meth:`create`.

    ``T(q, m) = BASE · T_n^0(θ(q) + Δθ(q, m)) · PROBE`` (6.23, 4.16).

    Attributes
    ----------
    structure : KinematicStructure
        The chain and model family.
    space : ParameterSpace
        The candidate error parameters Δg.
    values : (len(space),) array
        Their current values, each in its parameter's unit (read-only).
    base_ref : (4, 4) array, m
        Reference BASE the BASE errors are relative to.
    probe_ref : (4, 4) array, m
        Reference PROBE the PROBE errors are relative to.
    payload_ref_kg : float, kg
        Payload the payload constants refer to.
    temperature_ref_c : float, °C
        Reference temperature of the thermal term.

    Raises
    ------
    ValueError
        ``values`` of the wrong shape.
    """

    structure: KinematicStructure
    space: ParameterSpace
    values: Array
    base_ref: Array
    probe_ref: Array
    payload_ref_kg: float = 0.0
    temperature_ref_c: float = 0.0

    def __post_init__(self) -> None:
        v = np.array(self.values, dtype=float)
        if v.shape != (len(self.space),):
            raise ValueError(f"values: expected shape ({len(self.space)},), got {v.shape}")
        v.setflags(write=False)
        object.__setattr__(self, "values", v)
        for key in ("base_ref", "probe_ref"):
            T = np.array(getattr(self, key), dtype=float)
            if T.shape != (4, 4):
                raise ValueError(f"{key}: expected a 4x4 transform, got shape {T.shape}")
            T.setflags(write=False)
            object.__setattr__(self, key, T)
        object.__setattr__(self, "_nominal", self.structure.nominal_parameters())
        object.__setattr__(self, "_reference", self.structure.source.nominal_parameters())
        object.__setattr__(
            self, "_compliance", self.space.of_kind("gravity", "payload", "harmonic")
        )

    # ------------------------------------------------------------------ construction
    @classmethod
    def create(
        cls,
        desc: RobotDescription,
        family: str = "loop",
        *,
        gravity: bool = False,
        payload: bool = False,
        base: ArrayLike | None = None,
        probe: ArrayLike | None = None,
        payload_ref_kg: float = 0.0,
        harmonics: int = 0,
        thermal: bool = False,
        temperature_ref_c: float = 0.0,
    ) -> ErrorModel:
        """All candidate parameters of ``family`` (+ gravity, + payload, + joint-angle
        harmonics up to order ``harmonics``, + the thermal expansion κT about
        ``temperature_ref_c`` when ``thermal``), values zero.

        With Δg = 0 the model predicts the nominal robot,
        ``T(q) = BASE_ref · T_n^0(θ(q)) · PROBE_ref`` (eq. 6.23 without errors).

        Parameters
        ----------
        desc : RobotDescription
            The robot.
        family : str
            Model family of the kinematic structure
            (:func:`~plugcell.calibration.structure.kinematic_structure`), e.g. ``"loop"``.
        gravity : bool
            Add the gravity compliance parameters (Δθ = R_g(q) c_g, eqs. 6.31, 6.40).
        payload : bool
            Add the payload compliance constants (eq. 6.41, scaled by m / m_ref).
        base : (4, 4) array_like, m, optional
            Reference BASE, the robot base in the measurement frame (default
            ``desc.base``).
        probe : (4, 4) array_like, m, optional
            Reference PROBE, the target in the flange frame (default ``desc.tool``).
        payload_ref_kg : float, kg
            The payload m_ref the payload constants refer to.
        harmonics : int
            Highest order k of the joint-angle harmonics ``sin(k q_j)``, ``cos(k q_j)``
            (0: none).
        thermal : bool
            Add the thermal expansion coefficient κT (1/K).
        temperature_ref_c : float, °C
            Reference temperature of κT.

        Returns
        -------
        ErrorModel
            The model, every value zero.
        """
        structure = kinematic_structure(desc, family)
        params = list(structure.candidates())
        if gravity:
            params += gravity_parameters(desc)
        if payload:
            params += payload_parameters(desc)
        params += harmonic_parameters(desc, harmonics)
        if thermal:
            params.append(THERMAL_PARAMETER)
        space = ParameterSpace(tuple(params))
        return cls(
            structure=structure,
            space=space,
            values=np.zeros(len(space)),
            base_ref=np.asarray(desc.base if base is None else base, dtype=float),
            probe_ref=np.asarray(desc.tool if probe is None else probe, dtype=float),
            payload_ref_kg=float(payload_ref_kg),
            temperature_ref_c=float(temperature_ref_c),
        )

    # ------------------------------------------------------------------ values
    def value(self, key: str) -> float:
        """The current value of one parameter.

        Parameters
        ----------
        key : str
            Parameter key (e.g. ``"a2'"``).

        Returns
        -------
        float
            Δg_key, in the parameter's unit (m, rad, rad/(N·m)…, ``space[key].unit``).

        Raises
        ------
        KeyError
            Unknown key.
        """
        return float(self.values[self.space.index(key)])

    def as_dict(self) -> dict[str, float]:
        """Every parameter's value by key.

        Returns
        -------
        dict of str to float
            ``{key: Δg_key}``, in :attr:`space` order, each in its parameter's unit.
        """
        return {k: float(v) for k, v in zip(self.space.keys, self.values, strict=True)}

    def with_values(self, values: ArrayLike) -> ErrorModel:
        """The same model (structure, space, references) with other parameter values.

        Parameters
        ----------
        values : (len(space),) array_like
            New Δg, each in its parameter's unit.

        Returns
        -------
        ErrorModel
            The new model.

        Raises
        ------
        ValueError
            ``values`` of the wrong shape.
        """
        return ErrorModel(self.structure, self.space, np.asarray(values, float), self.base_ref,
                          self.probe_ref, self.payload_ref_kg, self.temperature_ref_c)

    def updated(self, delta: Mapping[str, float] | None = None, *,
                keys: Sequence[str] | None = None, step: ArrayLike | None = None) -> ErrorModel:
        """A copy with increments added, ``Δg ← Δg + δ``: ``updated({"a2'": 1e-3})`` or
        ``updated(keys=, step=)`` (both may be given; both add).

        Parameters
        ----------
        delta : mapping of str to float, optional
            ``{key: δ}``, each in its parameter's unit.
        keys : sequence of str, optional
            Parameters ``step`` applies to (e.g. the identified ones).
        step : (len(keys),) array_like, optional
            Increments, in ``keys`` order (required with ``keys``; e.g. a Gauss–Newton step).

        Returns
        -------
        ErrorModel
            The updated model.

        Raises
        ------
        KeyError
            An unknown key.
        ValueError
            ``keys`` without ``step``, or a ``step`` of another length than ``keys``.
        """
        v = np.array(self.values)
        if delta:
            for k, x in delta.items():
                v[self.space.index(k)] += float(x)
        if keys is not None:
            if step is None:
                raise ValueError("updated(keys=...) needs step: one increment per key")
            s = np.asarray(step, dtype=float).reshape(-1)
            if s.shape != (len(keys),):
                raise ValueError(f"step has {s.size} increment(s) for {len(keys)} key(s)")
            v[self.space.indices(keys)] += s
        return self.with_values(v)

    def with_references(self, base: ArrayLike | None = None, probe: ArrayLike | None = None,
                        payload_ref_kg: float | None = None) -> ErrorModel:
        """The same model with other references BASE_ref, PROBE_ref, m_ref (values kept,
        so BASE/PROBE errors now act on the new references).

        Parameters
        ----------
        base : (4, 4) array_like, m, optional
            New BASE_ref (default: unchanged).
        probe : (4, 4) array_like, m, optional
            New PROBE_ref (default: unchanged).
        payload_ref_kg : float, kg, optional
            New m_ref (default: unchanged).

        Returns
        -------
        ErrorModel
            The new model.

        Raises
        ------
        ValueError
            A reference that is not 4×4.
        """
        return ErrorModel(
            self.structure, self.space, self.values,
            self.base_ref if base is None else np.asarray(base, float),
            self.probe_ref if probe is None else np.asarray(probe, float),
            self.payload_ref_kg if payload_ref_kg is None else float(payload_ref_kg),
            self.temperature_ref_c,
        )

    @property
    def compliance_keys(self) -> tuple[str, ...]:
        """Keys of the compliance parameters c (gravity, payload, harmonic), in the order
        of the columns of :attr:`PoseBatch.regressors`."""
        return self._compliance  # type: ignore[attr-defined,no-any-return]

    @property
    def nominal(self) -> GeometricParameters:
        """Nominal geometry of the structure's chain."""
        return self._nominal  # type: ignore[attr-defined,no-any-return]

    # ------------------------------------------------------------------ parts
    def geometric_parameters(self) -> GeometricParameters:
        """Nominal geometry of the chain plus the link errors, ``g = g_nom + Δg_link``.

        Returns
        -------
        GeometricParameters
            θ, α, β (rad), d, a (m) per link of the structure's description.
        """
        delta = {
            (p.link, p.field): float(v)
            for p, v in zip(self.space, self.values, strict=True)
            if p.kind == "link" and v != 0.0
        }
        return self.nominal.perturbed(delta) if delta else self.nominal

    def _get(self, kind: str, field: str) -> float:
        s = self.structure
        name = s.base_name if kind == "base" else s.probe_name
        key = f"{field}{name}"
        return self.value(key) if key in self.space else 0.0

    def base_parameters(self) -> tuple[float, float, float, float, float, float]:
        """The BASE errors of eq. (6.24), relative to ``base_ref`` (0 when not a parameter).

        Returns
        -------
        (a0, b0, alpha0, beta0, theta0, d0) : tuple of float
            a0, b0, d0 in m; α0, β0, θ0 in rad.
        """
        g = self._get
        return (g("base", "a"), g("base", "b"), g("base", "alpha"), g("base", "beta"),
                g("base", "theta"), g("base", "d"))

    def probe_parameters(self) -> tuple[float, float, float, float]:
        """The errors of the virtual PROBE frame 7 (6.2.2), 0 when not a parameter.

        Returns
        -------
        (theta7, d7, a7, alpha7) : tuple of float
            θ7, α7 in rad; d7, a7 in m.
        """
        g = self._get
        return (g("probe", "theta"), g("probe", "d"), g("probe", "a"), g("probe", "alpha"))

    def base(self) -> Array:
        """BASE: the robot base frame in the measurement frame (eq. 6.24),
        ``BASE = BASE_ref · Tx(a0) Ty(b0) Rx(α0) Ry(β0) Rz(θ0) Tz(d0)``.

        Returns
        -------
        (4, 4) array, m
            BASE (:func:`base_transform` of :meth:`base_parameters`).
        """
        return base_transform(self.base_ref, *self.base_parameters())

    def probe(self) -> Array:
        """PROBE: the target in the flange frame of the identified chain (6.2.2),
        ``PROBE = Rx(−90°) · Rz(θ7) Tz(d7) Tx(a7) Rx(90° + α7) · PROBE_ref``.

        Returns
        -------
        (4, 4) array, m
            PROBE (:func:`probe_transform` of :meth:`probe_parameters`).
        """
        return probe_transform(self.probe_ref, *self.probe_parameters())

    # ------------------------------------------------------------------ prediction
    def batch(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
              temperature_c: ArrayLike | float | None = None) -> PoseBatch:
        """Readings with their compliance regressors ``R(q, m)`` (``Δθ = R c``, eqs. 6.31,
        6.40, 6.41) and temperatures, computed once for every prediction on them.

        Parameters
        ----------
        q : (N, n_readings) or (n_readings,) array_like, rad
            Joint readings (one vector is one pose).
        payload_kg : float or (N,) array_like, kg, optional
            Payload per pose or one for all (default 0).
        temperature_c : float or (N,) array_like, °C, optional
            Temperature per pose or one for all, for the thermal term (default: none,
            the reference temperature).

        Returns
        -------
        PoseBatch
            ``q`` ``(N, n_readings)``, ``payload_kg`` ``(N,)``, ``regressors``
            ``(N, n_actuated, len(compliance_keys))``, ``temperature_c`` ``(N,)`` or None.

        Raises
        ------
        ValueError
            ``q`` not of width ``n_readings``, or payloads/temperatures that do not
            broadcast to ``(N,)``.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        n = self.structure.n_readings
        if q.ndim != 2 or q.shape[1] != n:
            raise ValueError(f"q: expected shape (N, {n}), got {q.shape}")
        m = np.zeros(len(q)) if payload_kg is None else np.broadcast_to(
            np.asarray(payload_kg, dtype=float), (len(q),)).copy()
        params = [self.space[k] for k in self.compliance_keys]
        R = compliance_regressors(self.structure.source, self._reference, params, q, m,  # type: ignore[attr-defined]
                                  self.payload_ref_kg)
        t = None if temperature_c is None else np.broadcast_to(
            np.asarray(temperature_c, dtype=float), (len(q),)).copy()
        return PoseBatch(q=q, payload_kg=m, regressors=R, temperature_c=t)

    def thermal_scale(self, batch: PoseBatch) -> Array | None:
        """Scale ``s_i = 1 + κT·(T_i − T_ref)`` of the chain's lengths.

        Parameters
        ----------
        batch : PoseBatch
            The poses (their temperatures).

        Returns
        -------
        (N,) array or None
            s per pose (dimensionless; 1 for a batch without temperatures), ``None`` when
            the model has no thermal term.
        """
        if THERMAL_KEY not in self.space:
            return None
        return 1.0 + self.value(THERMAL_KEY) * batch.delta_t(self.temperature_ref_c)

    def deflections(self, batch: PoseBatch) -> Array:
        """Joint deflections of the kinematic joints, ``Δθ = R(q, m) · c`` (eqs. 4.16, 6.31,
        6.40) with c the current compliance values.

        Parameters
        ----------
        batch : PoseBatch
            The poses with their regressors R ``(N, n_actuated, n_c)``.

        Returns
        -------
        (N, n_actuated) array, rad
            Δθ (zeros without compliance parameters).
        """
        if not self.compliance_keys:
            return np.zeros(batch.regressors.shape[:2])
        c = self.values[self.space.indices(self.compliance_keys)]
        return batch.regressors @ c

    def chain_joints(self, batch: PoseBatch) -> Array:
        """Joint values of the structure's chain, ``q_desc = reading_map · (θ(q) + Δθ)``.

        θ(q) are the kinematic joints of the readings (``M·q + offset`` with a coupling),
        Δθ the :meth:`deflections`.

        Parameters
        ----------
        batch : PoseBatch
            The poses.

        Returns
        -------
        (N, n_desc) array, rad (m for prismatic)
            Joint values of the structure's description.
        """
        return self.structure.joints(batch.q, self.deflections(batch))

    def predict_batch(self, batch: PoseBatch) -> Array:
        """Predicted target poses in the measurement frame (eq. 6.23),
        ``T_i = BASE · S_i · T_n^0(q_desc,i; g) · PROBE``.

        T_n^0 is the flange of the structure's chain with geometry
        :meth:`geometric_parameters`, joints :meth:`chain_joints` and the passive angles
        from the exact four-bar closure; S_i scales the flange position by
        :meth:`thermal_scale` (identity without the thermal term).

        Parameters
        ----------
        batch : PoseBatch
            The poses (from :meth:`batch` of a model with the same parameter space).

        Returns
        -------
        (N, 4, 4) array, m
            Predicted target poses.

        Raises
        ------
        LoopClosureError
            A loop that cannot close at some pose.
        """
        fk = forward(self.structure.desc, self.geometric_parameters(), self.chain_joints(batch),
                     closure="fourbar")
        flange = fk.flange
        scale = self.thermal_scale(batch)
        if scale is not None:
            flange = flange.copy()
            flange[:, :3, 3] *= scale[:, None]
        return self.base() @ flange @ self.probe()

    def predict(self, q: ArrayLike, payload_kg: ArrayLike | float | None = None,
                temperature_c: ArrayLike | float | None = None) -> Array:
        """Predicted target poses for readings ``q`` (eq. 6.23),
        ``T(q, m) = BASE · T_n^0(θ(q) + Δθ(q, m)) · PROBE`` — at the temperatures
        ``temperature_c`` when the model has the thermal term.
        ``predict_batch(batch(q, payload_kg, temperature_c))``.

        Parameters
        ----------
        q : (N, n_readings) or (n_readings,) array_like, rad
            Joint readings.
        payload_kg : float or (N,) array_like, kg, optional
            Payloads (default 0).
        temperature_c : float or (N,) array_like, °C, optional
            Temperatures (default: the reference).

        Returns
        -------
        (N, 4, 4) array, m
            Predicted target poses in the measurement frame (N = 1 for one vector).

        Raises
        ------
        ValueError
            Malformed ``q``, payloads or temperatures.
        LoopClosureError
            A loop that cannot close at some pose.
        """
        return self.predict_batch(self.batch(q, payload_kg, temperature_c))


def fold_frames(model: ErrorModel) -> ErrorModel:
    """The same BASE·T·PROBE with every BASE, PROBE-frame and flange-link error folded
    into the references and set to zero (values of other parameters kept).

    The flange link's θ, d, a, α act after the last joint, so for any joint value
    ``DH(q + θ, d, a, α) = DH_nominal(q) · [DH_nominal(0)⁻¹ · DH(θ, d, a, α)]`` — a
    constant that belongs to the PROBE: ``PROBE_ref' = A_nom⁻¹ · A · PROBE``,
    ``BASE_ref' = BASE``.  Used after the nominal frames fit: the identification then
    starts from the nominal geometry with fitted BASE/PROBE.

    Parameters
    ----------
    model : ErrorModel
        The model.

    Returns
    -------
    ErrorModel
        The same prediction with zero BASE, PROBE and flange-link errors.
    """
    s = model.structure
    desc = s.desc
    fl = desc.flange
    nom = model.nominal
    i = desc.index(fl)
    g = model.geometric_parameters()
    A = dh_hayati(nom.theta[i], nom.d[i], nom.a[i], nom.alpha[i], nom.beta[i])
    B = dh_hayati(g.theta[i], g.d[i], g.a[i], g.alpha[i], g.beta[i])
    probe = np.linalg.solve(A, B) @ model.probe()
    v = np.array(model.values)
    for j, p in enumerate(model.space):
        if p.kind in ("base", "probe") or (p.kind == "link" and p.link == fl):
            v[j] = 0.0
    return ErrorModel(s, model.space, v, model.base(), probe, model.payload_ref_kg,
                      model.temperature_ref_c)
