"""bench/surrogate_3d.py: the published table of the shipped 3D models is read from their training runs'
own fold metrics (the committed result folder of N500_phi0.56_3d), not retyped; a folder that is not a
finished run's is refused in one line."""

import json

import numpy as np
import pytest
from conftest import ROOT, load_bench_script

RUN = ROOT / "docs" / "results" / "surrogate_3d" / "N500_phi0.56"


def test_rows_come_from_the_folds_metrics():
    bench = load_bench_script("surrogate_3d")
    run = bench.read_run(RUN)
    assert (run["n"], run["phi"], run["trajectories"], run["snapshots"]) == (500, 0.56, 16, 320)
    folds = json.loads((RUN / "metrics.json").read_text())["folds"]
    values = [f["test/r2_log_eta"] for f in folds]
    assert bench.cell(folds, "test/r2_log_eta") == f"{np.mean(values):.3f} ± {np.std(values, ddof=1):.3f}"
    blocks = bench.section([run], "python -m bench.surrogate_3d RUN").blocks()
    (table,) = [b["table"] for b in blocks if "table" in b]
    network = [row for row in table["rows"] if row[1] == "graph network"]
    assert network == [
        [network[0][0], "graph network", *(bench.cell(folds, f"test/{k}") for k, _ in bench.METRICS)]
    ]
    assert "N500_phi0.56_3d" in "".join(b.get("text", "") for b in blocks)


def test_a_folder_that_is_not_a_finished_run_is_refused(tmp_path):
    bench = load_bench_script("surrogate_3d")
    with pytest.raises(SystemExit, match="must be named N<N>_phi"):
        bench.read_run(tmp_path)
    with pytest.raises(SystemExit, match="no metrics.json"):
        bench.read_run(tmp_path / "N500_phi0.5")
