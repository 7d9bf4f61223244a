"""bench/snapshot_noise.py end to end on a tiny training run: every predictor row, finite scores, the
lookup independent of the noise, the exact network degraded by it."""

import json
import re

from conftest import load_bench_script, train_tiny_fold


def test_noise_bench_scores_every_predictor_on_a_tiny_run(tiny_files, tmp_path, capsys):
    run_dir = train_tiny_fold(
        tiny_files,
        tmp_path,
        "data.split=grouped",  # the bench scores whole held-out trajectories
    )
    bench = load_bench_script("snapshot_noise")
    args = [str(run_dir), "--folds", "0", "--noise", "0", "0.01", "--no-write"]
    args += ["--cache-dir", str(tmp_path / "cache"), "--relax-strain", "0.002", "--relax-every", "5"]
    assert bench.main(args) == 0
    text = capsys.readouterr().out
    for predictor in (
        "graph network",
        "trees on descriptors",
        "physics:",
        "lookup: mean at (φ, σ)",
        "relaxed",
    ):
        assert predictor in text, predictor
    lookup = [line for line in text.splitlines() if line.startswith("| lookup") and "R² log η_r" in line]
    cells = re.findall(r"\| (-?[\d.]+|nan) ", lookup[0] + " ")
    assert cells[0] == cells[1]  # the lookup reads no positions
    assert "R² log μ_eff" in text


def test_noise_bench_records_each_runs_table_for_the_figure(tiny_files, tmp_path, capsys, monkeypatch):
    """Without --no-write the bench keeps each run's numbers as a JSON record (what
    bench/noise_figure.py draws): the record holds the printed table cell for cell, and the command."""
    run_dir = train_tiny_fold(tiny_files, tmp_path, "data.split=grouped")
    bench = load_bench_script("snapshot_noise")
    monkeypatch.setenv("RHEOGRAPH_BENCH_OUT", str(tmp_path / "sections"))  # not the docs page
    monkeypatch.setattr(bench, "RECORDS", tmp_path / "records")
    args = [str(run_dir), "--folds", "0", "--noise", "0", "0.01", "--cache-dir", str(tmp_path / "cache")]
    assert bench.main(args) == 0
    text = capsys.readouterr().out
    record = json.loads((tmp_path / "records" / f"{run_dir.name}.json").read_text())
    assert record["noise"] == [0.0, 0.01] and "python -m bench.snapshot_noise" in record["command"]
    table = [line for line in text.splitlines() if line.startswith("| graph network | R² log η_r |")]
    cells = [float(c) for c in table[0].strip("| ").split("|")[2:]]
    assert record["predictors"]["graph network"]["R² log η_r"] == cells
    # the section's record holds the table as rows of cells, with the command
    section = json.loads((tmp_path / "sections" / "snapshot_noise.json").read_text())
    rows = next(b["table"]["rows"] for b in section["blocks"] if "table" in b)
    assert [float(c) for c in rows[0][2:]] == record["predictors"][rows[0][0]][rows[0][1]]
    assert section["command"] == record["command"].strip("`")
    figure = load_bench_script("noise_figure")
    eps, rows = figure.run_records(tmp_path / "records", [run_dir.name])
    assert eps == [0.0, 0.01] and rows[(run_dir.name, "graph network", "R² log η_r")] == cells
