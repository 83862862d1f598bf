"""A workspace of named values, one per requester (the Matlab workspace of thesis 7.3).

The robot "delegates complex numerical computations to Matlab" by setting matrices
into its workspace (Set Matrix), evaluating functions on them (Evaluate) and reading
results back (Get Matrix).  Here each requester — each robot — has its own
workspace, so two robots calling their measurements ``mT`` never mix them.

Values are real matrices (float64, 2-D; a number is 1×1, a vector one row) or
opaque results of registered functions (e.g. identified parameters), which can be
passed to functions but not read with Get Matrix.  A workspace holds at most
``max_elements`` matrix elements in all.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from plugcell.devices.compute.expr import MAX_NAME, Scope

NAME = re.compile(rf"^[A-Za-z][A-Za-z0-9_]{{0,{MAX_NAME - 1}}}$")
DEFAULT_MAX_ELEMENTS = 8_000_000  # 64 MB of float64 per requester
MAX_VALUES = 1000

__all__ = ["DEFAULT_MAX_ELEMENTS", "Workspace", "WorkspaceError", "as_matrix", "check_name"]


class WorkspaceError(ValueError):
    """A refused workspace operation; the message is the precise reason."""


def check_name(name: str) -> str:
    """A workspace name: a letter, then letters, digits, ``_`` (at most 63)."""
    if not NAME.match(name):
        raise WorkspaceError(
            f"bad matrix name {name!r}: a letter, then letters, digits or '_' "
            f"(at most {MAX_NAME} characters)"
        )
    return name


def as_matrix(value: Any, what: str = "value") -> np.ndarray:
    """A real 2-D float64 matrix from a number, vector (one row) or matrix."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        raise WorkspaceError(f"{what}: a real matrix expected, got {arr.dtype} values")
    arr = np.array(arr, dtype=float)
    if arr.ndim == 0:
        arr = arr.reshape(1, 1)
    elif arr.ndim == 1:
        arr = arr.reshape(1, -1)
    elif arr.ndim != 2:
        raise WorkspaceError(f"{what}: a matrix has 2 dimensions, got {arr.ndim}")
    if not np.all(np.isfinite(arr)):
        raise WorkspaceError(f"{what}: values must be finite")
    return arr


def kind_of(value: Any) -> str:
    """How a value is described to people."""
    if isinstance(value, np.ndarray):
        return f"a {value.shape[0]}×{value.shape[1]} matrix"
    return getattr(value, "kind", type(value).__name__)


class Workspace(Scope):
    """The named values of one requester (module docstring)."""

    def __init__(self, owner: str, max_elements: int = DEFAULT_MAX_ELEMENTS) -> None:
        self.owner = owner
        self.max_elements = max_elements
        self._values: dict[str, Any] = {}

    def __contains__(self, name: str) -> bool:
        return name in self._values

    def names(self) -> list[str]:
        return sorted(self._values)

    def elements(self) -> int:
        """Matrix elements held."""
        return sum(v.size for v in self._values.values() if isinstance(v, np.ndarray))

    def get(self, name: str) -> Any:
        try:
            return self._values[name]
        except KeyError:
            raise WorkspaceError(f"{name!r} is not defined in the workspace of {self.owner}"
                                 ) from None

    def matrix(self, name: str) -> np.ndarray:
        """A value that must be a matrix (Get Matrix)."""
        value = self.get(check_name(name))
        if not isinstance(value, np.ndarray):
            raise WorkspaceError(f"{name} is {kind_of(value)}, not a matrix")
        return value

    def set(self, name: str, value: Any) -> None:
        """Store ``value`` under ``name`` (a matrix is copied and made read-only)."""
        check_name(name)
        if isinstance(value, str):
            raise WorkspaceError(f"{name}: a string cannot be stored in the workspace")
        if isinstance(value, float | int | np.ndarray | list | tuple):
            value = as_matrix(value, name)
            value.setflags(write=False)
            self._check_room(name, value.size)
        elif name not in self._values and len(self._values) >= MAX_VALUES:
            raise WorkspaceError(f"workspace of {self.owner} holds {MAX_VALUES} values already")
        self._values[name] = value

    def append(self, name: str, rows: Any) -> np.ndarray:
        """Append ``rows`` (a vector is one row) to the matrix ``name`` (created if absent)."""
        check_name(name)
        new = as_matrix(rows, name)
        old = self._values.get(name)
        if old is None:
            self.set(name, new)
            return self._values[name]
        if not isinstance(old, np.ndarray):
            raise WorkspaceError(f"cannot append to {name}: it is {kind_of(old)}")
        if old.size and old.shape[1] != new.shape[1]:
            raise WorkspaceError(
                f"cannot append {new.shape[1]} columns to {name}, which has {old.shape[1]}"
            )
        self.set(name, np.vstack([old, new]) if old.size else new)
        return self._values[name]

    def clear(self, names: list[str] | None = None) -> list[str]:
        """Remove the given names (all if None); returns what was removed.  A name
        that is not there is not an error (a program clears before it starts), but
        it must be a valid name."""
        if names is None:
            gone = self.names()
            self._values.clear()
            return gone
        for n in names:
            check_name(n)
        return [n for n in names if self._values.pop(n, None) is not None]

    def snapshot(self) -> dict[str, Any]:
        """The values by name (a new dict; matrices are read-only, so shared)."""
        return dict(self._values)

    def restore(self, values: dict[str, Any]) -> None:
        """Hold exactly ``values`` (a :meth:`snapshot`, e.g. of a copy of this workspace
        an engine evaluated in another process), each checked as :meth:`set` checks it."""
        self._values.clear()
        for name, value in values.items():
            self.set(name, value)

    def _check_room(self, name: str, size: int) -> None:
        old = self._values.get(name)
        freed = old.size if isinstance(old, np.ndarray) else 0
        total = self.elements() - freed + size
        if total > self.max_elements:
            raise WorkspaceError(
                f"workspace of {self.owner} would hold {total} elements, more than its "
                f"limit of {self.max_elements}"
            )
        if name not in self._values and len(self._values) >= MAX_VALUES:
            raise WorkspaceError(f"workspace of {self.owner} holds {MAX_VALUES} values already")
