"""Steady-state estimator: exact on synthetic series, and equal to LF_DEM's published summary."""

from pathlib import Path

import numpy as np
import pytest

from rheograph.analysis.steady import steady_state_summary
from rheograph.io.lfdem import read_lfdem_data

REFERENCE = Path(__file__).resolve().parent / "data" / "lfdem_phi0.76"  # LF_DEM output, see its README


def test_viscosity_is_stress_over_time_averaged_shear_rate():
    # shear rate alternating 1 and 3 in equal time: mean rate 2 -> eta = sigma / 2
    t = np.linspace(0, 10, 1001)
    rate = np.where((t * 10).astype(int) % 2 == 0, 1.0, 3.0)
    strain = np.concatenate([[0], np.cumsum(rate[:-1] * np.diff(t))])
    ones = np.ones_like(t)
    out = steady_state_summary(strain, t, ones, ones, ones, stress=4.0, strain_min=0.0)
    assert out["viscosity"] == pytest.approx(2.0, rel=1e-2)


def test_stalled_rows_do_not_outweigh_strain_sampled_rows():
    strain = np.array([0.0, 0.01, 0.02, 0.02, 0.02, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08])
    time = np.arange(strain.size, dtype=float)
    pressure = np.where(np.diff(strain, append=0.09) == 0, 100.0, 1.0)
    ones = np.ones_like(strain)
    out = steady_state_summary(strain, time, pressure, ones, ones, 1.0, 0.0, n_blocks=2)
    assert out["pressure"] == pytest.approx(1.0)


def test_too_short_window_gives_nan_not_a_number_made_up():
    s = np.linspace(0, 0.05, 6)
    out = steady_state_summary(s, s, s, s, s, 1.0, strain_min=1.0)
    assert np.isnan(out["viscosity"]) and out["n_rows"] == 0


@pytest.mark.parametrize(
    "name,eta,se",
    [("data_N400_phi0.76_s0.5_disp1e-3.dat", 45.3, 1.2), ("data_N400_phi0.76_s10_disp1e-3.dat", 155, 11)],
)
def test_estimator_reproduces_the_reference_summary(name, eta, se):
    """Applied to LF_DEM's own time series, our estimator gives the reference README's eta_r."""
    d = read_lfdem_data(REFERENCE / name)
    stress = float(name.split("_s")[1].split("_")[0])
    out = steady_state_summary(d["strain"], d["time"], d["pressure"], d["z_mu"], d["z"], stress, 1.0)
    assert out["viscosity"] == pytest.approx(eta, abs=se / 2)
    assert out["viscosity_se"] == pytest.approx(se, rel=0.1)  # the same block estimate of the error


def test_block_standard_error_of_uncorrelated_rows_is_the_textbook_one():
    """Uncorrelated rows of spread s, n of them: the block standard error estimates s / sqrt(n).  One
    estimate from 5 blocks scatters by ~35 %; the mean of its square over 400 independent series is
    within ~4 % (1 s.d.) of s^2 / n, so 15 % is a tolerance that a wrong formula (e.g. the spread of
    the block means not divided by sqrt(5), or s/n) cannot meet."""
    rng = np.random.default_rng(4)
    n, spread = 500, 0.3
    strain = np.linspace(1.0, 6.0, n)
    time = strain.copy()  # unit shear rate
    ones = np.ones(n)
    ratios = []
    for _ in range(400):
        pressure = 2.0 + spread * rng.normal(size=n)
        out = steady_state_summary(strain, time, pressure, ones, ones, 1.0, 1.0)
        assert out["pressure"] == pytest.approx(np.mean(pressure), abs=1e-9)
        ratios.append(out["pressure_se"] ** 2 * n / spread**2)
    assert np.mean(ratios) == pytest.approx(1.0, rel=0.15)


