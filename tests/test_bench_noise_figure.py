"""bench/noise_figure.py keeps the numbers of the position-noise figure from the noise records of
bench/snapshot_noise.py (JSON, one per scored run), which hold the published tables' numbers, and refuses
a missing record in one line."""

import json
import re
import shutil

import pytest
from conftest import load_bench_script

from bench import figures


def test_the_noise_records_hold_the_published_tables_and_the_figure_record_their_numbers():
    bench = load_bench_script("noise_figure")
    page = (bench.ROOT / "docs" / "validation" / "position_noise.md").read_text()
    for _, exact, imaging, extra in bench.PANELS:
        runs = dict.fromkeys(run for run, _, _ in bench.curves(exact, imaging, extra))
        eps, rows = bench.run_records(bench.RECORDS, runs)
        assert eps == [0.0, 0.001, 0.003, 0.01, 0.03, 0.05]
        for run, predictor, _ in bench.curves(exact, imaging, extra):
            for metric, _ in bench.TARGETS:
                values = rows[(run, predictor, metric)]
                assert len(values) == len(eps)
                # the published page shows the same numbers in the run's table
                cells = " | ".join(f"{v:.3f}" for v in values)
                assert f"| {predictor} | {metric} | {cells} |" in page, (run, predictor, metric)
    # the figure's record holds the numbers these records give
    assert bench.figure_data() == figures.figure_data(bench.FIGURE)


def test_noise_figure_names_a_missing_or_damaged_record(tmp_path):
    bench = load_bench_script("noise_figure")
    records = tmp_path / "records"
    shutil.copytree(bench.RECORDS, records)
    (records / "N400_phi0.70.json").unlink()
    with pytest.raises(SystemExit, match=re.escape("N400_phi0.70.json")):
        bench.figure_data(records)
    (records / "N400_phi0.70.json").write_text("{cut")
    with pytest.raises(SystemExit, match="not a readable result record of N400_phi0.70"):
        bench.figure_data(records)
    json.loads((bench.RECORDS / "N400_phi0.70.json").read_text())  # the committed one untouched
