"""The syntax tree of a source text, parsed once per test process.

The structural tests (layering, import circles, keys, transport, function and class
sizes, the command table) each walk the tree of every module of ``src/plugcell``;
parsing all of it again in each test was ~40 s of CPU in a suite run (py-spy).  The
trees are shared: read them, never change them.
"""

from __future__ import annotations

import ast
import functools


@functools.cache
def parsed(source: str) -> ast.Module:
    """``ast.parse(source)``, the same tree for the same text."""
    return ast.parse(source)
