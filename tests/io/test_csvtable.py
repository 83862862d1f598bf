"""The CSV tables under every text file format: line numbers of records, any text."""

from __future__ import annotations

import csv
import io

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.io.csvtable import table_rows
from plugcell.io.plans import PlanFileError, parse_plan


def test_line_numbers_count_lines_not_records():
    # a quoted cell spanning several lines: later rows keep their line numbers
    text = 'j1,j2\n"1\n",2\n\n# comment\n5,6\n'
    assert [n for n, _ in table_rows(text, "t.csv", ValueError)] == [1, 2, 6]
    with pytest.raises(PlanFileError, match=r"^p\.csv: line 5, column 'j2': not a number"):
        parse_plan('j1,j2\n"1\n\n",2\n1,abc\n', name="p.csv")


_cell = st.text(alphabet=st.sampled_from(list('ab1 ,"\n')), min_size=1, max_size=6).filter(
    lambda c: c.strip() and not c.lstrip().startswith("#"))


@settings(max_examples=100, deadline=None)
@given(st.lists(st.lists(_cell, min_size=1, max_size=3), min_size=1, max_size=6),
       st.lists(st.sampled_from(["", "\n", "# c\n"]), min_size=6, max_size=6))
def test_each_row_is_numbered_by_the_line_it_starts_on(records, gaps):
    text, starts = "", []
    for record, gap in zip(records, gaps, strict=False):
        text += gap
        starts.append(text.count("\n") + 1)
        out = io.StringIO()
        csv.writer(out, lineterminator="\n").writerow(record)
        text += out.getvalue()
    rows = table_rows(text, "t.csv", ValueError)
    assert [r for _, r in rows] == records
    assert [n for n, _ in rows] == starts
