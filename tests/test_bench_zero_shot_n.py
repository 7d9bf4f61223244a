"""bench/zero_shot_n.py: the per-snapshot listing is the table's own predictions (R² recomputed from it
agrees with the row), and a glob that matches nothing ends in one line."""

import numpy as np
import pytest
from conftest import ROOT, load_bench_script

RUN = ROOT / "data" / "paper" / "multirun" / "N400_phi0.76_s10_seed1_d0.002_implicit" / "trajectory.h5"


def test_per_snapshot_ratios_reproduce_the_tables_r2():
    bench = load_bench_script("zero_shot_n")
    snapshots = []
    (row,) = bench.score(["N400_phi0.76"], [RUN], min_strain=1.0, per_snapshot=snapshots)
    assert len(snapshots) == row["snapshots"] > 10
    assert all(s["strain"] >= 1.0 and s["model"] == "N400_phi0.76" for s in snapshots)
    # R² of log η_r from the listing: the ratios are the table's own predictions, snapshot by snapshot
    log_err = np.log([s["eta_ratio"] for s in snapshots])
    log_true = np.log([s["eta"] for s in snapshots])
    r2 = 1.0 - np.sum(log_err**2) / np.sum((log_true - log_true.mean()) ** 2)
    assert r2 == pytest.approx(row["r2_log_eta"], abs=1e-6)

def test_a_glob_matching_nothing_is_one_line(capsys):
    bench = load_bench_script("zero_shot_n")
    with pytest.raises(SystemExit):
        bench.main(["data/large_n/multirun/N8000_phi0.70_*/trajectory.h5", "--no-write"])
    assert "no file matches" in capsys.readouterr().err
