"""Named error parameters: what a calibration model can identify, with units.

An :class:`ErrorParameter` is one scalar unknown of the error model (thesis
eq. 6.11): a geometric error of a link (Δθ, Δd, Δa, Δα, Δβ of eq. B.10), of the
BASE (Δa0, Δb0, Δα0, Δβ0, Δθ0, Δd0 of eq. 6.24), of the PROBE through the
virtual frame 7 (Δθ7, Δd7, Δa7, Δα7 of 6.2.2), a gravity-deflection constant
(G1–G3 of eq. 6.31), a payload-compliance constant (A, B, C, D of eq. 6.40) or
the amplitude of a joint-angle harmonic (transmission error, ``h1s_2`` …).

Every parameter has

* ``key`` — an ASCII name used in files and on the command line:
  ``theta2'``, ``a0``, ``d7``, ``G1``, ``A4``, ``B2'``;
* ``name`` — the thesis's symbol: ``Δθ2'``, ``Δa0``, ``G1``, ``A4``;
* ``unit`` — SI: ``m``, ``rad``, ``rad/m`` (A_i) or ``rad/(N·m)`` (joint compliance);
* ``priority`` — the order in which the identifiability analysis prefers to
  keep parameters when several explain the same pose error (see
  :mod:`plugcell.calibration.identifiability`).

A :class:`ParameterSpace` is an immutable, ordered collection of them.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

#: Kinds of error parameters.
KINDS: tuple[str, ...] = ("base", "link", "probe", "gravity", "payload", "harmonic", "thermal")

#: Greek symbols of the geometric fields (thesis notation).
SYMBOLS: dict[str, str] = {
    "theta": "θ",
    "d": "d",
    "a": "a",
    "b": "b",
    "alpha": "α",
    "beta": "β",
}

#: SI unit of each geometric field.
FIELD_UNITS: dict[str, str] = {
    "theta": "rad",
    "d": "m",
    "a": "m",
    "b": "m",
    "alpha": "rad",
    "beta": "rad",
}

__all__ = ["FIELD_UNITS", "KINDS", "SYMBOLS", "ErrorParameter", "ParameterSpace"]


@dataclass(frozen=True)
class ErrorParameter:
    """One identifiable-candidate unknown Δg_k of the error model (eq. 6.11, module docstring).

    Attributes
    ----------
    key : str
        ASCII name used in files and on the command line (``theta2'``, ``a0``, ``G1``).
    name : str
        The thesis's symbol (``Δθ2'``, ``Δa0``, ``G1``).
    kind : str
        One of :data:`KINDS`.
    unit : str
        SI unit of the value: ``m``, ``rad``, ``rad/m``, ``rad/(N·m)``, ``1/K``, … .
    link : str or None
        Link of a geometric parameter (the BASE's or the virtual PROBE frame's name
        for those kinds).
    field : str or None
        Geometric field (``theta``, ``d``, ``a``, ``b``, ``alpha``, ``beta``).
    joint : str or None
        The actuated joint whose deflection a compliance parameter scales.
    priority : (int, int, int)
        Sort key of the identifiability analysis (lower is kept first).

    Raises
    ------
    ValueError
        ``kind`` not one of :data:`KINDS`.
    """

    key: str
    name: str
    kind: str
    unit: str
    link: str | None = None
    field: str | None = None
    joint: str | None = None
    priority: tuple[int, int, int] = (0, 0, 0)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"ErrorParameter.kind must be one of {KINDS}, got {self.kind!r}")

    @property
    def is_geometric(self) -> bool:
        """True for BASE, link and PROBE parameters."""
        return self.kind in ("base", "link", "probe")

    @property
    def is_angle(self) -> bool:
        """True when the unit is rad."""
        return self.unit == "rad"

    @property
    def is_length(self) -> bool:
        """True when the unit is m."""
        return self.unit == "m"


def geometric_parameter(
    kind: str, link: str, field: str, priority: tuple[int, int, int]
) -> ErrorParameter:
    """A geometric error parameter ``Δ<field><link>`` (e.g. ``Δa2'``, key ``a2'``).

    Parameters
    ----------
    kind : str
        ``"base"``, ``"link"`` or ``"probe"``.
    link : str
        The link (or BASE/PROBE frame) name.
    field : str
        One of :data:`SYMBOLS` (``theta``, ``d``, ``a``, ``b``, ``alpha``, ``beta``).
    priority : (int, int, int)
        Identifiability priority.

    Returns
    -------
    ErrorParameter
        With the unit of the field (m or rad).
    """
    return ErrorParameter(
        key=f"{field}{link}",
        name=f"Δ{SYMBOLS[field]}{link}",
        kind=kind,
        unit=FIELD_UNITS[field],
        link=link,
        field=field,
        priority=priority,
    )


@dataclass(frozen=True, eq=False)
class ParameterSpace:
    """An ordered, immutable collection of :class:`ErrorParameter` with unique keys.

    The order is that of the parameter vector ``Δg`` (eq. 6.11).

    Attributes
    ----------
    parameters : tuple of ErrorParameter
        The parameters, in vector order.

    Raises
    ------
    ValueError
        Duplicate keys.
    """

    parameters: tuple[ErrorParameter, ...]

    def __post_init__(self) -> None:
        params = tuple(self.parameters)
        object.__setattr__(self, "parameters", params)
        keys = [p.key for p in params]
        if len(set(keys)) != len(keys):
            dup = sorted({k for k in keys if keys.count(k) > 1})
            raise ValueError(f"ParameterSpace: duplicate parameter keys {dup}")
        object.__setattr__(self, "_index", {k: i for i, k in enumerate(keys)})

    # ------------------------------------------------------------------ access
    def __len__(self) -> int:
        return len(self.parameters)

    def __iter__(self) -> Iterator[ErrorParameter]:
        return iter(self.parameters)

    def __getitem__(self, key: str | int) -> ErrorParameter:
        if isinstance(key, int):
            return self.parameters[key]
        return self.parameters[self.index(key)]

    def __contains__(self, key: object) -> bool:
        return key in self._index  # type: ignore[attr-defined]

    @property
    def keys(self) -> tuple[str, ...]:
        """Parameter keys, in vector order."""
        return tuple(p.key for p in self.parameters)

    @property
    def names(self) -> tuple[str, ...]:
        """Thesis symbols, in vector order."""
        return tuple(p.name for p in self.parameters)

    def index(self, key: str) -> int:
        """Position of parameter ``key`` in the vector Δg.

        Parameters
        ----------
        key : str
            A parameter key.

        Returns
        -------
        int
            Its index.

        Raises
        ------
        KeyError
            Unknown key (the message lists the known keys).
        """
        try:
            return self._index[key]  # type: ignore[attr-defined,no-any-return]
        except KeyError:
            raise KeyError(f"unknown error parameter {key!r}; known: {list(self.keys)}") from None

    def indices(self, keys: Iterable[str]) -> NDArray[np.intp]:
        """Positions of several parameters.

        Parameters
        ----------
        keys : iterable of str
            Parameter keys.

        Returns
        -------
        (len(keys),) int array
            Their indices, in the order given.

        Raises
        ------
        KeyError
            An unknown key.
        """
        return np.array([self.index(k) for k in keys], dtype=np.intp)

    def of_kind(self, *kinds: str) -> tuple[str, ...]:
        """Keys of the parameters of the given kinds, in space order.

        Parameters
        ----------
        *kinds : str
            Kinds from :data:`KINDS`.

        Returns
        -------
        tuple of str
            The matching keys.
        """
        return tuple(p.key for p in self.parameters if p.kind in kinds)

    def subset(self, keys: Sequence[str]) -> ParameterSpace:
        """The sub-space of the parameters ``keys`` (in that order).

        Parameters
        ----------
        keys : sequence of str
            Parameter keys.

        Returns
        -------
        ParameterSpace
            The subset.

        Raises
        ------
        KeyError
            An unknown key.
        """
        return ParameterSpace(tuple(self[k] for k in keys))

    def by_priority(self) -> tuple[str, ...]:
        """Keys sorted by :attr:`ErrorParameter.priority` (stable).

        Returns
        -------
        tuple of str
            All keys, highest priority (lowest tuple) first.
        """
        order = sorted(range(len(self)), key=lambda i: self.parameters[i].priority)
        return tuple(self.parameters[i].key for i in order)

    def zeros(self) -> Array:
        """A zero parameter vector ``Δg = 0``, shape ``(len(self),)``."""
        return np.zeros(len(self))
