"""Cross-validated error bars (rheograph.learn.error_model): the RMS of held-out residuals per state point
recovers a known error, covers ~68 % / 95 % of fresh errors, interpolates in log σ and is read by predict."""

import numpy as np
import pytest

from rheograph.learn.error_model import error_scale, fit_error_model, predicted_error

STRESSES = np.array([0.5, 5.0, 50.0])
TRUE_SIGMA = {  # per stress: log10 error of eta_r and Pi, absolute error of Z_mu
    0.5: (0.02, 0.20, 0.01),
    5.0: (0.04, 0.05, 0.05),
    50.0: (0.08, 0.03, 0.05),
}


def synthetic(rng, n_per_point, phi=0.76):
    """Truth and predictions whose errors are Gaussian with the per-stress widths above."""
    stress = np.repeat(STRESSES, n_per_point)
    true = np.stack(
        [
            10 ** rng.uniform(1, 3, stress.size),
            10 ** rng.uniform(-1, 2, stress.size),
            rng.uniform(0, 2, stress.size),
        ],
        axis=1,
    )
    width = np.array([TRUE_SIGMA[s] for s in stress])
    noise = rng.normal(size=true.shape) * width
    pred = np.stack(
        [true[:, 0] * 10 ** noise[:, 0], true[:, 1] * 10 ** noise[:, 1], true[:, 2] + noise[:, 2]], 1
    )
    return pred, true, stress, np.full(stress.size, phi)


def test_error_bars_recover_the_error_and_cover_fresh_errors():
    rng = np.random.default_rng(0)
    model = fit_error_model(*synthetic(rng, 4000))
    assert model["stress"] == list(STRESSES) and model["count"] == [4000] * 3
    for k, name in enumerate(("eta", "pressure", "z_mu")):
        # RMS of 4000 Gaussian samples: relative standard error 1/sqrt(2 * 4000) ~ 1.1 %, so 4 % is > 3 s.e.
        np.testing.assert_allclose(model["rms"][name], [TRUE_SIGMA[s][k] for s in STRESSES], rtol=0.04)
    pred, true, stress, phi = synthetic(rng, 4000)
    bars = predicted_error(model, stress, phi)
    for k, name in enumerate(("eta", "pressure", "z_mu")):
        error = np.abs(error_scale(pred[:, k], name) - error_scale(true[:, k], name))
        # a Gaussian covers 68.3 % within 1 sigma and 95.4 % within 2; 12000 samples: s.e. < 0.5 %
        assert np.mean(error <= bars[:, k]) == pytest.approx(0.683, abs=0.02)
        assert np.mean(error <= 2 * bars[:, k]) == pytest.approx(0.954, abs=0.01)


def test_error_bars_interpolate_in_log_stress_and_take_the_nearest_phi():
    rng = np.random.default_rng(1)
    a = synthetic(rng, 50, phi=0.70)
    b = synthetic(rng, 50, phi=0.76)
    model = fit_error_model(*(np.concatenate([x, y]) for x, y in zip(a, b)))
    at = {p: predicted_error(model, STRESSES, np.full(3, p)) for p in (0.70, 0.76)}
    # sqrt(0.5 * 5) = 1.58 lies halfway in log sigma between 0.5 and 5: the bar is the mean of the two
    mid = predicted_error(model, [np.sqrt(0.5 * 5.0)], [0.71])[0]
    np.testing.assert_allclose(mid, 0.5 * (at[0.70][0] + at[0.70][1]))
    np.testing.assert_allclose(predicted_error(model, STRESSES, np.full(3, 0.75)), at[0.76])
    # beyond the trained stresses the end value holds (such inputs are flagged out of domain elsewhere)
    np.testing.assert_allclose(predicted_error(model, [1000.0], [0.76])[0], at[0.76][2])


def test_jammed_viscosities_and_sparse_state_points_are_left_out():
    rng = np.random.default_rng(2)
    pred, true, stress, phi = synthetic(rng, 40)
    jammed = stress == 50.0
    pred[jammed, 0] = 1e9  # a jammed snapshot's eta_r is not a target: must not enter the error bar
    model = fit_error_model(pred, true, stress, phi, jammed=jammed)
    assert model["rms"]["eta"][2] is None and model["rms"]["pressure"][2] is not None
    # the missing bar is filled from the neighbour in log sigma (constant beyond the last known point)
    assert predicted_error(model, [50.0], [0.76])[0, 0] == pytest.approx(model["rms"]["eta"][1])
    assert np.all(np.isnan(error_scale(np.array([0.0, -1.0]), "eta")))


def test_error_bounds_are_a_factor_on_the_log_targets_and_a_difference_on_z_mu():
    """The bar of η_r and Π is in log10 units: the truth 10^±err away from a prediction lies on the
    bounds; a prediction that is not positive has none (a factor cannot bound it), never a sign flip."""
    from rheograph.learn.error_model import error_bounds

    lower, upper = error_bounds("eta", np.array([100.0, 2.0, -1.0]), np.array([0.1, 0.3, 0.1]))
    np.testing.assert_allclose(lower[:2], [100.0 / 10**0.1, 2.0 / 10**0.3])
    np.testing.assert_allclose(upper[:2], [100.0 * 10**0.1, 2.0 * 10**0.3])
    assert np.isnan(lower[2]) and np.isnan(upper[2])
    lower, upper = error_bounds("z_mu", np.array([2.5]), np.array([0.05]))
    np.testing.assert_allclose([lower[0], upper[0]], [2.45, 2.55])
