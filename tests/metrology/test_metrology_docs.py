"""The examples of docs/metrology.md run and still print the numbers shown there."""

from __future__ import annotations

import contextlib
import io
import itertools
import re
from pathlib import Path

import numpy as np
import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "metrology.md"
_NUM = re.compile(r"[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")


def _examples() -> list[tuple[str, str]]:
    text = DOC.read_text(encoding="utf-8")
    blocks = re.findall(r"```(python|text)\n(.*?)```", text, flags=re.S)
    pairs = []
    for (kind, code), (nkind, out) in itertools.pairwise(blocks):
        if kind == "python" and nkind == "text":
            pairs.append((code, out))
    return pairs


@pytest.mark.skipif(not DOC.exists(), reason="docs/metrology.md not present")
@pytest.mark.parametrize("index", range(3))
def test_doc_example_prints_what_the_doc_shows(index):
    pairs = _examples()
    assert len(pairs) == 3, "docs/metrology.md should hold 3 python/text example pairs"
    code, expected = pairs[index]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        exec(compile(code, f"docs/metrology.md example {index}", "exec"), {})
    got, want = buf.getvalue(), expected
    g = np.array([float(x) for x in _NUM.findall(got)])
    w = np.array([float(x) for x in _NUM.findall(want)])
    assert g.shape == w.shape, f"output changed shape:\n{got}\nvs doc:\n{want}"
    # printed numbers are rounded: allow one unit in the last printed place
    np.testing.assert_allclose(g, w, rtol=2e-3, atol=1.5e-3, err_msg=f"\n{got}\nvs doc:\n{want}")
