"""Jamming-point fits: closed forms recovered, branches selected as documented, noise bracketed, and
the jamming page's consistency claim on the committed N = 400 set."""

import json
from pathlib import Path

import numpy as np
import pytest

from rheograph.analysis.jamming_points import (
    arrest_bracket,
    arrest_probability,
    bootstrap,
    fit_divergence,
    fit_wyart_cates,
    flowing,
    frictionless_branch,
    jamming_table,
    main,
    near,
    plateau_branch,
    read_runs,
    rule_comparison,
    rule_comparison_block,
    section_blocks,
    select_rules,
    two_digits,
)
from rheograph.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


def test_divergence_fit_recovers_phi_j_and_beta_of_an_exact_power_law():
    phi = np.array([0.78, 0.80, 0.81, 0.82, 0.83])
    eta = 0.7 * (0.845 - phi) ** -1.6
    free = fit_divergence(phi, eta)
    assert free["phi_j"] == pytest.approx(0.845, abs=1e-6) and free["beta"] == pytest.approx(1.6, abs=1e-5)
    assert free["prefactor"] == pytest.approx(0.7, rel=1e-4) and free["rms_log"] < 1e-8
    fixed = fit_divergence(phi, 0.7 * (0.845 - phi) ** -2.0, beta=2.0)
    assert fixed["phi_j"] == pytest.approx(0.845, abs=1e-6) and fixed["beta"] == 2.0
    with pytest.raises(InputError, match="at least 3 area fractions"):
        fit_divergence([0.78, 0.78, 0.80], [70, 71, 120])


def test_wyart_cates_fit_recovers_both_jamming_points_from_mixed_friction():
    rng = np.random.default_rng(0)
    phi = rng.uniform(0.70, 0.79, 60)
    f = rng.uniform(0.0, 1.0, 60)
    phi_m = f * 0.80 + (1 - f) * 0.85
    eta = 1.3 * (1 - phi / phi_m) ** -2.0
    fit = fit_wyart_cates(phi, f, eta)
    assert fit["phi_j0"] == pytest.approx(0.85, abs=1e-6) and fit["phi_jmu"] == pytest.approx(0.80, abs=1e-6)
    free = fit_wyart_cates(phi, f, 1.3 * (1 - phi / phi_m) ** -1.7, beta=None)
    assert free["beta"] == pytest.approx(1.7, abs=1e-5) and free["phi_j0"] == pytest.approx(0.85, abs=1e-6)


def test_wyart_cates_with_branch_amplitudes_recovers_them_where_one_amplitude_cannot():
    """Frictionless and frictional branches with different amplitudes (log A linear in f): the fit with
    prefactor_in_f recovers both jamming points and amplitudes exactly; one shared amplitude cannot,
    and pays for it with a biased phi_J^0 and a residual."""
    rng = np.random.default_rng(1)
    phi = rng.uniform(0.70, 0.79, 80)
    f = rng.uniform(0.0, 1.0, 80)
    phi_m = f * 0.80 + (1 - f) * 0.84
    eta = np.exp((1 - f) * np.log(0.5) + f * np.log(4.0)) * (1 - phi / phi_m) ** -1.5
    fit = fit_wyart_cates(phi, f, eta, beta=None, prefactor_in_f=True)
    assert fit["phi_j0"] == pytest.approx(0.84, abs=1e-6) and fit["phi_jmu"] == pytest.approx(0.80, abs=1e-6)
    assert fit["prefactor"] == pytest.approx(0.5, rel=1e-5)
    assert fit["prefactor_mu"] == pytest.approx(4.0, rel=1e-5)
    assert fit["beta"] == pytest.approx(1.5, abs=1e-5) and fit["rms_log"] < 1e-8
    shared = fit_wyart_cates(phi, f, eta, beta=None)
    assert shared["rms_log"] > 0.01 and abs(shared["phi_j0"] - 0.84) > 0.002


def _run(n, phi, stress, seed, eta, mu=0.5, z_mu=0.0, z=2.0, status="completed", strain=3.0):
    return dict(
        n=n, phi=phi, stress=stress, seed=seed, mu=mu, status=status, strain=strain, eta=eta, z_mu=z_mu, z=z
    )


