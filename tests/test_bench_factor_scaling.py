"""bench/factor_scaling.py: the claims docs/jamming.md makes of the factor, on two small boxes — fill per
particle grows with N (nested dissection: ~log N), the work per particle grows faster than the fill
(~√N: dense separator blocks), and AMD fills more than nested dissection at the larger N."""

import pytest
from conftest import load_bench_script


def test_factor_work_per_particle_grows_faster_than_its_fill(capsys):
    bench = load_bench_script("factor_scaling")
    rows = {}
    for n in (100, 1600):
        for row in bench.measure(n, warmup=2, repeats=2, windows=1, orderings=["nesdis", "amd"]):
            rows[n, row["ordering"]] = row
    small, large = rows[100, "nesdis"], rows[1600, "nesdis"]
    fill_growth = large["nnz_per_particle"] / small["nnz_per_particle"]
    work_growth = large["flops_per_particle"] / small["flops_per_particle"]
    assert 1.1 < fill_growth < work_growth
    # the work of a column Cholesky is at least one multiply-add per nonzero
    assert all(r["flops_per_particle"] >= r["nnz_per_particle"] for r in rows.values())
    assert rows[1600, "amd"]["nnz_per_particle"] > large["nnz_per_particle"]
    with pytest.raises(SystemExit, match="--orderings"):
        bench.main(["--orderings", "fastest", "--no-write"])
