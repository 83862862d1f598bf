"""plugcell.io.text_files.read_text: a UTF-8 file's text, or the format's error naming the
file and the cause."""

from __future__ import annotations

import pytest

from plugcell.io.text_files import read_text


class FormatError(ValueError):
    pass


def test_the_text_of_a_utf8_file(tmp_path):
    f = tmp_path / "a.csv"
    f.write_bytes("x,y\n1,2 µm\n".encode())
    assert read_text(f, FormatError) == "x,y\n1,2 µm\n"


@pytest.mark.parametrize(("make", "cause"), [
    (lambda p: None, "no such file"),
    (lambda p: p.write_bytes(b"x\n\xff\xfe\n"), "not a UTF-8 text file (invalid start byte)"),
    (lambda p: p.mkdir(), "Is a directory"),
])
def test_each_cause_is_named_in_the_formats_error(tmp_path, make, cause):
    f = tmp_path / "a.csv"
    make(f)
    with pytest.raises(FormatError) as ei:
        read_text(f, FormatError)
    assert str(ei.value) == f"{f}: cannot read: {cause}"
    with pytest.raises(FormatError, match=r"^a\.csv: cannot read: "):
        read_text(f, FormatError, name="a.csv")
