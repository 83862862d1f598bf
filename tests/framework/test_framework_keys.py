"""Only the framework knows the key layout: KeySpace builds and parses every key, and
nothing outside ``plugcell/framework`` builds a key (a ``plugcell/`` literal or f-string,
a KeySpace layout applied), splits one or reaches into a participant's private Zenoh
plumbing (read statically, no import; the check is shown failing on made-up source)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from source_trees import parsed

from plugcell.framework.keys import KeySpace

SRC = Path(__file__).resolve().parents[2] / "src" / "plugcell"
NAMES = st.from_regex(r"[A-Za-z0-9][A-Za-z0-9_.\-]{0,20}", fullmatch=True)


@given(NAMES, NAMES, NAMES)
def test_a_process_key_parses_back_to_its_service_and_sender(cell, service, sender):
    keys = KeySpace(cell)
    assert keys.parse_process(keys.process(service, sender)) == (service, sender)


@pytest.mark.parametrize("key", [
    "plugcell/c/svc/CAM/get", "plugcell/other/svc/CAM/process/R1", "plugcell/c/live/service/A/1",
    "plugcell/c/svc/CAM/process", "x/c/svc/CAM/process/R1", "", "plugcell/c/sim/reflector/T"])
def test_other_keys_are_not_process_keys(key):
    assert KeySpace("c").parse_process(key) is None


def _outside_framework() -> list[Path]:
    return [p for p in SRC.rglob("*.py") if "framework" not in p.relative_to(SRC).parts]


#: KeySpace's layouts: its public methods and properties (``cell`` is its data, not one).
LAYOUTS = frozenset(
    name for name, value in vars(KeySpace).items()
    if not name.startswith("_") and (callable(value) or isinstance(value, property))
)


def _is_key_space(node: ast.expr, aliases: set[str]) -> bool:
    """Whether ``node`` denotes a KeySpace: ``x.keys``, ``KeySpace(...)`` or a name
    bound to one of those (or annotated ``KeySpace``)."""
    if isinstance(node, ast.Attribute):
        return node.attr == "keys"
    if isinstance(node, ast.Name):
        return node.id in aliases
    if isinstance(node, ast.Call):
        func = node.func
        return (isinstance(func, ast.Name) and func.id == "KeySpace") or (
            isinstance(func, ast.Attribute) and func.attr == "KeySpace")
    return False


def _key_space_aliases(tree: ast.AST) -> set[str]:
    """Names a module binds to a KeySpace (``keys = self.keys``, ``ks: KeySpace``)."""
    aliases: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.arg) and node.annotation is not None and "KeySpace" in \
                ast.unparse(node.annotation):
            aliases.add(node.arg)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and (
                "KeySpace" in ast.unparse(node.annotation)):
            aliases.add(node.target.id)
    grew = True
    while grew:  # ``a = self.keys; b = a``: follow the chain
        grew = False
        for node in ast.walk(tree):
            if isinstance(node, ast.Assign) and _is_key_space(node.value, aliases):
                for target in node.targets:
                    if isinstance(target, ast.Name) and target.id not in aliases:
                        aliases.add(target.id)
                        grew = True
    return aliases


def key_offences(source: str, where: str) -> list[str]:
    """What ``source`` (a module outside the framework) does that only the framework
    may: write a ``plugcell/`` key (literal or f-string), use a KeySpace layout
    (``keys.state(name)``, ``KeySpace(cell).process(...)``), import the key root, or read
    a sample's key to parse it."""
    tree = parsed(source)
    aliases = _key_space_aliases(tree)
    in_fstring = {id(part) for node in ast.walk(tree) if isinstance(node, ast.JoinedStr)
                  for part in node.values}
    prose = {id(node.value) for node in ast.walk(tree)  # docstrings: text, not keys
             if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)}
    found = []
    for node in ast.walk(tree):
        # an f-string or literal starting with the key root: a key built by hand
        if isinstance(node, ast.JoinedStr) and node.values and isinstance(
                node.values[0], ast.Constant) and str(node.values[0].value).startswith(
                "plugcell/"):
            found.append(f"{where}:{node.lineno}: builds a key")
        elif (isinstance(node, ast.Constant) and isinstance(node.value, str)
              and node.value.startswith("plugcell/")
              and id(node) not in in_fstring | prose):
            found.append(f"{where}:{node.lineno}: writes a key")
        # keys.get(name), KeySpace(cell).process(...): a layout applied outside
        elif (isinstance(node, ast.Attribute) and node.attr in LAYOUTS
              and _is_key_space(node.value, aliases)):
            found.append(f"{where}:{node.lineno}: applies the layout {node.attr}")
        elif isinstance(node, ast.ImportFrom) and node.module == "plugcell.framework.keys" \
                and any(a.name == "ROOT" for a in node.names):
            found.append(f"{where}:{node.lineno}: imports the key root")
        # str(sample.key_expr)...: a key parsed by hand
        if isinstance(node, ast.Attribute) and node.attr == "key_expr":
            found.append(f"{where}:{node.lineno}: reads a key")
    return sorted(found, key=lambda f: int(f.split(":")[1]))


