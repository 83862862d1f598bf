"""Geometric parameter sets: the numbers forward kinematics actually uses.

A :class:`GeometricParameters` is immutable (Pinocchio's *Model* side): one DH +
Hayati row ``(θ, d, a, α, β)`` per link, in description order, plus the BASE and
tool transforms.  The nominal set comes from
:meth:`plugcell.kinematics.description.RobotDescription.nominal_parameters`;
calibration and the digital twin derive perturbed sets with :meth:`perturbed` or
:meth:`replace`.  Forward kinematics reads *only* these numbers (never the
description's), so every entry — loop links and Hayati β included — acts on FK.

Meaning of ``theta`` per joint type: actuated — offset added to the joint
reading; passive — offset added to the loop-closure angle (nominally 0, see
docs/kinematics.md); fixed — the constant joint angle.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

#: Per-link parameter fields, in the order of thesis eq. (B.10): Δg_i = (Δθ, Δd, Δa, Δα, Δβ).
FIELDS: tuple[str, ...] = ("theta", "d", "a", "alpha", "beta")

__all__ = ["FIELDS", "GeometricParameters"]


def _frozen(x: ArrayLike, shape: tuple[int, ...], name: str) -> Array:
    arr = np.array(x, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"GeometricParameters.{name}: expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"GeometricParameters.{name}: values must be finite")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class GeometricParameters:
    """DH + Hayati parameters of every link (SI: metres, radians) and BASE/tool.

    Link *i* contributes ``A_i = Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i) Ry(β_i)`` (eq. B.1)
    and the world TCP is ``base · T_flange · tool`` (eq. 6.23 with PROBE = tool).
    All arrays are read-only copies, validated (shape, finite) on construction.

    Attributes
    ----------
    link_names : tuple of str
        Link names in description order (unique).
    theta : (n_links,) array, rad
        DH angle offsets θ (see the module docstring for their meaning per joint type).
    d : (n_links,) array, m
        DH offsets along z.
    a : (n_links,) array, m
        DH link lengths along x.
    alpha : (n_links,) array, rad
        DH twists α about x.
    beta : (n_links,) array, rad
        Hayati twists β about y (0 for a plain DH row).
    base : (4, 4) array, m
        The robot base frame in the world/metrology frame (thesis BASE of eq. 6.23).
    tool : (4, 4) array, m
        The TCP (or PROBE) in the flange frame.

    Raises
    ------
    ValueError
        Duplicate link names, an array of the wrong shape or non-finite values.
    """

    link_names: tuple[str, ...]
    theta: Array
    d: Array
    a: Array
    alpha: Array
    beta: Array
    base: Array = field(default_factory=lambda: np.eye(4))
    tool: Array = field(default_factory=lambda: np.eye(4))

    def __post_init__(self) -> None:
        names = tuple(self.link_names)
        if len(set(names)) != len(names):
            raise ValueError("GeometricParameters.link_names: names must be unique")
        object.__setattr__(self, "link_names", names)
        n = len(names)
        for f in FIELDS:
            object.__setattr__(self, f, _frozen(getattr(self, f), (n,), f))
        object.__setattr__(self, "base", _frozen(self.base, (4, 4), "base"))
        object.__setattr__(self, "tool", _frozen(self.tool, (4, 4), "tool"))

    # ------------------------------------------------------------------ access
    @property
    def n_links(self) -> int:
        """Number of links ``n_links``."""
        return len(self.link_names)

    def index(self, link: str) -> int:
        """Position of ``link`` in the parameter arrays.

        Parameters
        ----------
        link : str
            A link name.

        Returns
        -------
        int
            Its index ``i`` in ``theta``, ``d``, … .

        Raises
        ------
        KeyError
            Unknown link.
        """
        try:
            return self.link_names.index(link)
        except ValueError:
            raise KeyError(f"unknown link {link!r}; links are {list(self.link_names)}") from None

    def get(self, link: str, field_name: str) -> float:
        """One parameter value, e.g. ``params.get("2'", "beta")``.

        Parameters
        ----------
        link : str
            A link name.
        field_name : str
            One of :data:`FIELDS` (``theta``, ``d``, ``a``, ``alpha``, ``beta``).

        Returns
        -------
        float
            The value, m or rad according to the field.

        Raises
        ------
        KeyError
            Unknown link or field.
        """
        if field_name not in FIELDS:
            raise KeyError(f"unknown parameter field {field_name!r}; expected one of {FIELDS}")
        return float(getattr(self, field_name)[self.index(link)])

    def table(self) -> Array:
        """The DH + Hayati table, one row ``(θ_i, d_i, a_i, α_i, β_i)`` per link.

        Returns
        -------
        (n_links, 5) array
            Columns θ (rad), d (m), a (m), α (rad), β (rad).
        """
        return np.stack([getattr(self, f) for f in FIELDS], axis=-1)

    # ------------------------------------------------------------------ derive
    def replace(self, **changes: Any) -> GeometricParameters:
        """A copy with some attributes replaced (``theta=..., base=...``).

        Parameters
        ----------
        **changes
            New values for any of ``theta, d, a, alpha, beta`` (``(n_links,)``, m/rad)
            and ``base, tool`` (``(4, 4)``, m).

        Returns
        -------
        GeometricParameters
            The new, validated set (same link names).

        Raises
        ------
        TypeError
            A keyword that is not one of those fields.
        """
        allowed = {*FIELDS, "base", "tool"}
        bad = set(changes) - allowed
        if bad:
            raise TypeError(f"replace(): unknown field(s) {sorted(bad)}; allowed {sorted(allowed)}")
        kw: dict[str, Any] = {f: getattr(self, f) for f in (*FIELDS, "base", "tool")}
        kw.update(changes)
        return GeometricParameters(self.link_names, **kw)

    def perturbed(self, delta: Mapping[tuple[str, str], float]) -> GeometricParameters:
        """A copy with ``delta[(link, field)]`` *added* to each named parameter.

        ``g'_{link, field} = g_{link, field} + δ``, e.g.
        ``params.perturbed({("2'", "a"): 1e-3, ("3'", "beta"): 2e-4})``.

        Parameters
        ----------
        delta : mapping of (str, str) to float
            ``(link, field) → δ``, m or rad according to the field.

        Returns
        -------
        GeometricParameters
            The perturbed set (BASE and tool unchanged).

        Raises
        ------
        KeyError
            A key that is not a ``(link, field)`` pair, or an unknown link or field.
        """
        arrays = {f: np.array(getattr(self, f)) for f in FIELDS}
        for key, value in delta.items():
            if not (isinstance(key, tuple) and len(key) == 2):
                raise KeyError(f"perturbed(): keys are (link_name, field) pairs, got {key!r}")
            link, f = key
            if f not in FIELDS:
                raise KeyError(f"perturbed(): unknown field {f!r}; expected one of {FIELDS}")
            arrays[f][self.index(link)] += float(value)
        return self.replace(**arrays)

    # ------------------------------------------------------------------ vector form
    def labels(self) -> list[tuple[str, str]]:
        """``(link, field)`` labels of :meth:`to_vector`, field-major (all θ, then all d, …).

        Returns
        -------
        list of (str, str)
            ``5 · n_links`` labels.
        """
        return [(n, f) for f in FIELDS for n in self.link_names]

    def to_vector(self) -> Array:
        """All link parameters as one vector, ``g = (θ_1..θ_n, d_1..d_n, a, α, β)``.

        Returns
        -------
        (5 · n_links,) array
            Field-major (see :meth:`labels`), m or rad per entry.
        """
        return np.concatenate([getattr(self, f) for f in FIELDS])

    def with_vector(self, x: ArrayLike) -> GeometricParameters:
        """Inverse of :meth:`to_vector` (BASE and tool unchanged).

        Parameters
        ----------
        x : (5 · n_links,) array_like
            Field-major parameter vector, m or rad per entry.

        Returns
        -------
        GeometricParameters
            A copy with these link parameters.

        Raises
        ------
        ValueError
            Wrong shape.
        """
        x = np.asarray(x, dtype=float)
        n = self.n_links
        if x.shape != (len(FIELDS) * n,):
            raise ValueError(f"with_vector(): expected shape ({len(FIELDS) * n},), got {x.shape}")
        return self.replace(**{f: x[k * n : (k + 1) * n] for k, f in enumerate(FIELDS)})

    def __repr__(self) -> str:
        rows = ", ".join(
            f"{n}: θ={t:.6g} d={d:.6g} a={a:.6g} α={al:.6g} β={b:.6g}"
            for n, t, d, a, al, b in zip(
                self.link_names, self.theta, self.d, self.a, self.alpha, self.beta, strict=True
            )
        )
        return f"GeometricParameters({rows})"
