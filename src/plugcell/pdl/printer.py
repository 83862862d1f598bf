"""AST → canonical source text (``parse(format_module(m)) == m``).

Used by tools (pretty printing, program generators) and by the property tests
that check the parser against its inverse.  Parentheses are added exactly where
precedence needs them.
"""

from __future__ import annotations

from plugcell.pdl import nodes as n

__all__ = ["format_expr", "format_module", "format_stmt"]

_INDENT = "  "
_PRECEDENCE = {
    "=": 1, "<>": 1, "<": 1, "<=": 1, ">": 1, ">=": 1,
    "+": 2, "-": 2, "OR": 2, "XOR": 2,
    "*": 3, "/": 3, "DIV": 3, "MOD": 3, "AND": 3,
}  # fmt: skip
_UNARY = 4
_ATOM = 5


def _prec(e: n.Expr) -> int:
    if isinstance(e, n.Binary):
        return _PRECEDENCE[e.op]
    if isinstance(e, n.Unary):
        return _UNARY
    if isinstance(e, n.IntLit | n.RealLit) and e.value < 0:
        return 0  # a negative literal only exists in generated trees: parenthesize
    return _ATOM


def _literal(e: n.Expr) -> str:
    if isinstance(e, n.IntLit):
        return str(e.value)
    if isinstance(e, n.RealLit):
        text = repr(float(e.value))
        return text if ("." in text or "e" in text) else text + ".0"
    if isinstance(e, n.StrLit):
        return "'" + e.value.replace("'", "''") + "'"
    if isinstance(e, n.BoolLit):
        return "TRUE" if e.value else "FALSE"
    raise TypeError(e)


def format_expr(e: n.Expr) -> str:
    """One expression, minimally parenthesized."""
    if isinstance(e, n.IntLit | n.RealLit | n.StrLit | n.BoolLit):
        text = _literal(e)
        return f"({text})" if _prec(e) == 0 else text
    if isinstance(e, n.Name):
        return e.name
    if isinstance(e, n.Index):
        return f"{_wrap(e.base, _ATOM)}[{', '.join(format_expr(i) for i in e.indices)}]"
    if isinstance(e, n.Field):
        return f"{_wrap(e.base, _ATOM)}.{e.name}"
    if isinstance(e, n.Call):
        return f"{e.name}({', '.join(format_expr(a) for a in e.args)})"
    if isinstance(e, n.Unary):
        inner = format_expr(e.operand)
        if _prec(e.operand) <= _UNARY:
            inner = f"({inner})"
        return f"NOT {inner}" if e.op == "NOT" else f"{e.op}{inner}"
    if isinstance(e, n.Binary):
        p = _PRECEDENCE[e.op]
        left = _wrap(e.left, p if p > 1 else 2)
        right = _wrap(e.right, p + 1)
        return f"{left} {e.op} {right}"
    raise TypeError(f"not an expression: {e!r}")


def _wrap(e: n.Expr, minimum: int) -> str:
    text = format_expr(e)
    return f"({text})" if _prec(e) < minimum else text


def _block(stmts: tuple[n.Stmt, ...], depth: int) -> list[str]:
    out: list[str] = []
    for s in stmts:
        out.extend(format_stmt(s, depth))
    return out


