"""The published tables against their JSON records: every marked section of the docs pages is what its
record under docs/results/bench/ gives (what ``python -m bench.render --check`` checks with the figures,
tests/test_bench_figures.py), and a changed number in a record is caught, naming its section."""

import json
import re
import shutil

from bench import render
from bench.records import DOCS, RECORDS, load_records, render_section

MARKER = re.compile(r"<!-- ([\w.-]+):start -->")


def test_every_page_holds_what_its_records_give():
    records = load_records()
    assert len(records) >= 40
    assert render.differences(records) == []


def test_every_marked_section_has_one_record_and_every_record_a_command():
    records = {r["section"]: r for r in load_records()}
    marked = {}
    for page in DOCS.rglob("*.md"):
        for name in MARKER.findall(page.read_text()):
            assert name not in marked, f"section {name} is marked on two pages"
            marked[name] = str(page.relative_to(DOCS))
    assert set(marked) == set(records)
    for name, record in records.items():
        assert record["page"] == marked[name]
        assert record["command"] is None or record["command"].startswith(("python", "OMP_", "PYTHONPATH"))
    # every section that quotes a command quotes its record's
    for record in records.values():
        if record["command"]:
            assert record["command"] in render_section(record)


def test_a_changed_number_in_a_record_fails_the_check_and_names_its_section(tmp_path):
    records, docs = tmp_path / "records", tmp_path / "docs"
    shutil.copytree(RECORDS, records)
    for record in load_records():
        target = docs / record["page"]
        target.parent.mkdir(parents=True, exist_ok=True)
        if not target.exists():
            shutil.copy(DOCS / record["page"], target)
    assert render.differences(load_records(records), docs) == []
    path = records / "simulate_speed.json"
    record = json.loads(path.read_text())
    table = next(b["table"] for b in record["blocks"] if "table" in b)
    table["rows"][0][5] = str(float(table["rows"][0][5]) + 0.1)  # wall s/strain of the first row
    path.write_text(json.dumps(record))
    assert render.differences(load_records(records), docs) == [
        "validation/speed.md: section simulate_speed differs from its record"
    ]
    # rendering puts the record's number on the page, and the check passes again
    assert render.render(load_records(records), docs) == 1
    assert table["rows"][0][5] in (docs / "validation" / "speed.md").read_text()
    assert render.differences(load_records(records), docs) == []
