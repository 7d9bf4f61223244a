"""bench/unknown_radii.py: the radii an experiment would give (nominal per species, the species known or
told from each size), and a run of exact radii refused by name."""

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
