"""The examples of docs/robot-description.md load and run."""

from __future__ import annotations

import contextlib
import io
import os
import re
import tomllib
from pathlib import Path

import numpy as np

from plugcell.io.robot_schema import description_from_dict, description_to_dict

DOC = Path(__file__).resolve().parents[2] / "docs" / "robot-description.md"


def _blocks(kind: str) -> list[str]:
    return re.findall(rf"```{kind}\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)


def test_minimal_example_loads_and_the_python_example_runs(tmp_path: Path):
    toml_text = _blocks("toml")[0]
    (tmp_path / "my_robot.toml").write_text(toml_text, encoding="utf-8")
    code = _blocks("python")[0]
    out = io.StringIO()
    cwd = os.getcwd()
    try:
        os.chdir(tmp_path)
        with contextlib.redirect_stdout(out):
            exec(compile(code, "docs/robot-description.md", "exec"), {})
    finally:
        os.chdir(cwd)
    nums = [float(x) for x in re.findall(r"-?\d+\.?\d*(?:e[-+]?\d+)?", out.getvalue())]
    np.testing.assert_allclose(nums[-6:], [0, -90, 0, 0, 90, 0], atol=1e-6)  # IK round trip


def test_snippets_are_valid_fragments():
    """Every other TOML snippet merges into the Smart H4 file without errors (the
    Fanuc [coupling] example is checked against its file in test_kinematics_coupling)."""
    from plugcell.io.robots import load_robot

    base = description_to_dict(load_robot("smart_h4"))
    for snippet in _blocks("toml")[1:]:
        if snippet.startswith("[coupling]"):
            continue
        frag = tomllib.loads(snippet)
        d = {**base}
        for k, v in frag.items():
            d[k] = v
        description_from_dict(d)
