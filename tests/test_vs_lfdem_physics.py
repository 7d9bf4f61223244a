"""Frictional physics against LF_DEM (slow: N = 400 runs to strain 3; run with ``pytest -m slow``).
At φ = 0.76, N = 400, σ/σ0 = 10 and 200 the converged scheme (linearly implicit springs, disp_max 2e-3)
must agree with LF_DEM at its finest committed discretisations: Z_μ and Π/σ within 10 %, η_r within 3
combined standard errors.  And LF_DEM's own discretisation (explicit Euler with its lagged step control,
``sim.lagged_step_control=true``) at disp_max 2e-3 must reproduce LF_DEM's biased η_r at that step — the
same number, well below the converged one.  Different initial configurations (LF_DEM's generator, ours)
make this statistical: each run's error is its block standard error over strain 1–end, and the runs of one
side are pooled as flowcurve pools seeds — three seeds of ours, every LF_DEM start of the reference.  One
run of a chaotic flow is one draw: its mean over two strain scatters by its standard error from start to
start, and with round-off from one machine or library build to another (σ/σ0 = 200, seed 1: η_r 215 in
the committed dataset run, 205 on a later machine; seeds 2 and 3 identical), so a single run on each
side would pass or fail by the draw.
References (LF_DEM output, tests/data/lfdem_phi0.76 and data/lfdem_phi0.76_n400; their READMEs): σ/σ0 =
10 at disp_max 5e-4 (strain 1.5) and 1e-3 (strain 3, and a second start to strain 2); σ/σ0 = 200 at 5e-4
(four starts, strain 2–3) and 2.5e-4 (two starts, strain 2–3); at 1e-3 LF_DEM is ~20 % low there
(docs/validation/time_step.md).
"""

from pathlib import Path

import numpy as np
import pytest

from rheograph.analysis.steady import steady_state_summary
from rheograph.io.lfdem import read_lfdem_data

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = ROOT / "tests" / "data" / "lfdem_phi0.76"
RUNS = ROOT / "data" / "lfdem_phi0.76_n400"
REFERENCES = {
    10.0: [
        FIXTURES / "data_N400_phi0.76_s10_disp5e-4.dat",
        FIXTURES / "data_N400_phi0.76_s10_disp1e-3.dat",
        RUNS / "s10" / "data_conf_params_stress10cl_shear.dat",
    ],
    200.0: sorted(RUNS.glob("d*e-4/s200*/data_conf_params_stress200cl_shear.dat")),
}
SEEDS = (1, 2, 3)
KEYS = ("viscosity", "pressure", "z_mu")

pytestmark = pytest.mark.slow


def _summary(strain, time, pressure, z_mu, z, stress):
    return steady_state_summary(strain, time, pressure, z_mu, z, stress, 1.0)


def pooled(runs: list[dict]) -> dict:
    """Runs of one state point pooled as rheograph.analysis.flow_curves pools seeds: per key the mean over
    runs, the error the larger of their spread / sqrt(n) and the propagated block errors."""
    out = {}
    for key in KEYS:
        values = np.array([r[key] for r in runs])
        errors = np.array([r[key + "_se"] for r in runs])
        spread = values.std(ddof=1) / np.sqrt(values.size) if values.size > 1 else 0.0
        out[key] = float(values.mean())
        out[key + "_se"] = float(max(spread, np.sqrt((errors**2).sum()) / values.size))
    return out


def lfdem_reference(paths, stress) -> dict:
    """Pooled LF_DEM value and error per key over the runs in ``paths``."""
    runs = []
    for path in paths:
        d = read_lfdem_data(path)
        runs.append(_summary(d["strain"], d["time"], d["pressure"], d["z_mu"], d["z"], stress))
    return pooled(runs)


def ours(tmp_path, stress, seed=1, **scheme) -> dict:
    from rheograph.io.hdf5 import read_timeseries
    from rheograph.runs.runner import run_state_point
    from rheograph.sim.params import SimParams

    params = SimParams(
        n_particles=400, phi=0.76, stress=stress, seed=seed, strain=3.0, snapshot_interval=3.0, **scheme
    )
    path = tmp_path / f"s{stress:g}_{params.integrator}_seed{seed}.h5"
    run_state_point(params, path, progress=False)
    ts = read_timeseries(path)
    return _summary(ts["strain"], ts["time"], ts["pressure"], ts["z_mu"], ts["z"], stress)


@pytest.mark.parametrize("stress", sorted(REFERENCES))
def test_converged_scheme_agrees_with_lfdem_in_frictional_states(tmp_path, stress):
    assert len(REFERENCES[200.0]) == 6  # four LF_DEM starts at 5e-4, two at 2.5e-4: none missing
    reference = lfdem_reference(REFERENCES[stress], stress)
    mine = pooled([ours(tmp_path, stress, seed, integrator="implicit", disp_max=2e-3) for seed in SEEDS])
    assert reference["z_mu"] > 1.5  # frictional: most contacts above the critical load
    for key in ("pressure", "z_mu"):
        assert mine[key] == pytest.approx(reference[key], rel=0.10), (key, mine[key], reference[key])
    allowed = 3.0 * np.hypot(mine["viscosity_se"], reference["viscosity_se"])
    assert abs(mine["viscosity"] - reference["viscosity"]) < allowed, (mine, reference)


def test_lfdem_discretisation_reproduces_lfdem_bias(tmp_path):
    """σ/σ0 = 10, disp_max 2e-3: LF_DEM's explicit Euler gives η_r ≈ 100, a third below the converged
    ≈ 150; rheograph with LF_DEM's discretisation gives the same biased value, and the converged scheme at
    the same disp_max does not."""
    biased = lfdem_reference([FIXTURES / "data_N400_phi0.76_s10_disp2e-3.dat"], 10.0)
    converged = lfdem_reference(REFERENCES[10.0], 10.0)
    assert biased["viscosity"] < 0.8 * converged["viscosity"]  # the reference's own bias
    mine = ours(tmp_path, 10.0, integrator="euler", lagged_step_control=True, disp_max=2e-3)
    allowed = 3.0 * np.hypot(mine["viscosity_se"], biased["viscosity_se"])
    assert abs(mine["viscosity"] - biased["viscosity"]) < allowed, (mine, biased)
    assert mine["viscosity"] < 0.8 * converged["viscosity"]
