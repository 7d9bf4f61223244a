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
    assert (run["n"], run["phi"], run["trajectories"], run["snapshots"]) == (500, 0.56, 24, 480)
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


POOLED = ROOT / "docs" / "results" / "surrogate_3d" / "pooled_N500"


def test_the_pooled_table_scores_each_phi_on_its_own_test_snapshots():
    """Per φ, each fold's R² log η_r is that of its test snapshots at that φ alone (recomputed here from
    the saved predictions: 1 − SS_res / SS_tot of log10 η_r), and the runs are counted per φ."""
    bench = load_bench_script("surrogate_3d")
    pooled = bench.read_pooled(POOLED)
    counts = {phi: e["trajectories"] for phi, e in pooled["per_phi"].items()}
    assert counts == {0.5: 24, 0.53: 1, 0.55: 1, 0.56: 24, 0.57: 1, 0.58: 1}
    for k in range(5):
        with np.load(POOLED / f"fold{k}_predictions.npz") as saved:
            at = np.isclose(saved["phi"], 0.56)
            pred, true = np.log10(saved["pred"][at, 0]), np.log10(saved["true"][at, 0])
        expected = 1.0 - np.sum((pred - true) ** 2) / np.sum((true - true.mean()) ** 2)
        assert pooled["per_phi"][0.56]["test"]["r2_log_eta"][k] == pytest.approx(expected, rel=1e-9)
    single = pooled["per_phi"][0.53]["test"]["r2_log_eta"]
    assert np.isfinite(single).sum() == 1
    assert bench.pooled_cell(single, "r2_log_eta").endswith("(one fold)")


def test_a_pooled_folder_must_be_named_so():
    bench = load_bench_script("surrogate_3d")
    with pytest.raises(SystemExit, match="must be named pooled_N<N>"):
        bench.read_pooled(RUN)