def test_flow_curve_report_of_three_stresses_is_shear_thickening(tiny_files, tmp_path):
    from rheograph.analysis.flow_curves import main

    main([str(Path(tiny_files[0]).parent), "--out", str(tmp_path)])
    table = (tmp_path / "flow_curves.md").read_text()
    assert (tmp_path / "flow_curves.png").stat().st_size > 10_000
    rows = [line for line in table.splitlines() if line.startswith("| 64 |")]
    assert len(rows) == 3 and all(r.rstrip().endswith("completed |") for r in rows)
    # eta_r grows with stress (shear thickening) in the tiny runs too
    etas = [float(r.split("|")[8].split("±")[0]) for r in rows]
    assert etas == sorted(etas)


def test_flow_curve_pools_the_seeds_of_a_state_point_and_flags_an_unfinished_run(tmp_path):
    """Three seeds of one state point: one value, their mean, with the error the larger of the seeds'
    spread / sqrt(3) and the propagated block errors; a run stopped by its wall-clock limit is pooled and
    its status listed."""
    import h5py

    from rheograph.analysis.flow_curves import markdown_table, state_points
    from rheograph.analysis.steady import steady_state_summary
    from rheograph.io.hdf5 import read_timeseries
    from rheograph.runs.runner import run_state_point
    from rheograph.sim.params import SimParams

    summaries = []
    for seed in (1, 2, 3):
        params = SimParams(
            n_particles=64, phi=0.72, stress=5.0, seed=seed, strain=0.3, snapshot_interval=0.1,
            steady_state_strain=0.05, disp_max=2e-3, integrator="implicit",
        )  # fmt: skip
        path = tmp_path / f"seed{seed}.h5"
        run_state_point(params, path, progress=False)
        if seed == 3:  # as a run ended by sim.max_wall_seconds leaves it
            with h5py.File(path, "r+") as h5:
                h5.attrs["status"] = "wall_limit"
        ts = read_timeseries(path)
        summaries.append(
            steady_state_summary(ts["strain"], ts["time"], ts["pressure"], ts["z_mu"], ts["z"], 5.0, 0.05)
        )
    (point,) = state_points([tmp_path])
    assert point["n_seeds"] == 3 and point["statuses"] == ["completed", "wall_limit"]
    for key in ("viscosity", "pressure", "z_mu"):
        values = np.array([s[key] for s in summaries])
        errors = np.array([s[key + "_se"] for s in summaries])
        assert len(set(values.round(9))) == 3  # independent seeds: a real pooling, not one run thrice
        assert point[key] == pytest.approx(values.mean(), rel=1e-12)
        expected = max(values.std(ddof=1) / np.sqrt(3), np.sqrt((errors**2).sum()) / 3)
        assert point[key + "_se"] == pytest.approx(expected, rel=1e-12)
    (row,) = [line for line in markdown_table([point]).splitlines() if line.startswith("| 64 |")]
    assert row.rstrip().endswith("completed,wall_limit |") and "| 3 |" in row


def test_reference_steps_per_strain_from_the_mean_dt_column(tmp_path):
    """LF_DEM's column 23 is the mean dt of each output interval: steps = interval / mean dt."""
    from rheograph.analysis.flow_curves import reference_points

    strain = np.arange(0.0, 2.0001, 0.01)
    table = np.zeros((strain.size, 29))
    table[:, 0] = strain / 0.5  # time at shear rate 0.5
    table[:, 1] = strain
    table[:, 2] = 0.5
    table[:, 3] = 20.0  # eta_r = sigma / rate
    table[:, 22] = 1e-3  # -> 0.02 time per interval / 1e-3 = 20 steps per 0.01 strain
    np.savetxt(tmp_path / "data_N400_phi0.76_s10_disp2e-3.dat", table)
    (point,) = reference_points(tmp_path, strain_min=1.0)
    assert point["steps_per_strain"] == pytest.approx(2000.0)
    assert point["viscosity"] == pytest.approx(20.0)


