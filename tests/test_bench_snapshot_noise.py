"""bench/snapshot_noise.py end to end on a tiny training run: every predictor row, finite scores, the
lookup independent of the noise, the exact network degraded by it."""

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
