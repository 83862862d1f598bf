"""Static checks: every name declared, every type right, every call well formed.

Runs once when a program is loaded, over the program and all the libraries it
imports, so that a program with a mistake is refused with its file and line
before the robot moves.  Produces one :class:`~.scope.ModuleScope` per module.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from plugcell.pdl import nodes as n
from plugcell.pdl import predefined
from plugcell.pdl.errors import (
    ArgumentError,
    DeclarationError,
    ExecutionError,
    LibraryError,
    Location,
    TypeMismatchError,
)
from plugcell.pdl.nodes import key
from plugcell.pdl.operators import (
    apply_binary,
    apply_unary,
    binary_type,
    unary_type,
)
from plugcell.pdl.printer import format_expr
from plugcell.pdl.scope import (
    ConstInfo,
    ModuleScope,
    RoutineRef,
    Symbol,
    VarInfo,
    external_variables,
)
from plugcell.pdl.types import (
    BOOLEAN,
    INTEGER,
    JOINTPOS,
    NEWLINE,
    POSITION,
    REAL,
    VECTOR,
    ArrayType,
    LangType,
    StringType,
    assignable,
    is_numeric,
)
from plugcell.pdl.values import POSITION_FIELDS, VECTOR_FIELDS

__all__ = ["LUNS", "ParsedModule", "check_program"]

#: Logical units WRITE accepts.  PC_CLIENT goes to the Channel, the others to the console.
LUNS = ("PC_CLIENT", "LUN_CRT", "LUN_TP", "LUN_NULL")
MOVE_FRAMES = ("BASE", "TOOL")


@dataclass(slots=True)
class ParsedModule:
    """A parsed file and what its IMPORTs / ``EXPORTED FROM`` resolved to."""

    key: str
    module: n.Module
    base_dir: Path | None
    links: dict[int, str] = field(default_factory=dict)  # id(decl) -> module key


@dataclass(slots=True)
class _Ctx:
    """Where a statement is: inside which routine (if any) with which locals."""

    locals: dict[str, VarInfo]
    routine: n.Routine | None = None


def _article(t: LangType | str) -> str:
    text = str(t)
    return ("an " if text[:1] in "AEIOU" else "a ") + text


class _ModuleChecker:
    def __init__(self, pm: ParsedModule, externals: Mapping[str, VarInfo], is_main: bool) -> None:
        self.pm = pm
        self.m = pm.module
        self.is_main = is_main
        self.scope = ModuleScope(pm.key, pm.module, externals=externals)
        self.declared: dict[str, Location] = {}

    # ----------------------------------------------------------------- declarations
    def _claim(self, name: str, loc: Location, what: str) -> str:
        k = key(name)
        if k in predefined.CONSTANTS or k in predefined.SYSTEM_VARIABLES:
            raise DeclarationError.at(loc, f"{name} is a predefined name and cannot be a {what}")
        if k in predefined.EXTERNALS:
            raise DeclarationError.at(loc, f"{name} is a service variable and cannot be a {what}")
        if k in self.declared:
            raise DeclarationError.at(loc, f"{name} is already declared at {self.declared[k]}")
        self.declared[k] = loc
        return k

    def declare_globals(self) -> None:
        for decl in self.m.variables:
            _require_sized(decl.type, decl.loc)
            for name in decl.names:
                k = key(name)
                if k in predefined.EXTERNALS:
                    self._declare_external(name, decl)
                    continue
                self._claim(name, decl.loc, "variable")
                self.scope.globals[k] = VarInfo(
                    name, decl.type, decl.loc, self.pm.key, settable=self.is_main
                )

    def _declare_external(self, name: str, decl: n.VarDecl) -> None:
        want, _ = predefined.EXTERNALS[key(name)]
        same_kind = isinstance(want, StringType) and isinstance(decl.type, StringType)
        if decl.type != want and not same_kind:
            raise TypeMismatchError.at(
                decl.loc, f"{name} is the service variable {name} : {want}, not {decl.type}"
            )

    def declare_consts(self) -> None:
        for c in self.m.consts:
            k = self._claim(c.name, c.loc, "constant")
            self._require_constant(c.value)
            t = self.type_of(c.value, _Ctx({}))
            value = self._constant_value(c.value)
            self.scope.consts[k] = ConstInfo(c.name, t, value, c.loc)

    def _require_constant(self, e: n.Expr) -> None:
        if isinstance(e, n.IntLit | n.RealLit | n.StrLit | n.BoolLit):
            return
        if isinstance(e, n.Name):
            sym = self.scope.resolve(key(e.name))
            if sym is not None and sym.kind == "const":
                return
        elif isinstance(e, n.Unary):
            return self._require_constant(e.operand)
        elif isinstance(e, n.Binary):
            self._require_constant(e.left)
            return self._require_constant(e.right)
        raise DeclarationError.at(e.loc, "a CONST value must be a constant expression")

    def _constant_value(self, e: n.Expr) -> Any:
        if isinstance(e, n.IntLit | n.RealLit | n.StrLit | n.BoolLit):
            return e.value
        if isinstance(e, n.Name):
            sym = self.scope.resolve(key(e.name))
            if sym is not None and sym.kind == "const":
                assert sym.const is not None
                return sym.const.value
        elif isinstance(e, n.Unary):
            return apply_unary(e.op, self._constant_value(e.operand), e.loc)
        elif isinstance(e, n.Binary):
            try:
                return apply_binary(
                    e.op, self._constant_value(e.left), self._constant_value(e.right), e.loc
                )
            except ExecutionError as exc:
                raise DeclarationError(exc.file, exc.line, exc.message, exc.column) from None
        raise DeclarationError.at(e.loc, "a CONST value must be a constant expression")

    def declare_routines(self, parsed: Mapping[str, ParsedModule]) -> None:
        for r in self.m.routines:
            if r.is_declaration:
                continue
            k = self._claim(r.name, r.loc, "routine")
            self._check_params(r)
            self.scope.routines[k] = RoutineRef(self.pm.key, r)
        for decl in self.m.decls:
            if isinstance(decl, n.Import):
                self._import(decl, parsed[self.pm.links[id(decl)]])
            elif isinstance(decl, n.Routine) and decl.is_declaration:
                self._extern_routine(decl, parsed[self.pm.links[id(decl)]])

    def _check_params(self, r: n.Routine) -> None:
        seen: dict[str, Location] = {}
        for p in (*r.params, *((x, d.loc) for d in r.locals for x in d.names)):
            name, loc = (p.name, p.loc) if isinstance(p, n.Param) else p
            k = key(name)
            if k in seen:
                raise DeclarationError.at(loc, f"{name} is already declared at {seen[k]}")
            if (
                k in predefined.CONSTANTS
                or k in predefined.SYSTEM_VARIABLES
                or k in predefined.EXTERNALS
            ):
                raise DeclarationError.at(loc, f"{name} is a predefined name")
            seen[k] = loc
        for d in r.locals:
            _require_sized(d.type, d.loc)

    def _import(self, decl: n.Import, lib: ParsedModule) -> None:
        for r in lib.module.routines:
            if r.is_declaration:
                continue
            k = key(r.name)
            if k in self.scope.routines:
                other = self.scope.routines[k]
                if other.module == lib.key and other.routine is r:
                    continue  # the same library imported twice
                where = other.via or other.routine.loc
                raise DeclarationError.at(
                    decl.loc,
                    f"routine {r.name} from '{decl.path}' clashes with {r.name} at {where}",
                )
            if k in self.declared:
                raise DeclarationError.at(
                    decl.loc,
                    f"'{decl.path}' defines {r.name}, already declared at {self.declared[k]}",
                )
            self.scope.routines[k] = RoutineRef(lib.key, r, decl.loc)

    def _extern_routine(self, decl: n.Routine, lib: ParsedModule) -> None:
        k = self._claim(decl.name, decl.loc, "routine")
        target = next(
            (r for r in lib.module.routines if key(r.name) == k and not r.is_declaration), None
        )
        if target is None:
            raise LibraryError.at(decl.loc, f"{lib.module.file} has no routine {decl.name}")
        if not _same_signature(decl, target):
            raise LibraryError.at(
                decl.loc,
                f"declaration of {decl.name} does not match its definition at {target.loc}"
                f" ({_signature(target)})",
            )
        self.scope.routines[k] = RoutineRef(lib.key, target, decl.loc)

    def link_exported_variables(self, scopes: Mapping[str, ModuleScope]) -> None:
        """``x : T EXPORTED FROM prog`` is prog's variable x (same storage)."""
        for decl in self.m.variables:
            if decl.exported_from is None or id(decl) not in self.pm.links:
                continue
            owner = scopes[self.pm.links[id(decl)]]
            if owner.key == self.pm.key:
                continue
            for name in decl.names:
                k = key(name)
                if k in predefined.EXTERNALS:
                    continue
                info = owner.globals.get(k)
                if info is None:
                    raise LibraryError.at(
                        decl.loc, f"{owner.module.file} has no variable {name} to share"
                    )
                if info.type != decl.type:
                    raise LibraryError.at(
                        decl.loc, f"{name} is {info.type} in {owner.module.file}, not {decl.type}"
                    )
                self.scope.globals[k] = info

    # ----------------------------------------------------------------- bodies
    def check_bodies(self) -> None:
        for ref in self.scope.routines.values():
            if ref.module != self.pm.key:
                continue
            r = ref.routine
            locals_: dict[str, VarInfo] = {}
            for p in r.params:
                locals_[key(p.name)] = VarInfo(p.name, p.type, p.loc, "local")
            for d in r.locals:
                for x in d.names:
                    locals_[key(x)] = VarInfo(x, d.type, d.loc, "local")
            self.block(r.body, _Ctx(locals_, r))
        if self.m.body is not None:
            self.block(self.m.body, _Ctx({}))

    def block(self, stmts: tuple[n.Stmt, ...], ctx: _Ctx) -> None:
        for s in stmts:
            self.stmt(s, ctx)

    def _condition(self, e: n.Expr, ctx: _Ctx, what: str) -> None:
        t = self.type_of(e, ctx)
        if t != BOOLEAN:
            raise TypeMismatchError.at(e.loc, f"{what} must be BOOLEAN, not {t}")

    def _numeric(self, e: n.Expr, ctx: _Ctx, what: str, integer: bool = False) -> None:
        t = self.type_of(e, ctx)
        ok = t == INTEGER if integer else is_numeric(t)
        if not ok:
            want = "INTEGER" if integer else "INTEGER or REAL"
            raise TypeMismatchError.at(e.loc, f"{what} must be {want}, not {t}")

    def stmt(self, s: n.Stmt, ctx: _Ctx) -> None:
        if isinstance(s, n.Assign):
            target = self.target_type(s.target, ctx)
            value = self.type_of(s.value, ctx)
            if not assignable(target, value):
                raise TypeMismatchError.at(
                    s.loc, f"cannot assign {_article(value)} to {_describe(s.target)} ({target})"
                )
        elif isinstance(s, n.CallStmt):
            self.call(s.name, s.args, s.loc, ctx, statement=True)
        elif isinstance(s, n.If):
            self._condition(s.cond, ctx, "the IF condition")
            self.block(s.then, ctx)
            if s.orelse is not None:
                self.block(s.orelse, ctx)
        elif isinstance(s, n.For):
            var_type = self.target_type(n.Name(s.var, s.loc), ctx)
            if var_type != INTEGER:
                raise TypeMismatchError.at(s.loc, f"FOR variable {s.var} must be INTEGER")
            self._numeric(s.start, ctx, "the FOR start", integer=True)
            self._numeric(s.stop, ctx, "the FOR limit", integer=True)
            if s.step is not None:
                self._numeric(s.step, ctx, "the FOR STEP", integer=True)
            self.block(s.body, ctx)
        elif isinstance(s, n.While):
            self._condition(s.cond, ctx, "the WHILE condition")
            self.block(s.body, ctx)
        elif isinstance(s, n.Repeat):
            self.block(s.body, ctx)
            self._condition(s.cond, ctx, "the UNTIL condition")
        elif isinstance(s, n.Select):
            self._numeric(s.subject, ctx, "the SELECT value", integer=True)
            for case in s.cases:
                for v in case.values:
                    self._numeric(v, ctx, "a CASE value", integer=True)
                self.block(case.body, ctx)
            if s.orelse is not None:
                self.block(s.orelse, ctx)
        elif isinstance(s, n.Wait):
            self._condition(s.cond, ctx, "the WAIT FOR condition")
            if s.timeout is not None:
                self._numeric(s.timeout, ctx, "the WAIT TIMEOUT (ms)")
        elif isinstance(s, n.Delay):
            self._numeric(s.duration, ctx, "the DELAY (ms)")
        elif isinstance(s, n.Move):
            self._move(s, ctx)
        elif isinstance(s, n.MoveRelative):
            t = self.type_of(s.vector, ctx)
            if t != VECTOR:
                raise TypeMismatchError.at(
                    s.vector.loc, f"MOVE RELATIVE needs a VECTOR (VEC(x, y, z)), not {t}"
                )
            if s.frame not in MOVE_FRAMES:
                raise DeclarationError.at(
                    s.loc, f"MOVE RELATIVE … IN {s.frame}: the frame must be BASE or TOOL"
                )
        elif isinstance(s, n.Write):
            if key(s.lun) not in LUNS:
                raise DeclarationError.at(
                    s.loc, f"unknown logical unit {s.lun} (known: {', '.join(LUNS)})"
                )
            for item in s.items:
                self.type_of(item.expr, ctx)
                for fmt in (item.width, item.precision):
                    if fmt is not None:
                        self._numeric(fmt, ctx, "a WRITE format", integer=True)
        elif isinstance(s, n.Return):
            self._return(s, ctx)
        elif isinstance(s, n.Deactivate):
            pass
        else:  # pragma: no cover
            raise TypeError(s)

    def _move(self, s: n.Move, ctx: _Ctx) -> None:
        """``MOVE [JOINT|LINEAR] TO x [WITH TRACKING T]``: the target's type, and tracking
        only on a straight move."""
        kind = "MOVE" if s.kind == "TO" else f"MOVE {s.kind}"
        t = self.type_of(s.target, ctx)
        allowed = (POSITION,) if s.kind == "LINEAR" else (POSITION, JOINTPOS)
        if t not in allowed:
            want = " or ".join(str(a) for a in allowed)
            raise TypeMismatchError.at(s.target.loc, f"{kind} TO needs a {want}, not {t}")
        if s.tracking is not None and s.kind != "LINEAR":
            raise TypeMismatchError.at(
                s.loc, f"{kind} TO … WITH TRACKING: only a MOVE LINEAR has a path for the "
                "tracker to correct (the joints' path of a MOVE TO is the controller's)")

    def _return(self, s: n.Return, ctx: _Ctx) -> None:
        r = ctx.routine
        if r is None:
            raise DeclarationError.at(
                s.loc, "RETURN outside a routine (DEACTIVATE ends the program)"
            )
        if r.return_type is None:
            if s.value is not None:
                raise TypeMismatchError.at(s.loc, f"routine {r.name} returns no value")
            return
        if s.value is None:
            raise TypeMismatchError.at(s.loc, f"RETURN in {r.name} needs {_article(r.return_type)}")
        t = self.type_of(s.value, ctx)
        if not assignable(r.return_type, t):
            raise TypeMismatchError.at(
                s.loc, f"{r.name} returns {_article(r.return_type)}, not {_article(t)}"
            )

    # ----------------------------------------------------------------- expressions
    def _symbol(self, name: str, loc: Location, ctx: _Ctx) -> Symbol:
        sym = self.scope.resolve(key(name), ctx.locals)
        if sym is None:
            raise DeclarationError.at(loc, f"{name} is not declared")
        return sym

    def target_type(self, e: n.Expr, ctx: _Ctx) -> LangType:
        """Type of an assignment target (and check it is one)."""
        if isinstance(e, n.Name):
            sym = self._symbol(e.name, e.loc, ctx)
            if sym.kind == "var":
                assert sym.var is not None
                return sym.var.type
            if sym.kind == "const":
                raise TypeMismatchError.at(e.loc, f"cannot assign to the constant {e.name}")
            raise TypeMismatchError.at(e.loc, f"{e.name} is a routine, not a variable")
        if isinstance(e, n.Index | n.Field):
            self.target_type(e.base, ctx)
            return self.type_of(e, ctx)
        raise TypeMismatchError.at(e.loc, "only variables can be assigned")

    def type_of(self, e: n.Expr, ctx: _Ctx) -> LangType:
        if isinstance(e, n.IntLit):
            return INTEGER
        if isinstance(e, n.RealLit):
            return REAL
        if isinstance(e, n.StrLit):
            return StringType(len(e.value))
        if isinstance(e, n.BoolLit):
            return BOOLEAN
        if isinstance(e, n.Name):
            sym = self._symbol(e.name, e.loc, ctx)
            if sym.kind == "var":
                assert sym.var is not None
                return sym.var.type
            if sym.kind == "const":
                assert sym.const is not None
                return sym.const.type
            result = self.call(e.name, (), e.loc, ctx, statement=False)
            assert result is not None
            return result
        if isinstance(e, n.Index):
            return self._index_type(e, ctx)
        if isinstance(e, n.Field):
            base = self.type_of(e.base, ctx)
            if base == POSITION and e.name in POSITION_FIELDS:
                return StringType(None) if e.name == "CNFG" else REAL
            if base == VECTOR and e.name in VECTOR_FIELDS:
                return REAL
            fields = {POSITION: POSITION_FIELDS, VECTOR: VECTOR_FIELDS}.get(base)  # type: ignore[call-overload]
            if fields is None:
                raise TypeMismatchError.at(e.loc, f"{base} has no fields (.{e.name})")
            raise TypeMismatchError.at(
                e.loc, f"{base} has no field {e.name} (fields: {', '.join(fields)})"
            )
        if isinstance(e, n.Call):
            result = self.call(e.name, e.args, e.loc, ctx, statement=False)
            assert result is not None
            return result
        if isinstance(e, n.Unary):
            t = self.type_of(e.operand, ctx)
            out = unary_type(e.op, t)
            if out is None:
                raise TypeMismatchError.at(e.loc, f"operator {e.op} cannot be applied to {t}")
            return out
        if isinstance(e, n.Binary):
            lt, rt = self.type_of(e.left, ctx), self.type_of(e.right, ctx)
            out = binary_type(e.op, lt, rt)
            if out is None:
                raise TypeMismatchError.at(e.loc, f"operator {e.op} cannot combine {lt} and {rt}")
            return out
        raise TypeError(f"not an expression: {e!r}")  # pragma: no cover

    def _index_type(self, e: n.Index, ctx: _Ctx) -> LangType:
        base = self.type_of(e.base, ctx)
        for i in e.indices:
            self._numeric(i, ctx, "an index", integer=True)
        if isinstance(base, ArrayType):
            if len(e.indices) != len(base.dims):
                raise TypeMismatchError.at(
                    e.loc,
                    f"{_describe(e.base)} has {len(base.dims)} dimension(s), "
                    f"{len(e.indices)} index(es) given",
                )
            return base.element
        if base == JOINTPOS:
            if len(e.indices) != 1:
                raise TypeMismatchError.at(e.loc, "a JOINTPOS takes one index (the axis)")
            return REAL
        raise TypeMismatchError.at(e.loc, f"{_describe(e.base)} ({base}) cannot be indexed")

    def call(
        self, name: str, args: tuple[n.Expr, ...], loc: Location, ctx: _Ctx, statement: bool
    ) -> LangType | None:
        """Check a call; the result type (``None`` for a procedure statement)."""
        k = key(name)
        if k in ctx.locals or k in self.scope.globals or k in self.scope.consts:
            raise TypeMismatchError.at(loc, f"{name} is a variable, not a routine")
        sym = self.scope.resolve_call(k, statement)
        if sym is None:
            raise DeclarationError.at(loc, f"unknown routine {name}")
        if sym.kind == "routine":
            assert sym.routine is not None
            r = sym.routine.routine
            if len(args) != len(r.params):
                raise ArgumentError.at(
                    loc, f"{r.name} expects {_count(len(r.params))}, got {len(args)}"
                )
            for i, (a, p) in enumerate(zip(args, r.params, strict=True), start=1):
                t = self.type_of(a, ctx)
                if not assignable(p.type, t):
                    raise TypeMismatchError.at(
                        a.loc, f"argument {i} of {r.name} ({p.name}) must be {p.type}, not {t}"
                    )
            if r.return_type is None and not statement:
                raise TypeMismatchError.at(loc, f"{r.name} returns no value")
            return r.return_type
        assert sym.builtin is not None
        b = sym.builtin
        if sym.kind == "function" and statement:
            raise TypeMismatchError.at(loc, f"{b.name} is a function: use its value")
        if sym.kind == "procedure" and not statement:
            raise TypeMismatchError.at(loc, f"{b.name} is a procedure and returns no value")
        if not b.min_args <= len(args) <= b.max_args:
            raise ArgumentError.at(
                loc, f"{b.name} expects {b.arity_text()} argument(s), got {len(args)}"
            )
        types: list[LangType] = []
        for i, a in enumerate(args):
            spec = b.arg_spec(i)
            t = self.target_type(a, ctx) if spec.output else self.type_of(a, ctx)
            if t == NEWLINE and spec is not predefined.WRITABLE:
                raise TypeMismatchError.at(a.loc, "NL can only be written (WRITE, ENCODE)")
            if not spec.accepts(t):
                raise TypeMismatchError.at(
                    a.loc, f"argument {i + 1} of {b.name} must be {spec.describe}, not {t}"
                )
            types.append(t)
        return b.result_type(types) if sym.kind == "function" else None


