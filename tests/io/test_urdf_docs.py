"""The first example block of docs/urdf.md runs (vendor robots from ../shared/data/urdf)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from shared_data import URDF_DIR, shared_dir

DOC = Path(__file__).resolve().parents[2] / "docs" / "urdf.md"


@pytest.mark.skipif(not URDF_DIR.is_dir(), reason="../shared/data/urdf not available")
def test_import_examples_run(capsys: pytest.CaptureFixture[str]) -> None:
    from plugcell.apps.cli import main

    block = re.findall(r"```sh\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)[0]
    env: dict[str, str] = {"PLUGCELL_DATA": str(shared_dir() / "data")}
    ran = 0
    for line in block.splitlines():
        for k, v in env.items():
            line = line.replace(f"${k}", v)
        if "=" in line.split()[0] and not line.startswith("plugcell"):
            k, v = line.split("=", 1)
            env[k] = v
            continue
        argv = shlex.split(line)
        assert argv[0] == "plugcell"
        assert main(argv[1:]) == 0, line
        ran += 1
    out = capsys.readouterr().out
    assert ran == 4 and "joint_6" in out and 'name = "ur10"' in out
