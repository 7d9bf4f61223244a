"""bench/short_run_3d.py --sizes: each N runs in a process of its own (its peak memory is its own), and a
size the simulator refuses stops the table in one line naming that N and the simulator's reason."""

import json

import pytest
from conftest import load_bench_script


def test_a_refused_size_is_named_in_one_line():
    bench = load_bench_script("short_run_3d")
    with pytest.raises(SystemExit, match=r"the run at N = 3 \(auto\) failed: .*n_particles=3 is too small"):
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


def test_tilings_are_the_most_cube_like():
    bench = load_bench_script("short_run_3d")
    assert bench.most_cubic_tiling(1) == (1, 1, 1)
    assert bench.most_cubic_tiling(8) == (2, 2, 2)
    assert sorted(bench.most_cubic_tiling(16)) == [2, 2, 4]
    assert sorted(bench.most_cubic_tiling(27)) == [3, 3, 3]
    assert sorted(bench.most_cubic_tiling(7)) == [1, 1, 7]


def test_a_replicated_start_keeps_every_pair_of_the_sheared_original():
    """Copies of a sheared box (Lees-Edwards offset not a multiple of the edge) are neighbours of one
    another exactly as the original's images are: every particle sees the same neighbour distances."""
    import numpy as np

    from rheograph.sim.geometry3d import neighbour_pairs, pair_geometry
    from rheograph.sim.integrator3d import Simulation3D
    from rheograph.sim.params3d import SimParams3D

    bench = load_bench_script("short_run_3d")
    params = SimParams3D(n_particles=60, phi=0.5, stress=10.0, seed=3)
    state = Simulation3D(params).state
    state.le_offset = 0.37 * state.lx  # as if sheared by 0.37 strain
    big_params, big = bench.replicate(params, state, 8 * 60)
    assert big_params.n_particles == 480 and big.radii.shape == (480,)
    assert np.isclose(big.lx * big.ly * big.lz, 8 * state.lx * state.ly * state.lz)

    def distances_seen(s):
        i, j = neighbour_pairs(s.positions, s.radii, s.lx, s.ly, s.lz, s.le_offset, 0.5, 0.4)
        _, r, _, _ = pair_geometry(s.positions, s.radii, i, j, s.lx, s.ly, s.lz, s.le_offset)
        close = r < 2.5
        n = s.radii.shape[0]
        return [np.sort(np.r_[r[close][i[close] == k], r[close][j[close] == k]]) for k in range(n)]

    original, replicated = distances_seen(state), distances_seen(big)
    for k, seen in enumerate(replicated):
        np.testing.assert_allclose(seen, original[k % 60], atol=1e-9)
