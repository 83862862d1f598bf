"""Typed reads of a JSON document's keys, and strict JSON values: what every reader of
plugcell's JSON files shares (PARAMS.json, :mod:`plugcell.io.params`; the learned
correction of a path, :mod:`plugcell.io.learned_paths`).

A reader asks for ``document[path[0]][path[1]]…`` as the type it needs; a key that is
missing, a container that is not an object or a value of the wrong type raises
:class:`DocumentError` (a ``ValueError``) whose message names the dotted key and what
was found there, e.g. ``"model.harmonics: expected an integer, got the string '2'"``.
:func:`strict` makes a value writable as strict JSON (RFC 8259 has no NaN or infinity).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["DocumentError", "at", "finite", "flag", "integer", "number", "numbers",
           "strict", "string", "typename"]


class DocumentError(ValueError):
    """A JSON document that cannot be used; the message names the key."""


def typename(x: Any) -> str:
    """What a JSON value is, for an error message.

    Parameters
    ----------
    x : Any
        A value of a parsed JSON document.

    Returns
    -------
    str
        ``null``, ``a boolean``, ``the number 3``, ``the string 'a'``, ``a list``,
        ``an object``, or the Python type's name for anything else.
    """
    if x is None:
        return "null"
    if isinstance(x, bool):
        return "a boolean"
    if isinstance(x, int | float):
        return f"the number {x!r}"
    if isinstance(x, str):
        return f"the string {x!r}"
    if isinstance(x, list):
        return "a list"
    if isinstance(x, dict):
        return "an object"
    return type(x).__name__


def at(document: dict[str, Any], *path: str, default: Any = KeyError) -> Any:
    """``document[path[0]][path[1]]…``.

    Parameters
    ----------
    document : dict
        A parsed JSON object.
    *path : str
        The keys, outermost first.
    default : Any, optional
        What a missing key gives (without it, a missing key is an error).

    Returns
    -------
    Any
        The value at ``path``.

    Raises
    ------
    DocumentError
        ``"missing key 'a.b'"``, or ``"a: expected an object, got a list"`` when a
        container on the path is not an object.
    """
    x: Any = document
    for i, key in enumerate(path):
        if not isinstance(x, dict):
            raise DocumentError(f"{'.'.join(path[:i])}: expected an object, got {typename(x)}")
        if key not in x:
            if default is not KeyError:
                return default
            raise DocumentError(f"missing key {'.'.join(path[:i + 1])!r}")
        x = x[key]
    return x


def finite(x: Any, label: str) -> float:
    """A JSON number as a finite float.

    Parameters
    ----------
    x : Any
        The value (a boolean is not a number).
    label : str
        Its name in the message, e.g. ``"offset.u_mm[3][1]"``.

    Returns
    -------
    float
        ``float(x)``.

    Raises
    ------
    DocumentError
        ``x`` is not an int or float, or is NaN, infinite, or an integer beyond float.
    """
    try:
        f = float("nan") if isinstance(x, bool) or not isinstance(x, int | float) else float(x)
    except OverflowError:  # an integer beyond float
        f = float("inf")
    if not math.isfinite(f):
        raise DocumentError(f"{label}: expected a finite number, got {typename(x)}")
    return f


def number(document: dict[str, Any], *path: str, default: Any = KeyError) -> float:
    """The finite number at ``path`` (:func:`at`, :func:`finite`).

    Parameters
    ----------
    document : dict
        A parsed JSON object.
    *path : str
        The keys, outermost first.
    default : Any, optional
        What a missing key gives (checked like a value).

    Returns
    -------
    float
        The number.

    Raises
    ------
    DocumentError
        Missing key, or not a finite number (the message names the dotted key).
    """
    return finite(at(document, *path, default=default), ".".join(path))


def integer(document: dict[str, Any], *path: str, default: Any = KeyError) -> int:
    """The integer at ``path`` (a boolean or a float is not one).

    Parameters
    ----------
    document : dict
        A parsed JSON object.
    *path : str
        The keys, outermost first.
    default : Any, optional
        What a missing key gives (checked like a value).

    Returns
    -------
    int
        The integer.

    Raises
    ------
    DocumentError
        Missing key, or not an integer (the message names the dotted key).
    """
    x = at(document, *path, default=default)
    if isinstance(x, bool) or not isinstance(x, int):
        raise DocumentError(f"{'.'.join(path)}: expected an integer, got {typename(x)}")
    return x


def flag(document: dict[str, Any], *path: str, default: Any = KeyError) -> bool:
    """The boolean at ``path``.

    Parameters
    ----------
    document : dict
        A parsed JSON object.
    *path : str
        The keys, outermost first.
    default : Any, optional
        What a missing key gives (checked like a value).

    Returns
    -------
    bool
        The flag.

    Raises
    ------
    DocumentError
        Missing key, or not ``true``/``false`` (the message names the dotted key).
    """
    x = at(document, *path, default=default)
    if not isinstance(x, bool):
        raise DocumentError(f"{'.'.join(path)}: expected true or false, got {typename(x)}")
    return x


def string(document: dict[str, Any], *path: str) -> str:
    """The string at ``path``.

    Parameters
    ----------
    document : dict
        A parsed JSON object.
    *path : str
        The keys, outermost first.

    Returns
    -------
    str
        The string.

    Raises
    ------
    DocumentError
        Missing key, or not a string (the message names the dotted key).
    """
    x = at(document, *path)
    if not isinstance(x, str):
        raise DocumentError(f"{'.'.join(path)}: expected a string, got {typename(x)}")
    return x


def numbers(document: dict[str, Any], *path: str) -> tuple[float, ...]:
    """The list of finite numbers at ``path``.

    Parameters
    ----------
    document : dict
        A parsed JSON object.
    *path : str
        The keys, outermost first.

    Returns
    -------
    tuple of float, shape (N,)
        The numbers, in order.

    Raises
    ------
    DocumentError
        Missing key, not a list, or an entry that is not a finite number (named
        ``key[i]``).
    """
    x = at(document, *path)
    label = ".".join(path)
    if not isinstance(x, list):
        raise DocumentError(f"{label}: expected a list of numbers, got {typename(x)}")
    return tuple(finite(v, f"{label}[{i}]") for i, v in enumerate(x))


def strict(x: Any) -> Any:
    """``x`` writable as strict JSON: NaN and infinities become ``None`` (``null``).

    Parameters
    ----------
    x : Any
        Nested dicts, lists and tuples of numbers (Python or NumPy scalars) and others.

    Returns
    -------
    Any
        The same structure (tuples as lists), NumPy scalars as Python ones, non-finite
        floats as ``None``.
    """
    if isinstance(x, dict):
        return {k: strict(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [strict(v) for v in x]
    if isinstance(x, float | np.floating):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x
