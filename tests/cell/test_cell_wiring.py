"""The wiring file and the keeper that re-applies it (thesis 7.6, Figure 7-9)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.devices.cell.wiring import (
    FORMAT,
    Wire,
    WiringError,
    WiringKeeper,
    load_wiring,
    parse_wiring,
    read_wiring,
    save_wiring,
    wires_in_place,
)


def test_save_then_load_round_trips(tmp_path: Path) -> None:
    wires = [Wire("ROBOT", "TRACKER"), Wire("ROBOT", "COMPUTE"), Wire("ROBOT", "TRACKER")]
    doc = save_wiring(wires, "lab", tmp_path / "sub" / "cell.json")
    assert doc["format"] == FORMAT and doc["cell"] == "lab"
    loaded, cell = load_wiring(tmp_path / "sub" / "cell.json")
    assert cell == "lab"
    assert loaded == [Wire("ROBOT", "COMPUTE"), Wire("ROBOT", "TRACKER")]


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("{", "not JSON"),
        ("[]", "JSON object"),
        ('{"format": "x", "wires": []}', "not a cell wiring file"),
        ('{"version": 2, "wires": []}', "unsupported wiring file version"),
        ('{"wires": {}}', "must be a list"),
        ('{"wires": [1]}', "wire 1: expected an object"),
        ('{"wires": [{"service": "A"}]}', "wire 1: 'service' and 'partner'"),
        ('{"wires": [{"service": "A", "partner": "A"}]}', "wired to itself"),
        ('{"wires": [{"service": "A/B", "partner": "C"}]}', "invalid service name"),
    ],
)
def test_bad_documents_say_why(text: str, reason: str) -> None:
    with pytest.raises(WiringError, match=reason):
        read_wiring(text)


def test_unreadable_files_name_the_path(tmp_path: Path) -> None:
    with pytest.raises(WiringError, match="cannot read"):
        load_wiring(tmp_path / "missing.json")
    (tmp_path / "bin.json").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(WiringError, match=r"bin\.json"):
        load_wiring(tmp_path / "bin.json")
    with pytest.raises(WiringError, match="cannot write"):
        save_wiring([], "c", tmp_path)  # a folder cannot be replaced by the file
    for bad in (Path("."), Path("a\x00b.json")):  # the controller's Save task, fuzzed
        with pytest.raises(WiringError, match="not a file name"):
            save_wiring([], "c", bad)


JSONS = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4)
    | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=20,
)


@settings(max_examples=300, deadline=None)
@given(doc=st.fixed_dictionaries({"wires": st.lists(
    st.fixed_dictionaries({"service": JSONS, "partner": JSONS}) | JSONS, max_size=4)}) | JSONS)
def test_any_json_is_a_wiring_or_a_wiring_error(doc: object) -> None:
    try:
        wires, _ = parse_wiring(doc)
    except WiringError as exc:
        assert str(exc)
        return
    assert all(isinstance(w, Wire) and w.service != w.partner for w in wires)
    assert parse_wiring(json.loads(json.dumps({"wires": [w.to_json() for w in wires]})))[0] == wires


def test_keeper_reports_missing_wires_with_back_off() -> None:
    keeper = WiringKeeper()
    w = Wire("ROBOT", "TRACKER")
    keeper.want(w)
    assert keeper.missing({"ROBOT"}, {}, now=0.0) == []  # the tracker is absent: wait
    assert keeper.status({"ROBOT"}, {})[0]["state"] == "waiting"
    assert keeper.missing({"ROBOT", "TRACKER"}, {}, now=0.0) == [w]
    keeper.failed(w, "refused", now=0.0)
    assert keeper.missing({"ROBOT", "TRACKER"}, {}, now=0.1) == []
    assert keeper.status({"ROBOT", "TRACKER"}, {})[0] == {
        "service": "ROBOT", "partner": "TRACKER", "state": "failing", "reason": "refused"}
    assert keeper.missing({"ROBOT", "TRACKER"}, {}, now=0.6) == [w]
    keeper.failed(w, "refused", now=0.6)
    assert keeper.missing({"ROBOT", "TRACKER"}, {}, now=1.2) == []  # 1 s after the 2nd failure
    keeper.reset_backoff("TRACKER")  # the tracker came back: try at once
    assert keeper.missing({"ROBOT", "TRACKER"}, {}, now=1.2) == [w]
    assert keeper.missing({"ROBOT", "TRACKER"}, {"ROBOT": {"TRACKER"}}) == []
    assert keeper.status({"ROBOT", "TRACKER"}, {"ROBOT": {"TRACKER"}})[0]["state"] == "in place"
    keeper.drop(w)
    assert keeper.missing({"ROBOT", "TRACKER"}, {}) == []


def test_reapply_asks_for_each_missing_wire_and_notes_the_answers() -> None:
    """The one re-apply of the controller and of ``cell load``: missing wires only, each
    answer noted (a refusal backs off, so the next round does not ask again at once)."""
    import asyncio

    keeper = WiringKeeper({Wire("R1", "TOOL"), Wire("R1", "CAMERA"), Wire("R2", "TOOL")})
    asked: list[Wire] = []

    async def ask(wire: Wire) -> tuple[bool, str]:
        asked.append(wire)
        return (wire.partner == "TOOL", "" if wire.partner == "TOOL" else "no such partner")

    alive = {"R1", "TOOL", "CAMERA"}  # R2 is absent: its wire waits
    partners = {"R1": set(), "TOOL": set(), "CAMERA": set()}
    results = asyncio.run(keeper.reapply(alive, partners, ask))
    assert results == [(Wire("R1", "CAMERA"), False, "no such partner"),
                       (Wire("R1", "TOOL"), True, "")]
    assert sorted(asked) == [Wire("R1", "CAMERA"), Wire("R1", "TOOL")]
    partners["R1"] = {"TOOL"}
    assert asyncio.run(keeper.reapply(alive, partners, ask)) == []  # CAMERA backs off
    status = {(s["service"], s["partner"]): s["state"] for s in keeper.status(alive, partners)}
    assert status == {("R1", "CAMERA"): "failing", ("R1", "TOOL"): "in place",
                      ("R2", "TOOL"): "waiting"}


def test_the_wires_in_place_are_each_partner_of_each_service_but_itself():
    """One reading of the wiring for the controller and `cell ls`/`save`."""
    partners = {"ROBOT": ["TRACKER", "COMPUTE", "ROBOT"], "TRACKER": [], "COMPUTE": ("TRACKER",)}
    assert wires_in_place(partners) == [Wire("COMPUTE", "TRACKER"), Wire("ROBOT", "COMPUTE"),
                                        Wire("ROBOT", "TRACKER")]
    assert wires_in_place({}) == []