def _count(k: int) -> str:
    return f"{k} argument" + ("" if k == 1 else "s")


def _describe(e: n.Expr) -> str:
    return format_expr(e)


def _require_sized(t: LangType, loc: Location) -> None:
    if isinstance(t, StringType) and t.length is None:
        raise TypeMismatchError.at(loc, "a STRING variable needs a length: STRING[n]")
    if isinstance(t, ArrayType):
        if any(d is None for d in t.dims):
            raise TypeMismatchError.at(loc, "only routine parameters may have * dimensions")
        _require_sized(t.element, loc)


def _signature(r: n.Routine) -> str:
    params = "; ".join(f"{p.name} : {p.type}" for p in r.params)
    ret = f" : {r.return_type}" if r.return_type is not None else ""
    return f"ROUTINE {r.name}({params}){ret}"


def _same_signature(a: n.Routine, b: n.Routine) -> bool:
    return (
        len(a.params) == len(b.params)
        and all(p.type == q.type for p, q in zip(a.params, b.params, strict=True))
        and a.return_type == b.return_type
    )


def check_program(parsed: Mapping[str, ParsedModule], main_key: str) -> dict[str, ModuleScope]:
    """Check every module; raise the first :class:`~.errors.ProgramError` found."""
    externals = external_variables()
    checkers = {k: _ModuleChecker(pm, externals, k == main_key) for k, pm in parsed.items()}
    for c in checkers.values():
        c.declare_globals()
    for c in checkers.values():
        c.declare_consts()
    for c in checkers.values():
        c.declare_routines(parsed)
    scopes = {k: c.scope for k, c in checkers.items()}
    for c in checkers.values():
        c.link_exported_variables(scopes)
    for c in checkers.values():
        c.check_bodies()
    return scopes
