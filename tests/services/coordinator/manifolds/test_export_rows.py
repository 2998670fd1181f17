"""The CSV rows of the fast export path equal csv.writer's for any text: a row whose texts
need quoting (comma, quote, line break) goes through the writer, the others are joined."""

from __future__ import annotations

import csv
import io

from graspscape.services.coordinator.manifolds.export import COLUMNS, csv_chunks


def _row(error: str, signature: str) -> tuple:
    cells = ["k", 0.1, 1e-05, 0.0, 1.0, None, 2.5, "held", "True", None, 3.0, 0.02, "A",
             "evaluated", "", "palm finger", "", signature, 0.25]
    cells += [None] * (len(COLUMNS) - len(cells) - 1) + [error]
    return tuple(cells)


def test_rows_equal_the_csv_writers_for_any_text() -> None:
    signature = '{"a":[1,2],"b":"x"}'
    rows = [_row(error, signature) for error in
            ("", "plain", "with, comma", 'with "quote"', "line\nbreak", "cr\ronly")]
    reference = io.StringIO()
    writer = csv.writer(reference, lineterminator="\n")
    writer.writerow(COLUMNS)
    writer.writerows(rows)
    quoted = '"' + signature.replace('"', '""') + '"'  # as the database hands it over
    special = (0, 0, 1, 1, 1, 1)  # as the database flags them (export._SPECIAL)
    at = COLUMNS.index("signature")
    fast = [(*r[:at], quoted, *r[at + 1:], flag) for r, flag in zip(rows, special, strict=True)]
    assert b"".join(csv_chunks(iter([fast[:2], fast[2:]]))) == reference.getvalue().encode()
