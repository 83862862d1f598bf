"""The kinematic models compensation inverts: tool pose and Jacobian in the robot base frame.

What is compensated (a decision, stated once): **the pose of the tool point in the
robot base frame F0**.  By default the tool point is the reflector the tracker
measures — the T-MAC — i.e. the tool is the identified PROBE, exactly as in thesis
8.3 where the laser tracker measures the T-MAC and the residuals of Table 8-5 are
T-MAC pose errors.  Another TCP (a drill tip, a gripper) can be given as ``tool``
(flange → TCP); the measurements of the sensor loop are then carried to it through
PROBE (``frames.MetrologyFrames``).

Two models share the :class:`PoseModel` protocol:

* :class:`IdentifiedModel` — an identified :class:`~plugcell.calibration.model.ErrorModel`
  (geometry, parallelogram loop, gravity and payload deflection, eqs. 6.23, 6.31,
  6.40).  Its prediction is ``BASE · T_n^0(q + Δq(q, m)) · PROBE`` (tracker frame);
  in the robot base frame the tool pose is ``T_n^0(q + Δq(q, m)) · tool``, which is
  ``BASE⁻¹ · predict(q, m) · PROBE⁻¹ · tool`` — the same numbers (tested).
* :class:`NominalModel` — the controller's own nominal model (description
  parameters, eq. 6.1) with a tool: what ``POS_TO_JNTP`` inverts.

``jacobian`` is the manipulator Jacobian at the tool point, thesis eqs. (6.37),
(6.39) — loop joints through the exact four-bar closure — with the identified
geometry, in the robot base frame, per unit change of the joint *readings*
(for a model on the serial structure of eq. 6.3 the chain joints are a linear map
of the readings).  The derivative of the deflection Δq(q) with respect to q (of
order 10⁻³ of the identity) is left out: the Newton iteration of 6.5.1 then
converges linearly with a ratio ~10⁻³ instead of quadratically — two or three
iterations to 10⁻⁶ either way.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.calibration.model import ErrorModel
from plugcell.kinematics import (
    GeometricParameters,
    RobotDescription,
    forward,
    jacobian_from_fk,
)
from plugcell.kinematics.transforms import cross, invert, so3_exp

Array = NDArray[np.float64]

__all__ = ["IdentifiedModel", "NominalModel", "PoseModel", "shift_jacobian"]


@runtime_checkable
class PoseModel(Protocol):
    """A kinematic model compensation can invert (module docstring).

    ``description``: the robot as its controller knows it (joint order, limits,
    nominal geometry); ``tool``: the compensated point in the flange frame;
    ``evaluate(q, payload_kg)`` → tool poses ``(N, 4, 4)`` in the robot base frame
    and the Jacobian ``(N, 6, n)`` with respect to the joint readings.
    """

    @property
    def description(self) -> RobotDescription:
        """The robot as its controller knows it: joint reading order, limits, nominal
        geometry (the seed of the nominal inverse kinematics)."""
        ...

    @property
    def tool(self) -> Array:
        """``(4, 4)`` m: the compensated point (TCP) in the flange frame."""
        ...

    def evaluate(self, q: ArrayLike, payload_kg: ArrayLike | float = 0.0) -> tuple[Array, Array]:
        """Tool poses and the manipulator Jacobian at the tool point, the two things the
        compensation's Newton step ``q ← q + J⁻¹ e(T_target, T(q))`` (eq. 4.11) needs.

        Parameters
        ----------
        q : (N, n_readings) or (n_readings,) array_like, rad (m for prismatic)
            Joint readings.
        payload_kg : float or (N,) array_like, kg
            Payload per pose or one for all (a model may ignore it).

        Returns
        -------
        T : (N, 4, 4) array, m
            Tool poses ``T(q, m)`` in the robot base frame.
        J : (N, 6, n_readings) array
            ``∂[p; φ]/∂q`` at the tool point, robot base frame: linear rows (m/rad) over
            angular rows (rad/rad).

        Raises
        ------
        ValueError
            ``q`` of the wrong shape or not finite.
        """
        ...


def shift_jacobian(J_flange: Array, p_flange: Array, p_tool: Array) -> Array:
    """Move the linear rows of a Jacobian from the flange origin to the tool point.

    ``v_tool = v_flange + ω × (p_tool − p_flange)`` (rigid body), so
    ``J_v,tool = J_v,flange − [p_tool − p_flange]× J_ω``; the angular rows are unchanged.

    Parameters
    ----------
    J_flange : (N, 6, n) array
        Jacobian at the flange origin, linear rows (m/rad) over angular rows (rad/rad).
    p_flange : (N, 3) array, m
        Flange origins.
    p_tool : (N, 3) array, m
        Tool points, same frame.

    Returns
    -------
    (N, 6, n) array
        The Jacobian at the tool point.
    """
    r = p_tool - p_flange  # (N, 3)
    Jw = J_flange[..., 3:, :]
    Jv = J_flange[..., :3, :] + cross(Jw, r[..., :, None], axis=-2)
    return np.concatenate([Jv, Jw], axis=-2)


def _as_batch(q: ArrayLike, n: int) -> Array:
    q = np.asarray(q, dtype=float)
    if q.ndim == 1:
        q = q[None, :]
    if q.ndim != 2 or q.shape[1] != n:
        raise ValueError(f"q: expected shape (N, {n}) joint readings, got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("q: joint readings must be finite")
    return q


@dataclass(frozen=True, eq=False)
class IdentifiedModel:
    """An identified error model as a :class:`PoseModel` (module docstring).

    Tool pose in the robot base frame ``T = T_n^0(θ(q) + Δθ(q, m)) · tool`` (6.23 without
    BASE), with the learned correction ``T ← G · T`` when a residual layer is set.

    Attributes
    ----------
    error_model : ErrorModel
        The identified model (e.g. ``CalibrationResult.model``).
    tool : (4, 4) array, m
        The compensated point in the flange frame of the identified chain, default the
        identified PROBE (the T-MAC).
    residual : LearnedResidual or None
        A learned residual layer (:mod:`~plugcell.calibration.residual_model`) on top —
        the hybrid model: its base-frame correction ``(e, φ)`` of the PROBE point is
        applied to the tool as the rigid motion
        ``G = Trans(p_probe + e) · Rot(Exp φ) · Trans(−p_probe)`` (``T ← G·T``: the PROBE
        point moves by ``e``, every orientation turns by φ), where the pose is inside the
        layer's trained region (elsewhere the physical model alone); the Jacobian stays
        the physical one (the boosted trees are piecewise constant —
        :func:`~plugcell.compensation.model_based.compensate_joints` solves the hybrid
        model by an outer fixed point on ``G``).
    temperature_c : float or None, °C
        The cell's temperature — for a layer that uses it, and for a model with the
        thermal term κT (the flange position and the linear rows of its Jacobian scale
        by ``1 + κT (T − T_ref)``); ``None``: the model's reference temperature.

    Raises
    ------
    ValueError
        ``tool`` not a finite 4×4 matrix.
    """

    error_model: ErrorModel
    tool: Array = field(default=None)  # type: ignore[assignment]
    residual: Any = None
    temperature_c: float | None = None

    def __post_init__(self) -> None:
        em = self.error_model
        tool = em.probe() if self.tool is None else np.array(self.tool, dtype=float)
        if tool.shape != (4, 4) or not np.all(np.isfinite(tool)):
            raise ValueError(f"tool: expected a finite 4x4 transform, got shape {tool.shape}")
        tool.setflags(write=False)
        object.__setattr__(self, "tool", tool)
        object.__setattr__(self, "_params", em.geometric_parameters())
        base = em.base()
        base.setflags(write=False)
        probe = em.probe()
        probe.setflags(write=False)
        object.__setattr__(self, "_base", base)
        object.__setattr__(self, "_probe", probe)

    @property
    def description(self) -> RobotDescription:
        """The robot as described (joint readings are in its reading order)."""
        return self.error_model.structure.source

    @property
    def base(self) -> Array:
        """Identified BASE: the robot base frame in the measurement (tracker) frame."""
        return self._base  # type: ignore[attr-defined,no-any-return]

    @property
    def probe(self) -> Array:
        """Identified PROBE: the reflector in the flange frame."""
        return self._probe  # type: ignore[attr-defined,no-any-return]

    def evaluate(self, q: ArrayLike, payload_kg: ArrayLike | float = 0.0) -> tuple[Array, Array]:
        """Tool poses and the manipulator Jacobian at the tool (eqs. 6.23, 6.37, 6.39).

        ``T = G · T_n^0(θ(q) + Δθ(q, m)) · tool``; ``J = shift(J_flange) · ∂q_chain/∂q``
        (deflection derivative left out, module docstring).

        Parameters
        ----------
        q : (N, n) or (n,) array_like, rad
            Joint readings.
        payload_kg : float or (N,) array_like, kg
            Payloads.

        Returns
        -------
        T : (N, 4, 4) array, m
            Tool poses in the robot base frame.
        J : (N, 6, n) array
            ``∂[p; φ]/∂q`` w.r.t. the readings (m/rad over rad/rad), robot base frame.

        Raises
        ------
        ValueError
            ``q`` of the wrong shape or not finite.
        """
        T, J = self._evaluate(q, payload_kg, True)
        assert J is not None
        return T, J

    def _evaluate(self, q: ArrayLike, payload_kg: ArrayLike | float, jacobian: bool
                  ) -> tuple[Array, Array | None]:
        """:meth:`evaluate`, the Jacobian only if asked (``None`` else: :meth:`pose`)."""
        em = self.error_model
        qb = _as_batch(q, em.structure.n_readings)
        batch = em.batch(qb, payload_kg)
        s = em.structure
        fk = forward(s.desc, self._params, em.chain_joints(batch), closure="fourbar")  # type: ignore[attr-defined]
        flange = fk.flange
        J = jacobian_from_fk(s.desc, fk, "flange") if jacobian else None
        scale = em.thermal_scale(em.batch(qb, payload_kg, self.temperature_c)) \
            if self.temperature_c is not None else None
        if scale is not None:  # thermal term: the flange position scales, so do its rates
            flange = flange.copy()
            flange[:, :3, 3] *= scale[:, None]
            if J is not None:
                J = J.copy()
                J[:, :3] *= scale[:, None, None]
        T = flange @ self.tool
        if J is not None:
            J = shift_jacobian(J, flange[:, :3, 3], T[:, :3, 3]) @ s.reading_jacobian
        if self.residual is not None:
            T = self._correction(flange @ self._probe, qb, batch.payload_kg) @ T  # type: ignore[attr-defined]
        return T, J

    def _correction(self, T_probe: Array, q: Array, payload_kg: Array) -> Array:
        """``G`` ``(N, 4, 4)`` (class docstring) at the PROBE poses ``T_probe``."""
        c = self.residual.predict(q, payload_kg, self.temperature_c).correction
        R = so3_exp(c[:, 3:])
        p = T_probe[:, :3, 3]
        G = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
        G[:, :3, :3] = R
        G[:, :3, 3] = p + c[:, :3] - np.einsum("nij,nj->ni", R, p)
        return G

    def physical(self) -> IdentifiedModel:
        """The same model without the learned layer.

        Returns
        -------
        IdentifiedModel
            ``residual = None``.
        """
        return IdentifiedModel(self.error_model, self.tool, None, self.temperature_c)

    def correction(self, q: ArrayLike, payload_kg: ArrayLike | float = 0.0) -> Array:
        """The learned layer's rigid correction ``G`` at ``q``: hybrid pose = ``G ·`` physical.

        Parameters
        ----------
        q : (N, n) or (n,) array_like, rad
            Joint readings.
        payload_kg : float or (N,) array_like, kg
            Payloads.

        Returns
        -------
        G : (N, 4, 4) array, m
            Identity without a layer or outside its trained region.
        """
        qb = _as_batch(q, self.error_model.structure.n_readings)
        if self.residual is None:
            return np.broadcast_to(np.eye(4), (len(qb), 4, 4)).copy()
        phys = self.physical().evaluate(qb, payload_kg)[0]
        T_probe = phys @ invert(self.tool) @ self._probe  # type: ignore[attr-defined]
        m = np.broadcast_to(np.asarray(payload_kg, float), (len(qb),))
        return self._correction(T_probe, qb, m)

    def in_domain(self, q: ArrayLike, payload_kg: ArrayLike | float = 0.0) -> Array:
        """Where the learned layer applies.

        Parameters
        ----------
        q : (N, n) or (n,) array_like, rad
            Joint readings.
        payload_kg : float or (N,) array_like, kg
            Payloads.

        Returns
        -------
        (N,) bool array
            True inside the layer's trained region (all True without a layer).
        """
        qb = _as_batch(q, self.error_model.structure.n_readings)
        if self.residual is None:
            return np.ones(len(qb), dtype=bool)
        m = np.broadcast_to(np.asarray(payload_kg, float), (len(qb),))
        return np.asarray(self.residual.predict(qb, m, self.temperature_c).in_domain)

    def pose(self, q: ArrayLike, payload_kg: ArrayLike | float = 0.0) -> Array:
        """Tool poses in the robot base frame (the first output of :meth:`evaluate`).

        Parameters
        ----------
        q : (N, n) or (n,) array_like, rad
            Joint readings.
        payload_kg : float or (N,) array_like, kg
            Payloads.

        Returns
        -------
        (N, 4, 4) array, m
            Tool poses (computed without the Jacobian).
        """
        return self._evaluate(q, payload_kg, False)[0]

    def predict_measurement(self, q: ArrayLike, payload_kg: ArrayLike | float = 0.0) -> Array:
        """The reflector pose the tracker should read, ``BASE · T_n^0 · PROBE`` (eq. 6.23).

        Computed as ``BASE · T · tool⁻¹ · PROBE`` from the tool pose ``T`` (with the learned
        correction when a layer is set).

        Parameters
        ----------
        q : (N, n) or (n,) array_like, rad
            Joint readings.
        payload_kg : float or (N,) array_like, kg
            Payloads.

        Returns
        -------
        (N, 4, 4) array, m
            Reflector poses in the measurement frame.
        """
        T = self.pose(q, payload_kg)
        return self.base @ T @ invert(self.tool) @ self.probe


@dataclass(frozen=True, eq=False)
class NominalModel:
    """The controller's nominal model (description parameters) with a tool, as a
    :class:`PoseModel`.  Payload and deflections are ignored, as a controller does.

    ``T = T_n^0(q) · tool`` (eq. 6.1, exact four-bar closure).

    Attributes
    ----------
    desc : RobotDescription
        The robot.
    tool : (4, 4) array, m
        The TCP in the flange frame (default identity).
    params : GeometricParameters
        Geometry used (default the description's nominal one; its tool is set to ``tool``).

    Raises
    ------
    ValueError
        ``tool`` not a finite 4×4 matrix.
    """

    desc: RobotDescription
    tool: Array = field(default=None)  # type: ignore[assignment]
    params: GeometricParameters | None = None

    def __post_init__(self) -> None:
        tool = np.eye(4) if self.tool is None else np.array(self.tool, dtype=float)
        if tool.shape != (4, 4) or not np.all(np.isfinite(tool)):
            raise ValueError(f"tool: expected a finite 4x4 transform, got shape {tool.shape}")
        tool.setflags(write=False)
        object.__setattr__(self, "tool", tool)
        p = self.desc.nominal_parameters() if self.params is None else self.params
        object.__setattr__(self, "params", p.replace(tool=tool))

    @property
    def description(self) -> RobotDescription:
        """The robot."""
        return self.desc

    def evaluate(self, q: ArrayLike, payload_kg: ArrayLike | float = 0.0) -> tuple[Array, Array]:
        """Tool poses and the manipulator Jacobian at the TCP (eqs. 6.1, 6.37).

        Parameters
        ----------
        q : (N, n) or (n,) array_like, rad
            Joint readings.
        payload_kg : float or (N,) array_like
            Ignored.

        Returns
        -------
        T : (N, 4, 4) array, m
            Tool poses in the robot base frame.
        J : (N, 6, n) array
            Jacobian at the TCP w.r.t. the readings (m/rad over rad/rad).

        Raises
        ------
        ValueError
            ``q`` of the wrong shape or not finite.
        """
        qb = _as_batch(q, self.desc.n_readings)
        fk = forward(self.desc, self.params, qb)
        return fk.tcp, jacobian_from_fk(self.desc, fk, "tcp")

    def pose(self, q: ArrayLike, payload_kg: ArrayLike | float = 0.0) -> Array:
        """Tool poses in the robot base frame, ``T = T_n^0(q) · tool`` (eq. 6.1): the first
        result of :meth:`evaluate`.

        Parameters
        ----------
        q : (N, n_readings) or (n_readings,) array_like, rad (m for prismatic)
            Joint readings.
        payload_kg : float or (N,) array_like
            Ignored (a controller's nominal model has no deflections).

        Returns
        -------
        (N, 4, 4) array, m
            Tool poses.

        Raises
        ------
        ValueError
            ``q`` of the wrong shape or not finite.
        """
        return forward(self.desc, self.params, _as_batch(q, self.desc.n_readings)).tcp