def test_branches_select_frictionless_and_plateau_runs_and_skip_jammed_ones():
    runs = [
        _run(400, 0.80, 1.0, 1, 120.0, mu=0.0),  # mu = 0: frictionless at any stress
        _run(400, 0.76, 0.5, 1, 46.0, z_mu=0.0),  # frictional set at low stress, no frictional contact
        _run(400, 0.76, 0.5, 2, 47.0, z_mu=0.05),  # some friction: not on the branch
        _run(400, 0.76, 2.0, 1, 60.0, z_mu=0.4),
        _run(400, 0.76, 200.0, 1, 230.0, z_mu=2.3),
        _run(400, 0.80, 200.0, 1, np.inf, z_mu=2.7, status="jammed"),
        _run(2000, 0.76, 200.0, 1, 232.0, z_mu=2.3),
    ]
    assert {(r["phi"], r["stress"]) for r in frictionless_branch(runs, 400)} == {(0.80, 1.0), (0.76, 0.5)}
    plateau, top = plateau_branch(runs, 400)
    assert top == 200.0 and [r["phi"] for r in plateau] == [0.76]  # the jammed run has no viscosity
    assert [r["phi"] for r in near(frictionless_branch(runs, 400), 0.03)] == [0.80]


def test_arrest_bracket_lies_between_the_last_area_fraction_that_flows_and_the_first_that_arrests():
    """Every run flows at 0.83, one of three arrests at 0.835, every one at 0.84: phi_J in [0.83, 0.84];
    a run stopped early decides nothing, and a branch that never arrests has no bracket."""
    branch = [
        *(_run(400, 0.82, 1.0, s, 300.0, mu=0.0) for s in (1, 2, 3)),
        *(_run(400, 0.83, 1.0, s, 900.0, mu=0.0) for s in (1, 2, 3)),
        _run(400, 0.835, 1.0, 1, 2900.0, mu=0.0),
        _run(400, 0.835, 1.0, 2, np.inf, mu=0.0, status="jammed"),
        _run(400, 0.835, 1.0, 3, 2200.0, mu=0.0),
        *(_run(400, 0.84, 1.0, s, np.inf, mu=0.0, status="jammed") for s in (1, 2)),
        _run(400, 0.84, 1.0, 3, np.nan, mu=0.0, status="interrupted"),
        _run(400, 0.845, 1.0, 1, np.inf, mu=0.0, status="jammed"),
    ]
    assert arrest_bracket(branch) == (0.83, 0.84, 8)
    assert arrest_bracket([r for r in branch if r["status"] != "jammed"]) is None
    rows = [r for r in jamming_table(branch) if r["method"].startswith("arrest bracket")]
    assert len(rows) == 1 and rows[0]["quantity"] == "phi_J^0" and rows[0]["phi_j"] == pytest.approx(0.835)
    assert rows[0]["phi_j_ci"] == (0.83, 0.84)


def _arrests(phi, arrested, flowing, strain=3.0):
    """Runs at phi on the sigma/sigma0 = 200 plateau: ``arrested`` that jammed (at half the window),
    ``flowing`` that reached ``strain``."""
    return [
        *(_run(400, phi, 200.0, s, np.inf, status="jammed", strain=strain / 2) for s in range(arrested)),
        *(_run(400, phi, 200.0, 100 + s, 500.0, strain=strain) for s in range(flowing)),
    ]