def test_the_layouts_are_keyspaces_methods():
    assert {"prefix", "get", "create", "request", "process", "live", "reflector",
            "parse_live", "parse_process", "notifications"} <= LAYOUTS
    assert "cell" not in LAYOUTS


def test_the_key_check_sees_each_offence():
    bad = (
        "from plugcell.framework.keys import ROOT, KeySpace\n"          # 1
        "def f(device, sample, cell, space: KeySpace):\n"                # 2
        "    device.bus.put(device.keys.state('CAM'), b'')\n"            # 3
        "    keys = device.keys\n"                                       # 4
        "    mine = keys\n"                                              # 5
        "    mine.process('CAM', 'ROBOT')\n"                             # 6
        "    KeySpace(cell).reflector('T')\n"                            # 7
        "    space.get('CAM')\n"                                         # 8
        "    raw = 'plugcell/default/svc/CAM/get'\n"                     # 9
        "    built = f'plugcell/{cell}/svc/CAM/get'\n"                   # 10
        "    return str(sample.key_expr).rsplit('/', 1)[-1]\n"           # 11
    )
    assert [o.split(":", 1)[1] for o in key_offences(bad, "bad.py")] == [
        "1: imports the key root", "3: applies the layout state",
        "6: applies the layout process", "7: applies the layout reflector",
        "8: applies the layout get", "9: writes a key", "10: builds a key", "11: reads a key"]
    fine = (
        '"""plugcell/framework owns the keys: a docstring is no key."""\n'
        "from plugcell.framework.keys import KeySpace, check_name\n"
        "def g(device, result, d, space: KeySpace):\n"
        "    cell = device.keys.cell\n"                                  # data, no layout
        "    names = list(d.keys())\n"                                   # a dict's keys
        "    where = result.keys.index('x')\n"                           # a tuple's index
        "    return check_name(cell), space.cell, 'plugcell-bench/' + cell, names, where\n"
    )
    assert key_offences(fine, "fine.py") == []


def test_no_module_outside_the_framework_builds_or_splits_keys():
    offenders = []
    for path in _outside_framework():
        offenders += key_offences(path.read_text(encoding="utf-8"),
                                  path.relative_to(SRC).as_posix())
    assert offenders == []


@pytest.mark.parametrize("private", ["_loop", "_loop_thread", "_callback"])
def test_no_module_outside_the_framework_reaches_into_a_participant(private):
    """``x._loop`` etc. of another object (``self._…`` is a class's own business)."""
    offenders = []
    for path in _outside_framework():
        tree = parsed(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and node.attr == private
                    and not (isinstance(node.value, ast.Name) and node.value.id == "self")):
                offenders.append(f"{path.relative_to(SRC)}:{node.lineno}")
    assert offenders == []
