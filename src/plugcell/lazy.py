"""A package's public names, imported from its modules when first used (PEP 562).

A package's ``__init__`` that imported every module it re-exports made importing any one
of its modules — ``plugcell.compensation.tracking.limiter`` for a rate limiter — import
all of them, and SciPy with them: seconds of start-up in every process that needed one
small class (the robot's link process, the services).  With :func:`exports` the package
names the module each public name lives in; the module is imported on the first access
of one of its names (``from plugcell.compensation import compensate`` as before), and
``__all__``, ``dir()`` and ``import *`` list every name.

Imports nothing of plugcell (every layer may use it).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any


def exports(package: str, names: Mapping[str, Sequence[str]]
            ) -> tuple[Callable[[str], Any], Callable[[], list[str]], list[str]]:
    """The module ``__getattr__``, ``__dir__`` and ``__all__`` of a package whose public
    names are imported lazily.

    Parameters
    ----------
    package
        The package's ``__name__``.
    names
        Module (relative to the package, e.g. ``"model_based"``) → the public names it
        defines that the package re-exports.

    Returns
    -------
    tuple
        ``(__getattr__, __dir__, __all__)`` to assign at the package's top level.
        ``__getattr__(name)`` imports the module of ``name``, keeps the value in the
        package (the next access is a plain attribute) and returns it; a name the table
        does not have raises ``AttributeError`` as for any module.

    Raises
    ------
    ValueError
        A name listed for two modules.
    """
    where: dict[str, str] = {}
    for module, public in names.items():
        for name in public:
            if name in where:
                raise ValueError(f"{package}: {name!r} listed for both {where[name]!r} "
                                 f"and {module!r}")
            where[name] = module

    def attribute(name: str) -> Any:
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{module}"), name)
        setattr(sys.modules[package], name, value)
        return value

    def listing() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | where.keys())

    return attribute, listing, sorted(where)
