"""bench/unknown_radii.py: the radii an experiment would give (nominal per species, the species known or
told from each size), a run of exact radii refused by name, an unfinished run left out."""

import numpy as np
import pytest
from conftest import load_bench_script


def test_nominal_radii_follow_the_species_known_or_told_by_size():
    bench = load_bench_script("unknown_radii")
    drawn = np.array([0.93, 1.19, 1.05, 1.17, 1.52, 1.30])  # three small, three large (simulator order)
    np.testing.assert_array_equal(bench.nominal_radii(drawn, 3, "species known"), [1, 1, 1, 1.4, 1.4, 1.4])
    # by size, against the geometric mean 1.183: the small 1.19 reads as large, the large 1.17 as small
    np.testing.assert_array_equal(bench.nominal_radii(drawn, 3, "species by size"), [1, 1.4, 1, 1, 1.4, 1.4])


def test_a_run_of_exact_radii_is_refused_by_name(tiny_files):
    bench = load_bench_script("unknown_radii")
    with pytest.raises(SystemExit, match="is not a run of sim.radii=polydisperse"):
        bench.main([tiny_files[0], "--no-write"])


def test_an_unfinished_run_is_left_out_not_scored(tiny_files, tmp_path):
    """A run still going or interrupted would score differently once resumed: it is left out (here the
    only run, so nothing is left to score), before its radii are even looked at."""
    import shutil

    import h5py

    bench = load_bench_script("unknown_radii")
    unfinished = tmp_path / "interrupted.h5"
    shutil.copy(tiny_files[0], unfinished)
    with h5py.File(unfinished, "r+") as h5:
        h5.attrs["status"] = "interrupted"
    with pytest.raises(SystemExit, match="match no finished run"):
        bench.main([str(unfinished), "--no-write"])