def test_arrest_probability_half_is_the_maximum_likelihood_logistic_crossing():
    """Mixed outcomes: phi_1/2 is the crossing -intercept / slope of an unpenalised logistic regression
    (scikit-learn, an independent maximiser), inside its profile interval; a symmetric design puts it
    at the middle area fraction."""
    from sklearn.linear_model import LogisticRegression

    branch = [
        *_arrests(0.780, 0, 6),
        *_arrests(0.785, 1, 5),
        *_arrests(0.790, 2, 4),
        *_arrests(0.795, 4, 2),
        *_arrests(0.800, 5, 1),
        *_arrests(0.805, 6, 0),
    ]
    out = arrest_probability(branch)
    phi = np.array([[r["phi"]] for r in branch])
    y = np.array([r["status"] == "jammed" for r in branch])
    # phi in units of 0.01 keeps the unpenalised problem well scaled for lbfgs
    reference = LogisticRegression(C=np.inf, tol=1e-10, max_iter=10_000).fit((phi - 0.79) / 0.01, y)
    crossing = 0.79 - 0.01 * reference.intercept_[0] / reference.coef_[0, 0]
    assert out["phi_half"] == pytest.approx(crossing, abs=5e-5)
    low, high = out["interval"]
    assert low < out["phi_half"] < high and 0.001 < high - low < 0.01
    assert (out["runs"], out["arrested"], out["window"]) == (36, 18, 3.0)
    symmetric = arrest_probability([*_arrests(0.78, 0, 4), *_arrests(0.79, 2, 2), *_arrests(0.80, 4, 0)])
    assert symmetric["phi_half"] == pytest.approx(0.79, abs=3e-5)


def test_arrest_probability_is_the_bracket_when_outcomes_separate_and_counts_late_arrests_as_flowing():
    separated = arrest_probability([*_arrests(0.83, 0, 3), *_arrests(0.84, 3, 0)])
    assert separated["phi_half"] == pytest.approx(0.835, abs=1e-4)
    # the gap, less the steepest logistic's width (1e-4) at each end
    assert separated["interval"][0] == pytest.approx(0.83, abs=3e-4)
    assert separated["interval"][1] == pytest.approx(0.84, abs=3e-4)
    # the shortest run that flowed to its end went 2 strain: arrests after that count as flowing within it
    late = [*_arrests(0.83, 0, 3, strain=2.0), *_arrests(0.84, 3, 0, strain=5.0)]
    assert arrest_probability(late) is None  # nothing arrests within 2 strain
    assert arrest_probability(_arrests(0.84, 3, 0)) is None  # no run flowed: no window, no crossing
    stopped = _run(400, 0.835, 200.0, 9, np.nan, status="interrupted", strain=0.5)
    assert arrest_probability([*_arrests(0.83, 0, 3), stopped, *_arrests(0.84, 3, 0)])["runs"] == 6


def test_bootstrap_interval_brackets_the_true_jamming_point_of_noisy_seeds():
    rng = np.random.default_rng(1)
    runs = [
        _run(400, phi, 1.0, seed, 0.7 * (0.845 - phi) ** -2.0 * np.exp(rng.normal(0, 0.05)), mu=0.0)
        for phi in (0.79, 0.80, 0.81, 0.82, 0.83)
        for seed in (1, 2, 3)
    ]
    spread = bootstrap(
        runs, lambda s: fit_divergence([r["phi"] for r in s], [r["eta"] for r in s], 2.0), ["phi_j"], rng, 200
    )
    median, low, high = spread["phi_j"]
    # a 68 % interval: the truth within three of its half-widths, and the interval a few 1e-3 wide
    # (5 % noise on 15 trajectories)
    assert abs(median - 0.845) < 1.5 * (high - low) and 0 < high - low < 0.01
    rows = jamming_table(runs, seed=0)
    assert {r["method"] for r in rows} == {"divergence, beta = 2", "divergence, beta fitted"}


def test_one_run_per_state_point_gets_an_interval_from_its_block_error_only_when_asked():
    """One trajectory per area fraction, eta_r scattered by 5 % and its block standard error saying so:
    resampling trajectories alone gives an empty interval; drawing each eta_r from its error gives one
    that brackets the true phi_J, and one four times wider for errors four times larger."""
    rng = np.random.default_rng(3)
    runs = []
    for phi in (0.79, 0.80, 0.81, 0.82, 0.83):
        eta = 0.7 * (0.845 - phi) ** -2.0 * np.exp(rng.normal(0, 0.05))
        runs.append({**_run(400, phi, 1.0, 1, eta, mu=0.0), "eta_se": 0.05 * eta})

    def fit(s):
        return fit_divergence([r["phi"] for r in s], [r["eta"] for r in s], 2.0)

    def width(sample, **kw):
        _, low, high = bootstrap(sample, fit, ["phi_j"], np.random.default_rng(0), 200, **kw)["phi_j"]
        return low, high

    low, high = width(runs)
    assert low == high  # nothing to resample
    low, high = width(runs, single_run_error=True)
    assert low < 0.845 + 3 * (high - low) and high > 0.845 - 3 * (high - low) and 0 < high - low < 0.01
    wider = [{**r, "eta_se": 4 * r["eta_se"]} for r in runs]
    low4, high4 = width(wider, single_run_error=True)
    assert (high4 - low4) / (high - low) == pytest.approx(4.0, rel=0.3)


