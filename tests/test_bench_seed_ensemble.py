"""bench/surrogate_seed_ensemble.py's averaging and its refusal to mix folds."""

import numpy as np
import pytest
from conftest import load_bench_script


@pytest.fixture(scope="module")
def seed_ensemble():
    return load_bench_script("surrogate_seed_ensemble")


def test_ensemble_mean_is_geometric_for_eta_and_pi_and_linear_for_z_mu(seed_ensemble):
    a = np.array([[10.0, 1.0, 0.5], [2.0, 4.0, 1.0]])
    b = np.array([[1000.0, 100.0, 1.5], [8.0, 1.0, 2.0]])
    mean = seed_ensemble.ensemble_mean([a, b])
    np.testing.assert_allclose(mean, [[100.0, 10.0, 1.0], [4.0, 2.0, 1.5]])
    # a non-positive member prediction (possible for an unconstrained output) falls back to the plain mean
    c = b.copy()
    c[1, 0] = -2.0
    assert seed_ensemble.ensemble_mean([a, c])[1, 0] == pytest.approx(0.0)


def test_runs_tested_on_other_graphs_are_refused(seed_ensemble, tmp_path):
    rng = np.random.default_rng(0)
    for name, run_id in (("a", [0, 0, 1]), ("b", [0, 1, 1])):
        (tmp_path / name).mkdir()
        np.savez(
            tmp_path / name / "fold0_predictions.npz",
            pred=rng.random((3, 3)) + 1,
            true=np.ones((3, 3)),
            run_id=np.array(run_id),
            phi=np.full(3, 0.7),
            stress=np.ones(3),
            jammed=np.zeros(3, dtype=bool),
        )
    with pytest.raises(SystemExit, match="fold 0: the runs were tested on different graphs"):
        seed_ensemble.fold_scores([tmp_path / "a", tmp_path / "b"], 0)
