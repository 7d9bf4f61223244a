"""The published tables against their JSON records: every marked section of the docs pages is what its
record under docs/results/bench/ gives (``python -m bench.render --check``, ``make bench``), and a changed
number in a record is caught, naming its section."""

import json
import re
import shutil

import pytest

from bench import gpu_report, render, scheme_near_jamming, time_step_convergence
from bench.records import DOCS, RECORDS, ROOT, as_blocks, load_records, render_section
from rheograph.io.pages import render_blocks

MARKER = re.compile(r"<!-- ([\w.-]+):start -->")


def words(text: str) -> str:
    """``text`` with its line breaks, shell continuations and runs of spaces as single spaces: a command
    wrapped on a page is the same command."""
    return " ".join(text.replace("\\\n", " ").split())


def test_every_page_holds_what_its_records_give():
    records = load_records()
    assert len(records) >= 72
    assert render.differences(records) == []
    assert render.main(["--check"]) == 0


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
            assert words(record["command"]) in words(render_section(record)), record["section"]


@pytest.mark.parametrize(
    "section, cell",
    [
        ("simulate_speed", (0, 5)),  # wall s/strain of the first row
        ("cholmod_handover", (1, 2)),  # an indented table: full-matrix ms at N = 2000
        ("time_step_convergence", (0, 7)),  # wall s/strain of the first row
        ("pooled_grouped", (5, 1)),  # a cell with its ± (pooled R² log η_r at φ = 0.80)
    ],
)
def test_a_changed_number_in_a_record_fails_the_check_and_names_its_section(tmp_path, capsys, section, cell):
    records, docs = tmp_path / "records", tmp_path / "docs"
    shutil.copytree(RECORDS, records)
    for record in load_records():
        target = docs / record["page"]
        target.parent.mkdir(parents=True, exist_ok=True)
        if not target.exists():
            shutil.copy(DOCS / record["page"], target)
    args = ["--check", "--records", str(records), "--docs", str(docs)]
    assert render.main(args) == 0
    path = records / f"{section}.json"
    record = json.loads(path.read_text())
    table = next(b["table"] for b in record["blocks"] if "table" in b)
    row, col = cell
    number, _, rest = table["rows"][row][col].partition(" ")
    table["rows"][row][col] = " ".join(filter(None, [f"{float(number) + 0.1:g}", rest]))
    path.write_text(json.dumps(record))
    capsys.readouterr()
    assert render.main(args) == 1
    assert f"{record['page']}: section {section} differs from its record" in capsys.readouterr().err
    # rendering puts the record's number on the page, and the check passes again
    assert render.main(args[1:]) == 0
    assert table["rows"][row][col] in (docs / record["page"]).read_text()
    assert render.main(args) == 0


def test_the_2d_flow_curve_tables_are_those_the_flow_curve_command_wrote():
    """The page quotes both tables of docs/figures/flow_curves.md, which its command writes."""
    (record,) = [r for r in load_records() if r["section"] == "flow_curves_2d"]
    written = (DOCS / "figures" / "flow_curves.md").read_text()
    tables = [b for b in record["blocks"] if "table" in b]
    assert len(tables) == 2
    assert all(render_blocks([t]) in written for t in tables)


def test_the_gpu_tables_are_what_gpu_report_draws_from_the_committed_measurement():
    (record,) = [r for r in load_records() if r["section"] == "gpu_cpu"]
    measured = json.loads((DOCS / "results" / "gpu" / "cpu.json").read_text())
    assert gpu_report.render(measured).rstrip("\n") in render_section(record)


def record_blocks(section: str) -> list[dict]:
    (record,) = [r for r in load_records() if r["section"] == section]
    return record["blocks"]


def test_the_time_step_tables_are_what_their_benchmarks_draw_from_the_committed_runs():
    """The two benchmarks' ``plot`` write these records; from the committed runs they give them unchanged."""
    rows = time_step_convergence.collect()
    stresses = sorted({r["stress"] for r in rows})
    lfdem = time_step_convergence.lfdem_rows(
        ROOT / "data/lfdem_reference/lfdem_phi0.76", 0.76, 400, stresses, 0.5
    )
    assert as_blocks(time_step_convergence.section(rows + lfdem)) == record_blocks("time_step_convergence")
    near_jamming = scheme_near_jamming.section(scheme_near_jamming.collect(0.80))
    assert as_blocks(near_jamming) == record_blocks("scheme_near_jamming")
