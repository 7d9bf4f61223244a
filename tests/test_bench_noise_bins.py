"""bench/noise_bins.py on a tiny run trained on noisy copies: every row lands in exactly one ε bin, the
bins' scores are those of the rows in them, rows the model flags are counted and not scored, and the
lookup does not depend on the noise."""

import re

import numpy as np
import pytest
from conftest import load_bench_script, train_tiny_fold


def test_noise_bins_score_the_saved_test_rows_of_each_noise_level(tiny_files, tmp_path, capsys, monkeypatch):
    from rheograph.learn.module import fold_metrics
    from rheograph.naming import state_point_key

    run_dir = train_tiny_fold(
        tiny_files,
        tmp_path,
        "graph=imaging_relaxed",
        "graph.noise_copies=3",
        "data.split=grouped",
    )
    bench = load_bench_script("noise_bins")
    cache = str(tmp_path / "cache")
    rows = bench.fold_rows(run_dir, 0, tmp_path / "cache")
    # 3 copies of every test snapshot, each copy's eps inside the trained range
    assert rows["eps"].size == rows["true"].shape[0] and rows["eps"].size % 3 == 0
    assert np.all((rows["eps"] >= 1e-4 * (1 - 1e-6)) & (rows["eps"] <= 0.05 * (1 + 1e-6)))
    edges = [1e-4, 3e-3, 5e-2]
    assert bench.main([str(run_dir), "--folds", "0", "--bins", *map(str, edges), "--cache-dir", cache,
                       "--no-write"]) == 0  # fmt: skip
    text = capsys.readouterr().out
    low = rows["eps"] < edges[1]
    counts = re.findall(r"\(n (\d+)\)", text)
    assert [int(c) for c in counts] == [int(low.sum()), int((~low).sum())]
    # the network's R² log eta_r in the low bin is that of the rows in it
    groups = state_point_key(rows["phi"], rows["stress"])
    expected = fold_metrics(rows["pred"][low], rows["true"][low], groups[low], rows["jammed"][low])
    line = next(s for s in text.splitlines() if s.startswith("| graph network | R² log η_r"))
    assert float(line.split("|")[3]) == pytest.approx(expected["r2_log_eta"], abs=6e-4)
    # --skip-stress leaves out every row at that stress, and only those; nothing left is an error
    stresses = np.unique(rows["stress"])
    skip = ["--folds", "0", "--bins", "1e-4", "0.05", "--cache-dir", cache, "--no-write", "--skip-stress"]
    assert bench.main([str(run_dir), *skip, "12345"]) == 0  # a stress no row has: every row kept
    kept = re.findall(r"\(n (\d+)\)", capsys.readouterr().out)
    assert [int(c) for c in kept] == [rows["stress"].size]
    with pytest.raises(SystemExit, match="leaves no rows"):
        bench.main([str(run_dir), *skip, *map(str, stresses)])
    # a row whose relaxation stopped short (an arrested packing: predict.py flags it) is counted in its
    # bin as flagged and left out of every score there
    flagged = np.zeros(rows["eps"].size, dtype=bool)
    flagged[0] = True
    monkeypatch.setattr("rheograph.learn.predict.short_relaxation", lambda graphs, settings: flagged.copy())
    assert bench.main([str(run_dir), "--folds", "0", "--bins", *map(str, edges), "--cache-dir", cache,
                       "--no-write"]) == 0  # fmt: skip
    text = capsys.readouterr().out
    first = 0 if low[0] else 1
    kept = (low if first == 0 else ~low) & ~flagged
    counts = re.findall(r"\(n (\d+)(?:, (\d+) flagged)?\)", text)
    assert counts[first] == (str(int(kept.sum())), "1") and counts[1 - first][1] == ""
    expected = fold_metrics(rows["pred"][kept], rows["true"][kept], groups[kept], rows["jammed"][kept])
    line = next(s for s in text.splitlines() if s.startswith("| graph network | R² log η_r"))
    assert float(line.split("|")[3 + first]) == pytest.approx(expected["r2_log_eta"], abs=6e-4)
    # bad bins end in one line
    with pytest.raises(SystemExit, match="increasing"):
        bench.main([str(run_dir), "--bins", "0.01", "0.001", "--no-write"])


def test_noise_bins_refuse_a_run_without_noisy_copies(tiny_files, tmp_path):
    run_dir = train_tiny_fold(tiny_files, tmp_path, "data.split=grouped")
    bench = load_bench_script("noise_bins")
    with pytest.raises(SystemExit, match="bench/snapshot_noise.py"):
        bench.main([str(run_dir), "--folds", "0", "--cache-dir", str(tmp_path / "cache"), "--no-write"])
