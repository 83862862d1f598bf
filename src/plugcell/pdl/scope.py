"""Name resolution: what an identifier means in a module.

A checked module has a :class:`ModuleScope`: its global variables, constants and
routines (its own and imported).  :meth:`ModuleScope.resolve` looks a name up in
the one order both the checker and the interpreter use:

1. the routine's parameters and local variables,
2. the module's global variables (own, or ``EXPORTED FROM`` another program),
3. the module's constants,
4. the service variables (``ext_cmd_finished`` …) and system variables (``$ERROR``),
5. predefined constants (``NL``, ``ED_UPPER``, ``ERR_WAIT_TIMEOUT`` …),
6. routines (the module's and imported ones), then built-ins.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from plugcell.pdl import nodes as n
from plugcell.pdl import predefined
from plugcell.pdl.errors import Location
from plugcell.pdl.types import LangType

__all__ = ["EXTERNAL_STORE", "ConstInfo", "ModuleScope", "RoutineRef", "Symbol", "VarInfo"]

#: Storage key of the service and system variables (shared by all modules).
EXTERNAL_STORE = "$external"


@dataclass(frozen=True, slots=True)
class VarInfo:
    """A variable: where it is declared and in which storage it lives."""

    name: str
    type: LangType
    loc: Location
    store: str  # a module key, EXTERNAL_STORE, or "local"
    settable: bool = False  # may services set it (Execution.post)?


@dataclass(frozen=True, slots=True)
class ConstInfo:
    name: str
    type: LangType
    value: Any
    loc: Location | None = None


@dataclass(frozen=True, slots=True)
class RoutineRef:
    """A routine with a body, and the key of the module that defines it."""

    module: str
    routine: n.Routine
    via: Location | None = None  # the IMPORT / EXPORTED FROM that brought it in

    @property
    def is_function(self) -> bool:
        return self.routine.return_type is not None


@dataclass(frozen=True, slots=True)
class Symbol:
    """What a name resolved to: ``kind`` is ``var``, ``const``, ``routine``,
    ``function`` (built-in) or ``procedure`` (built-in)."""

    kind: str
    var: VarInfo | None = None
    const: ConstInfo | None = None
    routine: RoutineRef | None = None
    builtin: predefined.Builtin | None = None


@dataclass(slots=True)
class ModuleScope:
    """Everything a module's code can name (filled by the checker, then frozen in use)."""

    key: str
    module: n.Module
    globals: dict[str, VarInfo] = field(default_factory=dict)
    consts: dict[str, ConstInfo] = field(default_factory=dict)
    routines: dict[str, RoutineRef] = field(default_factory=dict)
    externals: Mapping[str, VarInfo] = field(default_factory=dict)

    def freeze(self) -> None:
        """Make the tables read-only (a loaded Program never changes)."""
        self.globals = MappingProxyType(dict(self.globals))  # type: ignore[assignment]
        self.consts = MappingProxyType(dict(self.consts))  # type: ignore[assignment]
        self.routines = MappingProxyType(dict(self.routines))  # type: ignore[assignment]

    def resolve(self, key: str, local: Mapping[str, VarInfo] | None = None) -> Symbol | None:
        """The meaning of upper-case ``key`` (functions before procedures for
        built-ins); ``None`` if it is not declared anywhere."""
        if local is not None and key in local:
            return Symbol("var", var=local[key])
        if key in self.globals:
            return Symbol("var", var=self.globals[key])
        if key in self.consts:
            return Symbol("const", const=self.consts[key])
        if key in self.externals:
            return Symbol("var", var=self.externals[key])
        if key in predefined.CONSTANTS:
            t, v = predefined.CONSTANTS[key]
            return Symbol("const", const=ConstInfo(key, t, v))
        if key in self.routines:
            return Symbol("routine", routine=self.routines[key])
        if key in predefined.FUNCTIONS:
            return Symbol("function", builtin=predefined.FUNCTIONS[key])
        if key in predefined.PROCEDURES:
            return Symbol("procedure", builtin=predefined.PROCEDURES[key])
        return None

    def resolve_call(self, key: str, statement: bool) -> Symbol | None:
        """A routine or built-in called by name; statements prefer built-in procedures."""
        if key in self.routines:
            return Symbol("routine", routine=self.routines[key])
        order = (
            (predefined.PROCEDURES, predefined.FUNCTIONS)
            if statement
            else (predefined.FUNCTIONS, predefined.PROCEDURES)
        )
        for table in order:
            if key in table:
                kind = "procedure" if table is predefined.PROCEDURES else "function"
                return Symbol(kind, builtin=table[key])
        return None


def external_variables() -> dict[str, VarInfo]:
    """The service and system variables, as :class:`VarInfo` (shared storage)."""
    nowhere = Location("<predefined>", 0)
    out = {
        k: VarInfo(k.lower(), t, nowhere, EXTERNAL_STORE, settable=True)
        for k, (t, _) in predefined.EXTERNALS.items()
    }
    out.update(
        {
            k: VarInfo(k, t, nowhere, EXTERNAL_STORE)
            for k, (t, _) in predefined.SYSTEM_VARIABLES.items()
        }
    )
    return out
