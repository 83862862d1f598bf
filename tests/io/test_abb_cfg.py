"""ABB's .cfg configuration files: written, read back (hypothesis), and every text that is
not one refused with the line (issue 37: the controller configuration plugcell ships)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.io.abb_cfg import WIDTH, CfgError, cfg_text, parse_cfg

_names = st.from_regex(r"[a-z][A-Za-z0-9_]{0,20}", fullmatch=True)
_values = st.one_of(
    st.integers(-10**6, 10**6),
    st.floats(-1e6, 1e6, allow_nan=False),
    st.text(st.characters(blacklist_characters='"\\\n\r', blacklist_categories=("Cs", "Cc")),
            max_size=30),
    st.just(True))


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.from_regex(r"[A-Z][A-Z0-9_]{0,15}", fullmatch=True),
                       st.lists(st.dictionaries(_names, _values, min_size=1, max_size=6),
                                max_size=3), max_size=3))
def test_what_is_written_reads_back(types) -> None:
    text = cfg_text("MOC", types)
    assert all(len(line) <= WIDTH for line in text.splitlines()
               if len(line.strip()) < WIDTH - 8)  # a single long pair cannot be split
    domain, version, back = parse_cfg(text.replace("\n", "\r\n"))  # as written to disk
    assert (domain, version) == ("MOC", (6, 0))
    assert set(back) == set(types)
    for name, instances in types.items():
        assert len(back[name]) == len(instances)
        for want, got in zip(instances, back[name], strict=True):
            assert list(got) == list(want)
            for attr, value in want.items():
                if isinstance(value, float):
                    assert got[attr] == pytest.approx(value, rel=1e-8, abs=1e-300)
                else:
                    assert got[attr] == value


def test_the_layout_is_robotstudios() -> None:
    text = cfg_text("SIOC", {"COM_TRP": [{"Name": "pcUC", "Type": "UDPUC",
                                          "RemoteAdress": "10.0.0.5",
                                          "RemotePortNumber": 6510, "LocalPortNumber": 0}]},
                    version=(6, 1))
    assert text.splitlines() == [
        "SIOC:CFG_1.0:6:1::", "#", "COM_TRP:", "",
        '      -Name "pcUC" -Type "UDPUC" -RemoteAdress "10.0.0.5"\\',
        "      -RemotePortNumber 6510 -LocalPortNumber 0", "", "#"]


@pytest.mark.parametrize(("text", "why"), [
    ("", "line 1: expected a header"),
    ("MOC:CFG_1.0::\n", "line 1: expected a header"),
    ("MOC:CFG_1.0:6:0::\n      -name \"x\"\n", "line 2: an instance before any type"),
    ("MOC:CFG_1.0:6:0::\nEXT:\n\n      -name \"x\"\\", "line 4: the instance is continued"),
    ("MOC:CFG_1.0:6:0::\nEXT:\n\n      name x\n", "line 4: expected a type 'NAME:' or an "
                                                  "instance"),
    ("MOC:CFG_1.0:6:0::\nEXT:\n\n      -name \"x\n", "line 4: cannot read"),
    ("MOC:CFG_1.0:6:0::\nEXT:\n\n      -a 1 -a 2\n", "line 4: -a given twice"),
    ("MOC:CFG_1.0:6:0::\nEXT:\n\n      -a 1 2\n", "line 4: expected -attribute, got '2'"),
])
def test_a_text_that_is_no_cfg_is_refused_with_the_line(text, why) -> None:
    with pytest.raises(CfgError, match=why.replace("(", r"\(")):
        parse_cfg(text)


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=200))
def test_any_text_reads_or_is_refused_with_a_cfg_error(text) -> None:
    try:
        parse_cfg("MOC:CFG_1.0:6:0::\nEXT_MOTION_DATA:\n" + text)
    except CfgError as exc:
        assert str(exc).startswith("line ")


@pytest.mark.parametrize(("types", "why"), [
    ({"ext": []}, "a domain or type is upper-case"),
    ({"EXT": [{"name": 'a"b'}]}, "a string cannot hold quotes"),
    ({"EXT": [{"gain": float("nan")}]}, "not a finite number"),
    ({"EXT": [{"flag": False}]}, "a flag is True"),
    ({"EXT": [{"bad-name": 1}]}, "attribute 'bad-name'"),
])
def test_what_cannot_be_written_is_refused(types, why) -> None:
    with pytest.raises(CfgError, match=why):
        cfg_text("MOC", types)