def test_command_line_names_a_bad_index(tmp_path, capsys):
    bad = tmp_path / "index.json"
    bad.write_text("not json")
    with pytest.raises(InputError, match="not a readable run index"):
        main([str(bad)])
    bad.write_text(json.dumps({"runs": []}))
    with pytest.raises(InputError, match="no branch with three area fractions"):
        main([str(bad)])
    with pytest.raises(InputError, match="--window"):
        main([str(bad), "--window", "0"])
    with pytest.raises(InputError, match="--record: give the page too"):
        main([str(bad), "--record", str(tmp_path / "jamming_fits.json")])


def _index_entry(phi, seed, eta, unloading=None):
    params = {"n_particles": 500, "phi": phi, "stress": 200.0, "seed": seed, "mu": 0.5, "dim": 3}
    if unloading is not None:  # files written before the option carry no elastic_unloading
        params["elastic_unloading"] = unloading
    return {
        "status": "completed",
        "strain": 3.0,
        "params": params,
        "summary": {"viscosity": eta, "viscosity_se": 0.05 * eta},
    }


def test_a_state_point_run_with_both_stick_slip_rules_is_refused_unless_told_which_to_keep(tmp_path, capsys):
    """The plateau at 0.53-0.57 in LF_DEM's rule, and 0.57 rerun with elastic unloading (eta_r twice
    as high): without --mixed-rules the mixed state point is refused by name; "unloading" fits the
    unloading run there and leaves out the other (reported), "pooled" averages both; state points run
    with one rule are kept either way, and an unloading run still under way supersedes nothing."""
    phis = (0.53, 0.55, 0.56, 0.57)
    lfdem = [_index_entry(phi, 1, 0.8 * (0.6 - phi) ** -2.0) for phi in phis]
    unloading = [_index_entry(0.57, 1, 1.6 * (0.6 - 0.57) ** -2.0, unloading=True)]
    first, second = tmp_path / "set.json", tmp_path / "near.json"
    first.write_text(json.dumps({"runs": lfdem}))
    second.write_text(json.dumps({"runs": unloading}))
    runs = read_runs([first, second])
    with pytest.raises(InputError, match=r"phi 0.57 sigma/sigma0 200 \(and 0 more.*--mixed-rules unloading"):
        select_rules(runs, None)
    with pytest.raises(InputError, match="phi 0.57"):
        main([str(first), str(second)])
    kept, left_out = select_rules(runs, "unloading")
    assert [(r["phi"], r["elastic_unloading"]) for r in left_out] == [(0.57, False)]
    assert sorted((r["phi"], r["elastic_unloading"]) for r in kept) == [
        (0.53, False),
        (0.55, False),
        (0.56, False),
        (0.57, True),
    ]
    assert select_rules(runs, "pooled") == (runs, [])
    under_way = [*runs[:4], {**runs[4], "status": "interrupted"}]
    assert select_rules(under_way, "unloading") == (under_way, [])  # nothing supersedes LF_DEM's yet
    assert select_rules(runs[:4], None) == (runs[:4], [])  # one rule throughout: nothing to choose
    (compared,) = rule_comparison([*runs, {**runs[0], "phi": 0.6, "status": "interrupted", "strain": 0.04}])
    assert (compared["phi"], compared["lfdem"]["runs"], compared["unloading"]["runs"]) == (0.57, 1, 1)
    assert compared["unloading"]["eta"] / compared["lfdem"]["eta"] == pytest.approx(2.0)
    arrested = {**runs[4], "phi": 0.6, "status": "jammed", "strain": 0.033}
    undecided = {**runs[0], "phi": 0.6, "status": "interrupted", "strain": 0.04}
    cells = rule_comparison_block(rule_comparison([*runs, arrested, undecided]))["table"]["rows"]
    assert cells[0][-1] == "2.00" and cells[0][4] == "888.9 ± 44"  # 0.8 / 0.03^2, its 5 % block error
    assert [two_digits(x) for x in (418.7, 38.2, 4.23, 0.0451, 0)] == ["420", "38", "4.2", "0.045", "0"]
    assert cells[1][4:] == [
        "undecided, stopped at strain 0.04",
        "—",
        "1",
        "arrested at strain 0.033",
        "—",
        "—",
    ]
    main([str(first), str(second), "--mixed-rules", "unloading"])
    assert (
        "left out (LF_DEM's rule where elastic unloading ran too): N = 500 phi 0.57"
        in capsys.readouterr().err
    )


