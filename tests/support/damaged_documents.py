"""Hypothesis strategies for damaged JSON/TOML-like documents: a valid document with
one to three places replaced by a random leaf, deleted, given an extra key or nudged
(robot description files, PARAMS.json — any reader that must refuse with its own error)."""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

from hypothesis import strategies as st

#: A random leaf value: nothing, a bool, numbers (NaN and infinities too), text, a list, a table.
LEAF = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**6), 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=5),
    st.lists(st.floats(-1e3, 1e3), max_size=5),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)

#: What may be done at a place: put a random leaf, delete it, add a key beside it, or
#: add up to ±200 to a number.
ACTIONS = ("replace", "delete", "insert", "perturb")


def paths(obj: Any, prefix: tuple = ()) -> list[tuple]:
    """Every place in ``obj`` (nested dicts and lists) as a tuple of keys, ``()`` first."""
    out = [prefix]
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out += paths(v, (*prefix, i))
    return out


@st.composite
def damaged(draw: st.DrawFn, base: dict[str, Any],
            actions: Sequence[str] = ACTIONS) -> dict[str, Any]:
    """A deep copy of ``base`` with one to three of ``actions`` done at random places."""
    d = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(paths(d)))
        if not path:
            continue
        parent = d
        for key in path[:-1]:
            parent = parent[key]
        key = path[-1]
        action = draw(st.sampled_from(list(actions)))
        if action == "replace":
            parent[key] = draw(LEAF)
        elif action == "delete":
            del parent[key]
        elif action == "insert" and isinstance(parent, dict):
            parent[draw(st.text(max_size=4))] = draw(LEAF)
        elif (action == "perturb" and isinstance(parent[key], int | float)
              and not isinstance(parent[key], bool)):
            parent[key] = parent[key] + draw(st.floats(-200, 200))
    return d
