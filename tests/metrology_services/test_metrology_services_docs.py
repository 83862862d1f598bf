"""The service documents describe the services as they are."""

from __future__ import annotations

import re
from pathlib import Path

from plugcell.devices.compute.expr import parse
from plugcell.devices.compute.functions import FUNCTIONS
from plugcell.devices.compute.service import ComputeService
from plugcell.devices.tracker.service import TrackerService

DOCS = Path(__file__).resolve().parents[2] / "docs"


def _table_commands(text: str) -> list[str]:
    return re.findall(r"^\| `([A-Z][A-Za-z ]+)` \|", text, flags=re.M)


def test_the_command_tables_list_the_catalogues():
    tracker = (DOCS / "tracker-service.md").read_text()
    compute = (DOCS / "compute-service.md").read_text()
    assert _table_commands(tracker) == [c.name for c in TrackerService.declaration.commands]
    assert _table_commands(compute) == [c.name for c in ComputeService.declaration.commands]


def test_every_registered_function_is_documented_and_the_examples_parse():
    compute = (DOCS / "compute-service.md").read_text()
    for name in FUNCTIONS:
        assert f"`{name}(" in compute or f"{name}(" in compute, name
    block = compute.split("```\nparams = calibrate", 1)[1].split("```", 1)[0]
    assert len(parse("params = calibrate" + block)) == 5