def test_a_reference_folder_without_lfdem_data_is_refused_by_name(tmp_path):
    from rheograph.analysis.flow_curves import reference_points
    from rheograph.errors import InputError

    with pytest.raises(InputError, match="--reference .*nosuch: no such directory"):
        reference_points(tmp_path / "nosuch")
    with pytest.raises(InputError, match=r"no LF_DEM data files \(data_N<N>_phi"):
        reference_points(tmp_path)
    (tmp_path / "data_conf_params_stress10cl_shear.dat").write_text("1 2 3\n")  # LF_DEM's own naming
    with pytest.raises(InputError, match="are not named data_N<N>_phi<phi>_s<stress>_disp<disp_max>.dat"):
        reference_points(tmp_path)


def test_reference_step_counts_match_the_reference_readme():
    """README: 1.1e4 steps per strain at disp_max 2e-3 and 1.6e4 at 1e-3 (phi 0.76, sigma/sigma0 10)."""
    from rheograph.analysis.flow_curves import reference_points

    steps = {(p["stress"], p["disp_max"]): p["steps_per_strain"] for p in reference_points(REFERENCE, 0.0)}
    assert steps[(10.0, 2e-3)] == pytest.approx(1.1e4, rel=0.05)
    assert steps[(10.0, 1e-3)] == pytest.approx(1.6e4, rel=0.05)


DATA = Path(__file__).resolve().parents[1] / "data" / "flow_curves" / "implicit"


def test_jammed_state_points_report_the_static_packing_not_a_viscosity():
    """phi = 0.80, sigma/sigma0 = 50: two seeds shear-jammed, one before the steady window; the point has
    no viscosity, and the pressure and Z_mu of the seed that has a steady window."""
    from rheograph.analysis.flow_curves import state_points

    (point,) = [p for p in state_points([DATA]) if p["stress"] == 50.0]
    assert point["jammed"] and point["n_seeds"] == 2
    assert np.isnan(point["viscosity"])
    assert 2.0 < point["pressure"] / point["stress"] < 2.2  # Pi_2D / sigma ~ 3.1, near isostatic packing
    assert 2.5 < point["z_mu"] < 3.0


def test_a_seed_held_by_two_sweeps_counts_once_with_its_longer_run(tmp_path):
    """The same start in two sweeps (a longer rerun) repeats one trajectory: pooling both would halve
    the error bar for nothing.  The longer run stands for the seed."""
    import shutil

    from rheograph.analysis.flow_curves import state_points
    from rheograph.io.hdf5 import read_run_info

    run = "N400_phi0.76_s10_seed1_d0.002_implicit"
    source = DATA.parents[1] / "paper" / "multirun" / run / "trajectory.h5"
    assert read_run_info(source)["status"] == "completed"
    for sweep in ("a", "b"):
        (tmp_path / sweep).mkdir()
        shutil.copy(source, tmp_path / sweep / "trajectory.h5")
    (alone,) = state_points([tmp_path / "a"])
    (both,) = state_points([tmp_path / "a", tmp_path / "b"])
    assert both["n_runs"] == both["n_seeds"] == 1
    for key in ("viscosity", "viscosity_se", "pressure", "z_mu"):
        assert both[key] == alone[key]


def test_slowest_shear_rate_is_the_minimum_over_the_flowing_seeds_steady_windows(tmp_path):
    """phi = 0.80, sigma/sigma0 = 20 at N = 400: two seeds arrest, one flows.  The slowest flow of the
    state point is the lowest shear rate of the flowing seed at strain >= its steady_state_strain (the
    arrested seeds' rates fall to zero and do not count), below its mean rate sigma/eta_r."""
    import shutil

    from rheograph.analysis.flow_curves import state_points
    from rheograph.io.hdf5 import read_params, read_run_info, read_timeseries

    runs = sorted((DATA.parents[1] / "paper" / "multirun").glob("N400_phi0.8_s20_seed*_implicit"))
    for run in runs:
        (tmp_path / run.name).mkdir()
        shutil.copy(run / "trajectory.h5", tmp_path / run.name / "trajectory.h5")
    (point,) = state_points([tmp_path])
    flowing = [r / "trajectory.h5" for r in runs if read_run_info(r / "trajectory.h5")["status"] != "jammed"]
    assert point["n_jammed"] == 2 and len(flowing) == 1
    ts, params = read_timeseries(flowing[0]), read_params(flowing[0])
    expected = ts["shear_rate"][ts["strain"] >= params["steady_state_strain"]].min()
    assert point["slowest_rate"] == expected
    assert 0 < point["slowest_rate"] < point["stress"] / point["viscosity"]


