"""The public API of the math packages and ``io`` has numpydoc ``Parameters``/``Returns`` (#21).

For every public function and class of ``kinematics``, ``metrology``, ``calibration``,
``compensation``, ``motion`` and ``io`` (the file formats) — the names of each module's
``__all__``, else the public functions and classes defined in the module — a function that takes
arguments must have a ``Parameters`` section and one that returns something other than
``None`` a ``Returns`` (or ``Yields``) section; a class whose constructor takes arguments
must document them in ``Parameters`` or, for a dataclass/record, ``Attributes``.  The
check only looks for the section headers (a title line underlined with dashes), so it is
cheap and imports nothing beyond the packages themselves.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import re
import textwrap
from collections.abc import Callable, Iterator
from typing import Any, Protocol

import pytest

PACKAGES = ("kinematics", "metrology", "calibration", "compensation", "motion", "io")

#: Modules not checked, with the reason.
SKIP_MODULES: dict[str, str] = {}

#: Classes exempt from the constructor check, by kind, with the reason.
#: - exceptions: their constructor is Exception's (a message), documented by the class line;
#: - typing.Protocol classes: structural interfaces, never constructed.
EXEMPT_CLASS_KINDS = ("exception", "protocol")

_SECTION = re.compile(r"^([A-Z][A-Za-z ]*)\n-{3,}[ \t]*$", re.M)


def sections(obj: Any) -> set[str]:
    """Titles of the numpydoc sections of ``obj``'s docstring."""
    return set(_SECTION.findall(inspect.getdoc(obj) or ""))


def _returns_value(func: Callable[..., Any]) -> bool:
    """True unless ``func`` is annotated ``-> None`` (or, unannotated, never returns a value)."""
    ann = inspect.signature(func).return_annotation
    if ann is not inspect.Signature.empty:
        return ann not in (None, "None")
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(func)))
    except (OSError, TypeError, SyntaxError):
        return True
    body = tree.body[0]
    return any(
        isinstance(node, ast.Return) and node.value is not None
        and not (isinstance(node.value, ast.Constant) and node.value.value is None)
        for node in ast.walk(body)
    )


def problems(obj: Any, name: str | None = None) -> list[str]:
    """What the docstring of function or class ``obj`` lacks (empty: nothing)."""
    name = name or getattr(obj, "__qualname__", repr(obj))
    found = sections(obj)
    if inspect.isclass(obj):
        if issubclass(obj, BaseException) or (
            Protocol in getattr(obj, "__mro__", ()) or getattr(obj, "_is_protocol", False)
        ):
            return []
        try:
            params = inspect.signature(obj).parameters
        except (TypeError, ValueError):
            return []
        if params and not ({"Parameters", "Attributes"} & found):
            return [f"{name}: class takes arguments but has no Parameters/Attributes section"]
        return []
    out = []
    params = [p for p in inspect.signature(obj).parameters if p not in ("self", "cls")]
    if params and "Parameters" not in found:
        out.append(f"{name}: takes {params} but has no Parameters section")
    if _returns_value(obj) and not ({"Returns", "Yields"} & found):
        out.append(f"{name}: returns a value but has no Returns section")
    return out


def public_api(packages: tuple[str, ...] = PACKAGES) -> Iterator[tuple[str, Any]]:
    """``(module:name, object)`` of every public function and class of ``packages``."""
    for pkg_name in packages:
        pkg = importlib.import_module(f"plugcell.{pkg_name}")
        for info in pkgutil.iter_modules(pkg.__path__):
            if info.name.startswith("_"):
                continue
            modname = f"{pkg.__name__}.{info.name}"
            if modname in SKIP_MODULES:
                continue
            mod = importlib.import_module(modname)
            names = getattr(mod, "__all__", None)
            if names is None:
                names = [n for n, o in vars(mod).items()
                         if not n.startswith("_") and getattr(o, "__module__", None) == modname]
            for n in names:
                obj = getattr(mod, n)
                if getattr(obj, "__module__", None) != modname:
                    continue  # re-exported: checked where it is defined
                if inspect.isfunction(obj) or inspect.isclass(obj):
                    yield f"{modname}:{n}", obj


@pytest.mark.parametrize("package", PACKAGES)
def test_public_math_api_has_numpydoc_sections(package: str) -> None:
    api = list(public_api((package,)))
    assert len(api) > 10  # the walk found the package
    missing = [msg for qual, obj in api for msg in problems(obj, qual)]
    assert not missing, "docstrings lack numpydoc sections:\n" + "\n".join(missing)


# --------------------------------------------------------------------- the checker itself
def _undocumented(q, scale=1.0):  # type: ignore[no-untyped-def]
    """Scale the joints."""
    return q * scale


def _documented(q: float, scale: float = 1.0) -> float:
    """Scale the joints, ``q' = s · q``.

    Parameters
    ----------
    q : float, rad
        A joint.
    scale : float
        The factor s.

    Returns
    -------
    float, rad
        ``s · q``.
    """
    return q * scale


def _procedure(q: float) -> None:
    """Does nothing.

    Parameters
    ----------
    q : float
        Ignored.
    """


class _Record:
    """A record without its fields."""

    def __init__(self, x: float) -> None:
        self.x = x


@pytest.mark.parametrize(
    ("obj", "expected"),
    [
        (_undocumented, ["no Parameters section", "no Returns section"]),
        (_documented, []),
        (_procedure, []),
        (_Record, ["no Parameters/Attributes section"]),
    ],
)
def test_checker_flags_a_made_up_undocumented_function(obj: Any, expected: list[str]) -> None:
    found = problems(obj)
    assert len(found) == len(expected)
    for msg, want in zip(found, expected, strict=True):
        assert want in msg
