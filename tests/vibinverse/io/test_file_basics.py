"""Text cells of the CSV tables the verbs write (`csv_cell`)."""

from __future__ import annotations

import csv
import io

import pytest

from vibinverse.io.file_basics import csv_cell


@pytest.mark.parametrize("text", ['=HYPERLINK("x")', "+1+1", "-2+3", "@SUM(A1)", "\tx", "\rx"])
def test_a_text_cell_is_never_a_formula(text):
    cell = csv_cell(text)
    assert cell == "'" + text
    buf = io.StringIO()
    csv.writer(buf).writerow([cell])
    assert not next(csv.reader(io.StringIO(buf.getvalue())))[0].startswith(("=", "+", "-", "@", "\t", "\r"))


@pytest.mark.parametrize("value", [-3.5, 0, 7, "ok", "vibration", None])
def test_numbers_and_plain_text_pass_through(value):
    assert csv_cell(value) == value