def test_committed_n400_set_the_two_fit_methods_agree_once_branches_keep_their_amplitudes():
    """The jamming page's claim on the committed N = 400 runs: Wyart–Cates over every flowing state
    point (f = Z_mu / Z measured) with log A linear in f puts both jamming points within 0.005 of the
    beta-fitted branch divergences, and fits better than one shared amplitude, whose phi_J^0 lies
    0.02 higher.  Point fits only (the bootstrap intervals are the page's)."""
    indexes = [ROOT / "data" / "paper" / "index.json", ROOT / "data" / "jamming" / "index.json"]
    runs = [r for r in read_runs(indexes) if r["n"] == 400]
    divergence = {}
    for name, branch in (
        ("phi_j0", frictionless_branch(runs, 400)),
        ("phi_jmu", plateau_branch(runs, 400)[0]),
    ):
        branch = near(branch, 0.05)
        divergence[name] = fit_divergence([r["phi"] for r in branch], [r["eta"] for r in branch])["phi_j"]
    every = [r for r in runs if flowing(r) and np.isfinite(r["z_mu"]) and r["z"] > 0]
    args = ([r["phi"] for r in every], [r["z_mu"] / r["z"] for r in every], [r["eta"] for r in every])
    branch_amplitudes = fit_wyart_cates(*args, beta=None, prefactor_in_f=True)
    shared = fit_wyart_cates(*args, beta=None)
    for key in ("phi_j0", "phi_jmu"):
        assert branch_amplitudes[key] == pytest.approx(divergence[key], abs=0.005), key
    assert branch_amplitudes["rms_log"] < 0.8 * shared["rms_log"]
    assert shared["phi_j0"] > divergence["phi_j0"] + 0.01


def test_discs_and_spheres_of_one_n_are_fitted_apart_and_the_spheres_are_labelled():
    """A 2D and a 3D set with the same N: each plateau divergence gives back its own phi_J (0.80 for
    the discs, 0.60 for the spheres), the rows carry their dimension and the table marks the 3D one."""
    runs = []
    for dim, phi_j, phis in ((2, 0.80, (0.74, 0.76, 0.78)), (3, 0.60, (0.54, 0.56, 0.58))):
        for phi in phis:
            run = _run(500, phi, 200.0, 1, (phi_j - phi) ** -2.0, z_mu=2.0, z=4.0)
            run["dim"] = dim
            runs.append(run)
    rows = [r for r in jamming_table(runs, n_boot=20) if r["method"] == "divergence, beta = 2"]
    fitted = {(r["dim"], r["quantity"]): r["phi_j"] for r in rows}
    assert fitted == {
        (2, "phi_J^mu"): pytest.approx(0.80, abs=1e-6),
        (3, "phi_J^mu"): pytest.approx(0.60, abs=1e-6),
    }
    cells = [block for block in section_blocks(rows, "cmd") if "table" in block][0]["table"]["rows"]
    assert sorted(row[0] for row in cells) == ["500", "500 (3D)"]
