"""Every reader, fed mutated programs: a result or a ProgramError naming file:line:column —
never another exception (hypothesis)."""

from __future__ import annotations

import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from programlib import FIXTURES

from plugcell.io.programs import ProgramError, read_program

FILES = ["drill_plate.src", "pick_place.script", "Module1.mod", "deburr.ls", "glue.pdl",
         "pocket.nc"]
ALPHABET = "{}[](),;:=.-+#'\"\\\n 0123456789XYZABCPJLGTE$!%e"


@st.composite
def mutations(draw, text: str):
    out = text
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, max(0, len(out) - 1)))
        op = draw(st.sampled_from(["insert", "delete", "replace"]))
        ch = draw(st.text(alphabet=ALPHABET, min_size=1, max_size=3))
        if op == "insert":
            out = out[:i] + ch + out[i:]
        elif op == "delete":
            out = out[:i] + out[i + draw(st.integers(1, 5)):]
        else:
            out = out[:i] + ch + out[i + len(ch):]
    return out


@pytest.mark.parametrize("name", FILES)
def test_mutated_programs_fail_cleanly(name, tmp_path_factory):
    text = (FIXTURES / name).read_bytes().decode("latin-1")
    d = tmp_path_factory.mktemp("fuzz")
    if name.endswith(".src"):
        (d / "drill_plate.dat").write_bytes((FIXTURES / "drill_plate.dat").read_bytes())

    @settings(max_examples=120, deadline=None, derandomize=True,
              suppress_health_check=[HealthCheck.too_slow])
    @given(mutated=mutations(text))
    def run(mutated):
        path = d / name
        path.write_bytes(mutated.encode("latin-1"))
        try:
            prog, _ = read_program(path)
        except ProgramError as exc:
            m = re.search(re.escape(name) + r"(?::(\d+):(\d+))?: ", str(exc))
            assert m is not None, str(exc)
            if m.group(1):
                n_lines = mutated.count("\n") + 1
                assert 1 <= int(m.group(1)) <= n_lines and int(m.group(2)) >= 1
            return
        # read: every number it found is where it says
        for t in prog.targets:
            for n in (*t.nums, *t.extra):
                if not n.virtual:
                    assert prog.files[0 if t.file == 0 else t.file].text[n.start:n.end] == n.text

    run()
