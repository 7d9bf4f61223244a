"""bench/short_run_3d.py --sizes: each N runs in a process of its own (its peak memory is its own), and a
size the simulator refuses stops the table in one line naming that N and the simulator's reason."""

import json

import pytest
from conftest import load_bench_script


def test_a_refused_size_is_named_in_one_line():
    bench = load_bench_script("short_run_3d")
    with pytest.raises(SystemExit, match=r"the run at N = 3 failed: .*n_particles=3 is too small"):
        bench.main(["--sizes", "3", "--steps", "2", "--warmup", "1"])


def test_one_run_keeps_its_numbers(tmp_path):
    """A run's --json holds the median CPU time of its steps, the per-phase times and its peak memory."""
    bench = load_bench_script("short_run_3d")
    out = tmp_path / "run.json"
    assert bench.main(["--n", "40", "--steps", "6", "--warmup", "2", "--json", str(out)]) == 0
    run = json.loads(out.read_text())
    assert run["n"] == 40 and run["steps"] == 6 and run["strain"][1] > run["strain"][0]
    assert 0 < run["cpu_per_step_median_s"] < 10 and run["peak_rss_mb"] > 10
    assert set(run["phases_s"]) >= {"assembly", "factorisation", "solve"}
