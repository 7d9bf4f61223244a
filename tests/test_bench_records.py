"""The published tables against their JSON records: every marked section of the docs pages is what its
record under docs/results/bench/ gives (what ``python -m bench.render --check`` checks with the figures,
tests/test_bench_figures.py), and a changed number in a record is caught, naming its section."""

import argparse
import itertools
import json
import re
import shutil
from pathlib import Path

import pytest

from bench import (
    gpu_report,
    microscope,
    physics_rows,
    render,
    scheme_near_jamming,
    surrogate_per_phi,
    surrogate_uncertainty,
    time_step_convergence,
)
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
def test_a_changed_number_in_a_record_fails_the_check_and_names_its_section(tmp_path, section, cell):
    records, docs = tmp_path / "records", tmp_path / "docs"
    shutil.copytree(RECORDS, records)
    for record in load_records():
        target = docs / record["page"]
        target.parent.mkdir(parents=True, exist_ok=True)
        if not target.exists():
            shutil.copy(DOCS / record["page"], target)
    assert render.differences(load_records(records), docs) == []
    path = records / f"{section}.json"
    record = json.loads(path.read_text())
    table = next(b["table"] for b in record["blocks"] if "table" in b)
    row, col = cell
    number, _, rest = table["rows"][row][col].partition(" ")
    table["rows"][row][col] = " ".join(filter(None, [f"{float(number) + 0.1:g}", rest]))
    path.write_text(json.dumps(record))
    assert render.differences(load_records(records), docs) == [
        f"{record['page']}: section {section} differs from its record"
    ]
    # rendering puts the record's number on the page, and the check passes again
    assert render.render(load_records(records), docs) == 1
    assert table["rows"][row][col] in (docs / record["page"]).read_text()
    assert render.differences(load_records(records), docs) == []


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


def record_of(section: str) -> dict:
    (record,) = [r for r in load_records() if r["section"] == section]
    return record


def as_json(data):
    """``data`` as its JSON record holds it (tuples as lists)."""
    return json.loads(json.dumps(data))


def test_the_time_step_tables_are_what_their_benchmarks_draw_from_the_committed_runs():
    """The two benchmarks' ``plot`` write these records, the numbers of their figures included; from the
    committed runs they give them unchanged."""
    rows = time_step_convergence.collect()
    stresses = sorted({r["stress"] for r in rows})
    lfdem = time_step_convergence.lfdem_rows(
        ROOT / "data/lfdem_reference/lfdem_phi0.76", 0.76, 400, stresses, 0.5
    )
    record = record_of("time_step_convergence")
    assert as_blocks(time_step_convergence.section(rows + lfdem)) == record["blocks"]
    assert as_json(time_step_convergence.figure_data(rows + lfdem, 0.76, 400)) == record["figure"]
    runs = scheme_near_jamming.collect(0.80)
    record = record_of("scheme_near_jamming")
    assert as_blocks(scheme_near_jamming.section(runs)) == record["blocks"]
    assert as_json(scheme_near_jamming.figure_data(runs, 0.80)) == record["figure"]


def test_the_per_phi_table_is_what_its_benchmark_draws_from_the_committed_runs():
    """bench.surrogate_per_phi keeps its table as cells; from the committed runs' metrics (nothing
    retrained) it gives its record unchanged."""
    (record,) = [r for r in load_records() if r["section"] == "surrogate_per_phi"]
    runs = DOCS / "results" / "surrogate_per_phi"
    results = {}
    for split, n, phi in itertools.product(
        ("grouped", "random"), (400, 2000), (0.7, 0.72, 0.74, 0.76, 0.78, 0.8)
    ):
        run = runs / (f"N{n}_phi{phi:g}" + ("" if split == "grouped" else f"_{split}"))
        if (run / "metrics.json").exists():
            folds = json.loads((run / "metrics.json").read_text())["folds"]
            results[(split, n, phi)] = (folds, float((run / "train_minutes.txt").read_text()), False)
    args = argparse.Namespace(epochs=60, overrides=[], split=["grouped", "random"])
    assert surrogate_per_phi.command(results, args) == record["command"]
    assert as_blocks(surrogate_per_phi.section(results, args)) == record["blocks"]
    assert as_json(surrogate_per_phi.figure_data(results)) == record["figure"]


def test_the_physics_rows_network_scores_are_those_of_the_committed_runs():
    """Each run's graph-network row is its committed metrics' test-fold mean (the physics rows need the
    graphs rebuilt: not rerun here), and the rows give the record's section."""
    (record,) = [r for r in load_records() if r["section"] == "physics_rows"]
    rows = next(b["table"]["rows"] for b in record["blocks"] if "table" in b)
    network = {row[0]: row for row in rows if row[1] == "graph network"}
    runs = [Path(run) for run in record["command"].split()[3:]]
    assert len(network) == len(runs)
    for run in runs:
        name = f"{run.parent.name}/{run.name}"
        phys = {
            n: dict.fromkeys(("r2_log_eta", "r2_log_pressure", "r2_z_mu"), 0.5) for n in physics_rows.ROWS
        }
        assert physics_rows.run_rows(name, physics_rows.network_scores(ROOT / run), phys)[0] == network[name]
    assert as_blocks(physics_rows.section(rows, record["command"])) == record["blocks"]


def test_the_uncertainty_record_is_a_table_and_its_benchmark_lays_it_out():
    """Its predictions of the unseen seed are not kept, so the layout is checked with numbers that print as
    published (34.5 ms a snapshot, 0.9 CPU s a decorrelated snapshot, 25×)."""
    (record,) = [r for r in load_records() if r["section"] == "surrogate_uncertainty"]
    (table,) = [b["table"] for b in record["blocks"] if "table" in b]
    assert [row[0] for row in table["rows"]] == ["η_r", "Π", "Z_μ"]
    lead = record["blocks"][0]["text"].split("\n")[0]
    out = surrogate_uncertainty.section(lead, table["rows"], 0.0345, 0.86, record["command"])
    assert as_blocks(out) == record["blocks"]


def test_the_microscope_section_is_what_its_benchmark_draws_from_its_committed_result():
    """bench.microscope writes the tutorial's record from its run's result, committed beside it."""
    (record,) = [r for r in load_records() if r["section"] == "microscope_bench"]
    result = json.loads((DOCS / "results" / "microscope" / "N400_phi0.76_imaging.json").read_text())
    assert as_blocks(microscope.section(result, result["command"])) == record["blocks"]