def test_decorrelation_strain_of_an_ar1_process_matches_its_closed_form():
    """AR(1) x_{k+1} = rho x_k + noise has autocorrelation rho^k: it crosses 1/e at lag -1/ln(rho)."""
    from rheograph.analysis.steady import decorrelation_strain

    rng = np.random.default_rng(0)
    rho, n, step = 0.9, 200_000, 0.01
    x = np.empty(n)
    x[0] = 0.0
    noise = rng.normal(size=n)
    for k in range(1, n):
        x[k] = rho * x[k - 1] + noise[k]
    expected = -step / np.log(rho)  # 0.0949 strain
    assert abs(decorrelation_strain(x, step) - expected) < 0.05 * expected
    assert np.isnan(decorrelation_strain(np.ones(50), step))


def test_transient_strain_finds_the_end_of_a_relaxation():
    from rheograph.analysis.steady import transient_strain

    rng = np.random.default_rng(1)
    strain = np.arange(0.0, 3.0, 0.01)
    values = 1.0 + 5.0 * np.exp(-strain / 0.1) + 0.05 * rng.normal(size=strain.size)
    t = transient_strain(strain, values, steady_from=1.0)
    # 5 exp(-s/0.1) drops below the 2-sigma band of 0.1-strain block means (~0.03) near s ~ 0.5
    assert 0.3 <= t <= 0.7
    assert transient_strain(strain, 1.0 + 0.05 * rng.normal(size=strain.size), 1.0) <= 0.3


def test_ensemble_transient_resolves_drifts_below_one_runs_noise_and_rarely_invents_one():
    """Runs to strain 4 (reference window from 2), per-row noise 0.1, a drift of 0.1 that ends at strain
    1.2: of one sign at every state point, or of opposite signs at two (which an average over all runs
    would cancel) -- both resolved, the transient ending with the block [1, 1.5); counting from strain 1
    then biases a run's mean by 0.1 x 0.2 / 3.  Stationary ensembles report a transient in at most about
    ``alpha`` = 5 % of cases (Bonferroni bound; measured over 200 ensembles of 10 state points x 3 runs)."""
    from rheograph.analysis.steady import ensemble_transient
    from rheograph.errors import InputError

    rng = np.random.default_rng(3)
    strain = np.arange(0.0, 4.0, 0.01)
    step = np.where(strain < 1.2, 0.1, 0.0)

    def ensemble(signs, runs_per_point=10):
        return [(strain, sign * step + 0.1 * rng.normal(size=strain.size), k) for k, sign in enumerate(signs)
                for _ in range(runs_per_point)]  # fmt: skip

    for signs in ((1, 1), (1, -1)):
        result = ensemble_transient(ensemble(signs), counted_from=1.0)
        assert result["transient"] == 1.5 and result["ceiling"] == 2.0 and not result["at_ceiling"]
        assert abs(abs(result["bias_largest"]) - 0.1 * 0.2 / 3.0) < 0.003
    assert abs(result["bias_mean"]) < 0.003  # opposite signs cancel in the mean, not in the largest
    false_alarms = np.mean(
        [ensemble_transient(ensemble([0] * 10, 3), 1.0)["transient"] > 0 for _ in range(200)]
    )
    assert false_alarms <= 0.08
    # one replicated state point leaves no scatter to test against; bad blocks are named
    assert np.isnan(ensemble_transient(ensemble([1], 5), 1.0)["transient"])
    with pytest.raises(InputError, match="block=0"):
        ensemble_transient(ensemble([1, 1]), 1.0, block=0)
