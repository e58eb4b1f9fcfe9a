"""docs/deviations.md quotes the manual in every row (issue 34): each table row names its
manual and quotes it; the quote checker (tools/deviation_quotes.py, run against the manuals'
text, which is not in the repository) reads the conversion artefacts as printed words and
finds a paraphrase missing."""

from __future__ import annotations

import pytest

from tools.deviation_quotes import DEVIATIONS, Row, missing_quotes, normalise, table_rows

ROWS = table_rows(DEVIATIONS.read_text(encoding="utf-8"))


def test_both_tables_are_read() -> None:
    tables = {row.table for row in ROWS}
    assert tables == {"Deviations on purpose", "Not simulated"}
    not_simulated = " ".join(r.cells[0] for r in ROWS if r.table == "Not simulated")
    for function in (1, 2, 4, 7, 9):  # the YZ-AIM special functions the motor only stores
        assert f"YZ-AIM special function {function} " in not_simulated


@pytest.mark.parametrize("row", ROWS, ids=lambda r: r.cells[0][:40])
def test_every_row_names_its_manual_quotes_it_and_says_why(row: Row) -> None:
    assert len(row.cells) == 4
    assert row.manual is not None, "the first cell names no manual"
    assert row.quotes, "the manual's words are not quoted"
    assert row.cells[2] and len(row.cells[3]) > 20


def test_normalise_reads_the_text_conversion_as_printed() -> None:
    manual = ("Motor absolute position range is  $\\pm 134,217,728$ . If position exceeds\n"
              "this\tposition **will** roll back. LINE\\_NUM after  $\\leq 300\\mu\\text{s}$ .")
    assert normalise(manual) == ("Motor absolute position range is ±134,217,728. If position "
                                 "exceeds this position will roll back. LINE_NUM after "
                                 "≤300µs.")


def test_a_paraphrase_is_reported_and_the_quote_passes() -> None:
    manuals = {"003": normalise("The servo drive will not exceed the speed set by this "
                                "parameter when in torque mode.")}
    quoted = Row("t", ("DYN5 0x27 (4.4)", '"The servo drive will not exceed the speed set by '
                       'this parameter when in torque mode."', "x", "y"))
    paraphrased = Row("t", ("DYN5 0x27 (4.4)", '"the drive stays below the limit" (4.4)', "x",
                            "y"))
    assert missing_quotes([quoted], manuals) == []
    assert len(missing_quotes([paraphrased], manuals)) == 1