def format_stmt(s: n.Stmt, depth: int = 0) -> list[str]:
    """One statement as indented source lines."""
    pad = _INDENT * depth
    if isinstance(s, n.Assign):
        return [f"{pad}{format_expr(s.target)} := {format_expr(s.value)}"]
    if isinstance(s, n.CallStmt):
        args = f"({', '.join(format_expr(a) for a in s.args)})" if s.args else ""
        return [f"{pad}{s.name}{args}"]
    if isinstance(s, n.If):
        lines = [f"{pad}IF {format_expr(s.cond)} THEN", *_block(s.then, depth + 1)]
        if s.orelse is not None:
            lines += [f"{pad}ELSE", *_block(s.orelse, depth + 1)]
        return [*lines, f"{pad}ENDIF"]
    if isinstance(s, n.For):
        step = f" STEP {format_expr(s.step)}" if s.step is not None else ""
        direction = "DOWNTO" if s.downto else "TO"
        head = f"{pad}FOR {s.var} := {format_expr(s.start)} {direction} {format_expr(s.stop)}"
        return [f"{head}{step} DO", *_block(s.body, depth + 1), f"{pad}ENDFOR"]
    if isinstance(s, n.While):
        return [
            f"{pad}WHILE {format_expr(s.cond)} DO",
            *_block(s.body, depth + 1),
            f"{pad}ENDWHILE",
        ]
    if isinstance(s, n.Repeat):
        return [f"{pad}REPEAT", *_block(s.body, depth + 1), f"{pad}UNTIL {format_expr(s.cond)}"]
    if isinstance(s, n.Select):
        lines = [f"{pad}SELECT {format_expr(s.subject)} OF"]
        for case in s.cases:
            values = ", ".join(format_expr(v) for v in case.values)
            lines += [f"{pad}{_INDENT}CASE ({values}):", *_block(case.body, depth + 2)]
        if s.orelse is not None:
            lines += [f"{pad}{_INDENT}ELSE:", *_block(s.orelse, depth + 2)]
        return [*lines, f"{pad}ENDSELECT"]
    if isinstance(s, n.Wait):
        timeout = f" TIMEOUT {format_expr(s.timeout)}" if s.timeout is not None else ""
        return [f"{pad}WAIT FOR {format_expr(s.cond)}{timeout}"]
    if isinstance(s, n.Delay):
        return [f"{pad}DELAY {format_expr(s.duration)}"]
    if isinstance(s, n.Move):
        kind = "" if s.kind == "TO" else f"{s.kind} "
        tracking = "" if s.tracking is None else f" WITH TRACKING {s.tracking}"
        return [f"{pad}MOVE {kind}TO {format_expr(s.target)}{tracking}"]
    if isinstance(s, n.MoveRelative):
        return [f"{pad}MOVE RELATIVE {format_expr(s.vector)} IN {s.frame}"]
    if isinstance(s, n.Write):
        return [f"{pad}WRITE {s.lun} ({', '.join(_write_item(i) for i in s.items)})"]
    if isinstance(s, n.Return):
        return [f"{pad}RETURN" + (f" {format_expr(s.value)}" if s.value is not None else "")]
    if isinstance(s, n.Deactivate):
        return [f"{pad}DEACTIVATE" + (f" {', '.join(s.names)}" if s.names else "")]
    raise TypeError(f"not a statement: {s!r}")


def _write_item(item: n.WriteItem) -> str:
    text = format_expr(item.expr)
    if item.width is not None:
        text += f"::{format_expr(item.width)}"
        if item.precision is not None:
            text += f"::{format_expr(item.precision)}"
    return text


def _var_decl(d: n.VarDecl, depth: int) -> str:
    attrs = "".join(f" {a}" for a in d.attrs)
    if d.exported_from:
        attrs += f" EXPORTED FROM {d.exported_from}"
    return f"{_INDENT * depth}{', '.join(d.names)} : {d.type}{attrs}"


def _routine(r: n.Routine) -> list[str]:
    params = "; ".join(f"{p.name} : {p.type}" for p in r.params)
    head = f"ROUTINE {r.name}" + (f"({params})" if r.params else "")
    if r.return_type is not None:
        head += f" : {r.return_type}"
    if r.exported_from is not None:
        return [f"{head} EXPORTED FROM {r.exported_from}"]
    lines = [head]
    if r.locals:
        lines += ["  VAR", *(_var_decl(d, 2) for d in r.locals)]
    return [*lines, "BEGIN", *_block(r.body, 1), f"END {r.name}"]


def format_module(m: n.Module) -> str:
    """A whole source file."""
    attrs = ", ".join(a.name + (f" = {format_expr(a.value)}" if a.value else "") for a in m.attrs)
    lines = [f"PROGRAM {m.name}" + (f" {attrs}" if attrs else "")]
    previous: type | None = None
    for d in m.decls:
        if isinstance(d, n.VarDecl):
            if previous is not n.VarDecl:
                lines.append("VAR")
            lines.append(_var_decl(d, 1))
        elif isinstance(d, n.ConstDecl):
            if previous is not n.ConstDecl:
                lines.append("CONST")
            lines.append(f"{_INDENT}{d.name} = {format_expr(d.value)}")
        elif isinstance(d, n.Import):
            lines.append("IMPORT '" + d.path.replace("'", "''") + "'")
        else:
            lines += _routine(d)
        previous = type(d)
    if m.body is not None:
        lines += ["BEGIN", *_block(m.body, 1)]
    lines.append(f"END {m.name}")
    return "\n".join(lines) + "\n"
