"""Report records kept as compact JSON, and the report written from them."""

from __future__ import annotations

import json
from collections.abc import Iterable

from lodconvert.report import Records, report_text


def test_records_read_back_as_added_and_the_report_holds_each_on_a_line_of_its_own() -> None:
    added = [{"id": "a", "levels": [{"name": "LOD2", "count": 3}]}, {"id": "b", "levels": []}]
    records = Records(added)
    assert len(records) == 2 and list(records) == added
    assert records[1] == added[1] and records[:1] == added[:1]
    records[0]["id"] = "changed"  # a read gives a copy; the records stay as added
    assert records[0]["id"] == "a"
    for objects in (records, Records()):
        report = {"input": "x.gml", "objects": objects, "totals": {"objects": len(objects)}}
        text = "".join(report_text(report))
        assert json.loads(text) == {**report, "objects": list(objects)}
        lines = text.splitlines()
        assert lines[:2] == ["{", '  "input": "x.gml",'] and lines[-2:] == ["  }", "}"]
    # each record is one line of compact JSON, indented as the report's other values
    assert lines_of(report_text({"objects": records})) == [
        "{",
        '  "objects": [',
        '    {"id":"a","levels":[{"name":"LOD2","count":3}]},',
        '    {"id":"b","levels":[]}',
        "  ]",
        "}",
    ]


def lines_of(pieces: Iterable[str]) -> list[str]:
    return "".join(pieces).splitlines()
