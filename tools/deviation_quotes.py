"""Check that docs/deviations.md quotes the manuals verbatim.

``python -m tools.deviation_quotes --specs DIR`` reads the manuals' plain text (the files
the specs README indexes: ``000_*.txt`` DYN2, ``002_*.txt`` DYN CAN, ``003_*.txt`` DYN5,
``004_*.txt`` YZ-AIM) and checks every quoted passage ("...") of each table row's "The
manual's words" cell against the manual the row names. Prints one line per quote that is not
found and exits 1 if there is one. The manuals are not in the repository, so the suite checks
the tables' shape (tests/docs/test_deviations.py) and this check runs where they are.

Verbatim means the manual's words, punctuation and case; what the text conversion added is
ignored on both sides: runs of white space (table tabs, line breaks), a space before
punctuation, Markdown escapes and emphasis, LaTeX math (``$\\pm 5$`` reads ``±5``), curly
quotes, the micro sign's two code points.
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from pathlib import Path

DEVIATIONS = Path(__file__).resolve().parent.parent / "docs" / "deviations.md"

#: A row's manual, by the first of these words in its "Drive (manual)" cell: the spec file's
#: number in the specs directory.
MANUALS: tuple[tuple[str, str], ...] = (
    ("DYN CAN", "002"), ("DYN5", "003"), ("EtherNet/IP", "003"), ("YZ-AIM", "004"),
    ("EasyCan", "004"), ("DYN2", "000"), ("DC2", "001"),
)
#: A quote ends at a double quote followed by the cell's end or what separates quotes.
QUOTE = re.compile(r'"(.+?)"(?=\s*(?:[;,()]|$|—|and\b))')
_LATEX = (("\\leq", "≤"), ("\\geq", "≥"), ("\\times", "×"), ("\\mu", "µ"), ("\\pm", "±"),
          ("\\circ", "°"), ("\\%", "%"))


@dataclass(frozen=True)
class Row:
    table: str  # the heading above the table
    cells: tuple[str, ...]

    @property
    def manual(self) -> str | None:
        """The spec file number the row's first cell names (None: none)."""
        found = [(self.cells[0].find(word), number) for word, number in MANUALS
                 if word in self.cells[0]]
        return min(found)[1] if found else None

    @property
    def quotes(self) -> list[str]:
        return QUOTE.findall(self.cells[1]) if len(self.cells) > 1 else []


def normalise(text: str) -> str:
    """The words as printed: conversion artefacts and spacing removed (module docstring)."""
    for macro, char in _LATEX:
        text = re.sub(re.escape(macro) + r"(?![A-Za-z])\s*", char, text)
    text = re.sub(r"\\text\{([^}]*)\}", r"\1", text)
    text = text.replace("$", "").replace("**", "").replace("\\_", "_").replace("\\|", "|")
    text = (text.replace("“", '"').replace("”", '"').replace("’", "'").replace("‘", "'")
            .replace("μ", "µ"))
    text = re.sub(r"\s+", " ", text)
    text = re.sub(r"\s+([.,;:)])", r"\1", text)
    return re.sub(r"\(\s+", "(", text).strip()


def table_rows(markdown: str) -> list[Row]:
    """Every body row of every table, with the heading it sits under."""
    rows: list[Row] = []
    heading = ""
    header_seen = False
    for line in markdown.splitlines():
        if line.startswith("#"):
            heading, header_seen = line.lstrip("# ").strip(), False
            continue
        if not line.startswith("|"):
            header_seen = False
            continue
        cells = tuple(c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1])
        if all(set(c) <= set("-: ") for c in cells):
            continue  # the separator line
        if not header_seen:
            header_seen = True  # the header line
            continue
        rows.append(Row(heading, cells))
    return rows


def load_manuals(specs: Path) -> dict[str, str]:
    return {path.name[:3]: normalise(path.read_text(encoding="utf-8"))
            for path in sorted(specs.glob("[0-9][0-9][0-9]_*.txt"))}


def missing_quotes(rows: list[Row], manuals: dict[str, str]) -> list[str]:
    """One line per quote its row's manual does not hold."""
    out = []
    for row in rows:
        manual = row.manual
        text = manuals.get(manual or "")
        for quote in row.quotes:
            if text is None or normalise(quote) not in text:
                out.append(f"{row.cells[0]}: not in manual {manual}: \"{quote}\"")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--specs", type=Path, required=True,
                        help="directory of the manuals' plain text (000_*.txt ...)")
    parser.add_argument("--doc", type=Path, default=DEVIATIONS)
    args = parser.parse_args(argv)
    rows = table_rows(args.doc.read_text(encoding="utf-8"))
    problems = missing_quotes(rows, load_manuals(args.specs))
    for line in problems:
        print(line)
    print(f"{sum(len(r.quotes) for r in rows)} quote(s) in {len(rows)} row(s), "
          f"{len(problems)} not found", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
