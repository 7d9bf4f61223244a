"""bench/zero_shot_n.py: the per-snapshot listing holds exactly the snapshots each row scores, and its
ratios are the row's predictions (the row's metrics recomputed from it agree); a glob that matches
nothing ends in one line."""

import numpy as np
import pytest
from conftest import ROOT, load_bench_script

RUNS = ROOT / "data" / "paper" / "multirun"


def test_per_snapshot_listing_reproduces_the_rows_metrics():
    """Two seeds at σ/σ0 = 10 give each other a lookup, so the row scores only them: the σ/σ0 = 200 run,
    alone at its stress, is predicted but neither scored nor listed."""
    from rheograph.learn.module import fold_metrics
    from rheograph.naming import state_point_key

    bench = load_bench_script("zero_shot_n")
    paths = [RUNS / f"N400_phi0.76_s{s}_seed{k}_d0.002_implicit" / "trajectory.h5" for s, k in
             ((10, 1), (10, 2), (200, 1))]  # fmt: skip
    listing = []
    rows = bench.score(["N400_phi0.76"], paths, min_strain=1.0, per_snapshot=listing)
    (row,) = [r for r in rows if r["model"] == "N400_phi0.76"]
    assert {s["stress"] for s in listing} == {10.0} and len(listing) == row["snapshots"] > 10
    true = np.array([[s["eta"], np.nan, np.nan] for s in listing])
    pred = true.copy()
    pred[:, 0] *= [s["eta_ratio"] for s in listing]
    keys = state_point_key(np.full(len(listing), 0.76), np.array([s["stress"] for s in listing]))
    metrics = fold_metrics(pred, true, keys)
    # R² and the within-state correlation (not symmetric under pred <-> true: an inverted ratio fails it)
    assert metrics["r2_log_eta"] == pytest.approx(row["r2_log_eta"], abs=1e-9)
    assert metrics["fluct_eta"] == pytest.approx(row["fluct_eta"], abs=1e-9)
    assert all(0.5 < s["pressure_ratio"] < 2 and abs(s["z_mu_diff"]) < 0.1 for s in listing)


def test_a_glob_matching_nothing_is_one_line(capsys):
    bench = load_bench_script("zero_shot_n")
    with pytest.raises(SystemExit):
        bench.main(["data/large_n/multirun/N8000_phi0.70_*/trajectory.h5", "--no-write"])
    err = capsys.readouterr().err.strip().splitlines()
    assert "no file matches" in err[-1] and not any("Traceback" in line for line in err)


def test_a_lookup_from_other_runs_is_their_mean_at_each_state_point():
    """``lookup_paths``: the lookup row of the seed-1 runs at σ/σ0 = 10 and 200 is the seed-2 σ/σ0 = 10
    run's mean (geometric in η_r and Π) over its snapshots at strain >= 1; σ/σ0 = 200, absent from the
    references, is left out of every row."""
    from rheograph.io.snapshots import read_snapshots
    from rheograph.learn.module import fold_metrics
    from rheograph.naming import state_point_key

    bench = load_bench_script("zero_shot_n")
    path = "N400_phi0.76_s{}_seed{}_d0.002_implicit/trajectory.h5"
    members = [RUNS / path.format(10, 1), RUNS / path.format(200, 1)]
    reference = RUNS / path.format(10, 2)
    (row,) = bench.score([], members, min_strain=1.0, lookup_paths=[reference])
    assert row["model"] == "lookup: mean of the N = 400 runs at (φ, σ)" and row["stresses"] == 1

    def flowing(p):
        s = read_snapshots(p)
        return s.targets[(np.nan_to_num(s.strain, nan=-1) >= 1.0) & ~s.jammed]

    ref, true = flowing(reference), flowing(members[0])
    mean = np.array([np.exp(np.log(ref[:, 0]).mean()), np.exp(np.log(ref[:, 1]).mean()), ref[:, 2].mean()])
    keys = state_point_key(np.full(len(true), 0.76), np.full(len(true), 10.0))
    metrics = fold_metrics(np.repeat(mean[None], len(true), axis=0), true, keys)
    assert row["snapshots"] == len(true)
    for name in ("r2_log_eta", "r2_log_pressure", "r2_z_mu"):
        assert row[name] == pytest.approx(metrics[name], abs=1e-12)
