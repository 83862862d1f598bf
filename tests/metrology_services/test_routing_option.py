"""The option clauses that name a requester and the destinations of output data (9.3)."""

from __future__ import annotations

import numpy as np
import pytest

from plugcell.devices.tracker.routing import (
    OptionError,
    ProcessOption,
    Route,
    fit_to_declaration,
    format_option,
    parse_option,
)


def test_a_plain_option_has_no_clauses():
    assert parse_option("tr2euler") == ProcessOption("tr2euler")
    assert parse_option("") == ProcessOption("")


def test_routes_and_requester_are_read_and_written_back():
    text = "tr2euler; to=COMPUTE:Set Matrix:mT:append; to=LOG:Append; for=ROBOT1"
    opt = parse_option(text)
    assert opt.device == "tr2euler"
    assert opt.routes == (Route("COMPUTE", "Set Matrix", "mT:append"), Route("LOG", "Append", ""))
    assert opt.on_behalf_of == "ROBOT1"
    assert parse_option(format_option(opt.device, opt.routes, opt.on_behalf_of)) == opt
    assert parse_option(";to=COMPUTE:Set Matrix:mT").device == ""


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("tr2rpy; to=COMPUTE", "expected SERVICE:Command"),
        ("tr2rpy; to=bad name:Set Matrix:x", "route service name"),
        ("tr2rpy; to=COMPUTE::x", "1 to 64 characters"),
        ("tr2rpy; via=COMPUTE", "unknown option clause 'via'"),
        ("tr2rpy; COMPUTE", "expected to=SERVICE"),
        ("x; for=A; for=B", "more than one for="),
        ("x; for=../etc", "for= name"),
        ("x" + "; to=A:B:c" * 5, "5 routes, at most 4"),
    ],
)
def test_malformed_clauses_are_refused_with_the_reason(text, reason):
    with pytest.raises(OptionError, match=reason):
        parse_option(text)


def test_output_is_fitted_to_the_destinations_declared_shape():
    v = np.arange(6.0)
    assert fit_to_declaration(v, (-1, -1)).shape == (1, 6)  # a vector is one row
    assert fit_to_declaration(v.reshape(1, 6), (6,)).shape == (6,)  # one row is a vector
    assert fit_to_declaration(v, ()).shape == (6,)  # any shape: untouched
    assert fit_to_declaration(np.float64(2.0), (1,)).shape == (1,)
    m = np.ones((2, 3))
    assert fit_to_declaration(m, (6,)) is m  # not ours to judge: the destination refuses
