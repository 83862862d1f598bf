"""How long the functions in ``src/plugcell`` are (issue #33).

A function is split where the split names a concept: a step of the algorithm with its
own equation, or a named stage (parse the header, check the coupled limits).  The goal
is no function over :data:`GOAL_LINES` lines (``end_lineno − lineno + 1`` by ``ast``,
docstring included) — met since issue #33's last splits: :data:`LINES_CEILING` is empty
and stays so (a function that has to be longer is listed there with its reason).

Print the table: ``.venv/bin/python tests/test_function_sizes.py``.
"""

from __future__ import annotations

import ast
from pathlib import Path

from source_trees import parsed

SRC = Path(__file__).resolve().parents[1] / "src" / "plugcell"

GOAL_LINES = 80

#: "path:function" (path under src/plugcell; methods as "Class.method") → the most lines
#: it may have today (only functions over GOAL_LINES).
LINES_CEILING: dict[str, int] = {}


def function_lines(root: Path = SRC) -> dict[str, int]:
    """``"path:name"`` → lines of every function under ``root`` (path relative to it).

    Methods are named ``Class.method``, nested functions ``outer.inner``.
    """
    out: dict[str, int] = {}
    for path in sorted(root.rglob("*.py")):
        tree = parsed(path.read_text(encoding="utf-8"))
        _count(tree, f"{path.relative_to(root).as_posix()}:", out)
    return out


def _count(node: ast.AST, prefix: str, out: dict[str, int]) -> None:
    """Add the lines of the functions inside ``node`` to ``out``, named ``prefix + name``."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
            name = f"{prefix}{child.name}"
            out[name] = child.end_lineno - child.lineno + 1  # type: ignore[operator]
            _count(child, f"{name}.", out)
        elif isinstance(child, ast.ClassDef):
            _count(child, f"{prefix}{child.name}.", out)
        else:
            _count(child, prefix, out)


def test_no_function_grows_past_its_ceiling() -> None:
    over = {k: n for k, n in function_lines().items() if n > LINES_CEILING.get(k, GOAL_LINES)}
    assert over == {}, "split these where the split names a concept (or they grew): " + str(over)


def test_the_ceilings_are_not_stale() -> None:
    """A ceiling names a function that exists, is still over the goal and is not loose."""
    lines = function_lines()
    assert {k for k in LINES_CEILING if lines.get(k, 0) <= GOAL_LINES} == set()
    shrunk = {k: (lines[k], c) for k, c in LINES_CEILING.items() if lines.get(k, c) < c}
    assert shrunk == {}, "lower these ceilings to the (lines, ceiling) now measured: " + str(shrunk)


def test_the_count_sees_methods_and_nested_functions(tmp_path: Path) -> None:
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "m.py").write_text(
        "def f():\n    pass\n\n\nclass A:\n    def m(self):\n"
        "        def inner():\n            pass\n\n        return inner\n"
    )
    assert function_lines(tmp_path) == {"pkg/m.py:f": 2, "pkg/m.py:A.m": 5,
                                        "pkg/m.py:A.m.inner": 2}


if __name__ == "__main__":
    lines = function_lines()
    print(f"functions in src/plugcell over {GOAL_LINES} lines (ceiling: the ratchet)")
    for key, n in sorted(lines.items(), key=lambda kv: -kv[1]):
        if n > GOAL_LINES or key in LINES_CEILING:
            print(f"{n:5}  {LINES_CEILING.get(key, '-'):>5}  {key}")
