"""Report records kept as compact JSON, and the report written from them."""

from __future__ import annotations

import json

from lodconvert.report import Records, report_text


def test_records_read_back_as_added_and_the_report_is_json_dumps_indented() -> None:
    added = [{"id": "a", "levels": [{"name": "LOD2", "count": 3}]}, {"id": "b", "levels": []}]
    records = Records(added)
    assert len(records) == 2 and list(records) == added
    assert records[1] == added[1] and records[:1] == added[:1]
    records[0]["id"] = "changed"  # a read gives a copy; the records stay as added
    assert records[0]["id"] == "a"
    for objects in (records, Records()):
        report = {"input": "x.gml", "objects": objects, "totals": {"objects": len(objects)}}
        expected = json.dumps({**report, "objects": list(objects)}, indent=2) + "\n"
        assert "".join(report_text(report)) == expected
