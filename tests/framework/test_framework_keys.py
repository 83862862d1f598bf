"""Only the framework knows the key layout: KeySpace builds and parses every key, and
nothing outside ``plugcell/framework`` builds a key, splits one or reaches into a
participant's private Zenoh plumbing (read statically, no import)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

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


def test_no_module_outside_the_framework_builds_or_splits_keys():
    offenders = []
    for path in _outside_framework():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            # an f-string or literal starting with the key root: a key built by hand
            if isinstance(node, ast.JoinedStr) and node.values and isinstance(
                    node.values[0], ast.Constant) and str(node.values[0].value).startswith(
                    "plugcell/"):
                offenders.append(f"{path.relative_to(SRC)}:{node.lineno}: builds a key")
            # str(sample.key_expr)...: a key parsed by hand
            if isinstance(node, ast.Attribute) and node.attr == "key_expr":
                offenders.append(f"{path.relative_to(SRC)}:{node.lineno}: reads a key")
    assert offenders == []


@pytest.mark.parametrize("private", ["_loop", "_loop_thread", "_callback"])
def test_no_module_outside_the_framework_reaches_into_a_participant(private):
    """``x._loop`` etc. of another object (``self._…`` is a class's own business)."""
    offenders = []
    for path in _outside_framework():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and node.attr == private
                    and not (isinstance(node.value, ast.Name) and node.value.id == "self")):
                offenders.append(f"{path.relative_to(SRC)}:{node.lineno}")
    assert offenders == []
