"""The shipped 3D surrogates (N500_phi0.56_3d, N500_phi0.50_3d, pooled_N500_3d) on committed 3D
trajectories: each reads its own kind of snapshot close to the simulator's values, flags a snapshot at
a volume fraction it was not trained on as outside its domain (naming the model that covers it), states
the dimension in its card, and refuses a 2D snapshot."""

import json
from pathlib import Path

import numpy as np
import pytest

import rheograph
from rheograph.errors import InputError
from rheograph.io.snapshots import read_snapshots

ROOT = Path(__file__).resolve().parents[1]
MODEL = "N500_phi0.56_3d"
RUN_3D = ROOT / "data/flow_curves_3d/multirun/N500_phi0.56_s10_seed2_d0.002_implicit_3d/trajectory.h5"
RUN_3D_050 = ROOT / "data/flow_curves_3d/multirun/N500_phi0.5_s10_seed2_d0.002_implicit_3d/trajectory.h5"
RUN_3D_053 = ROOT / "data/flow_curves_3d/multirun/N500_phi0.53_s200_seed1_d0.002_implicit_3d/trajectory.h5"
RUN_3D_058 = ROOT / "data/flow_curves_3d/multirun/N500_phi0.58_s10_seed1_d0.002_implicit_3d/trajectory.h5"
RUN_2D = ROOT / "data/paper/multirun/N400_phi0.76_s10_seed1_d0.002_implicit/trajectory.h5"


@pytest.fixture(scope="module")
def model():
    return rheograph.load_model(MODEL)


def steady_snapshots(path):
    snaps = read_snapshots(path)
    return snaps.select(snaps.strain >= 1.0)


def assert_close_to_the_simulator(table, n_snapshots, eta_factor, pressure_mean, pressure_max):
    """Every snapshot predicted and in domain; η_r within ``eta_factor`` in the mean of |log10 ratio|, Π
    within ``pressure_mean`` (relative) in the mean and ``pressure_max`` at worst, Z_μ within 0.02."""
    assert len(table["eta_pred"]) == n_snapshots >= 15
    assert np.mean(np.abs(np.log10(table["eta_pred"] / table["eta_sim"]))) < np.log10(eta_factor)
    pressure_error = np.abs(table["pressure_pred"] / table["pressure_sim"] - 1.0)
    assert pressure_error.mean() < pressure_mean and pressure_error.max() < pressure_max
    assert np.max(np.abs(table["z_mu_pred"] - table["z_mu_sim"])) < 0.02
    assert table["in_domain"].all()


def test_the_3d_model_reads_a_3d_trajectory_close_to_the_simulator(model):
    """Steady snapshots (strain >= 1) of one committed run (each trajectory is held out by one fold
    model): the ensemble's η_r within 12 % of the simulator's in the mean of |log10 ratio| (measured
    0.028 decades, 7 %), Π within 1 % in the mean and 2.5 % at worst (measured 0.5 % and 1.2 %; R² log Π
    0.99996) and Z_μ within 0.02 of the simulator's (measured 0.004 at worst: learned on the count),
    every snapshot in domain."""
    snaps = steady_snapshots(RUN_3D)
    assert_close_to_the_simulator(model.predict_snapshots(snaps), len(snaps), 1.12, 0.01, 0.025)


def test_the_phi_050_model_reads_its_own_trajectory_and_flags_the_other_phi(model, capsys):
    """N500_phi0.50_3d on steady snapshots of a committed φ = 0.50 run: η_r within 8 % in the mean of
    |log10 ratio| (measured 0.014 decades, 3 %), Π within 2.5 % in the mean and 5 % at worst (measured 1.3 %
    and 2.8 %), Z_μ within 0.02, every snapshot in domain.  The φ = 0.56 model on the same snapshots
    flags every one as outside its domain and names the model that covers it."""
    snaps = steady_snapshots(RUN_3D_050)
    table = rheograph.load_model("N500_phi0.50_3d").predict_snapshots(snaps)
    assert_close_to_the_simulator(table, len(snaps), 1.08, 0.025, 0.05)
    capsys.readouterr()
    other = model.predict_snapshots(snaps)
    assert not other["in_domain"].any()
    expected = "phi = 0.5 outside the trained [0.56, 0.56] (use N500_phi0.50_3d or pooled_N500_3d)"
    assert expected in capsys.readouterr().err


def test_the_pooled_model_reads_a_phi_between_the_full_sets_and_flags_one_beyond(capsys):
    """pooled_N500_3d (trained on every φ of the set, 0.50–0.58) on steady snapshots of the φ = 0.53,
    σ/σ0 = 200 run (one trajectory at that φ, held out by one fold model): η_r within 12 % in the mean of
    |log10 ratio| (measured 0.025 decades, 6 %), Π within 2 % in the mean and 4 % at worst (measured 0.8 %
    and 2.1 %), Z_μ within 0.02 (measured 0.004), every snapshot in domain.  The set's one φ = 0.58 run
    (σ/σ0 = 200) is held out by the first fold model, whose training range [0.50, 0.57] the model's
    domain is: a φ = 0.58 snapshot is flagged (there the prediction is 24 % off the simulator's at
    σ/σ0 = 10: measured 0.094 decades)."""
    pooled = rheograph.load_model("pooled_N500_3d")
    snaps = steady_snapshots(RUN_3D_053)
    assert_close_to_the_simulator(pooled.predict_snapshots(snaps), len(snaps), 1.12, 0.02, 0.04)
    capsys.readouterr()
    assert not pooled.predict_snapshots(steady_snapshots(RUN_3D_058))["in_domain"].any()
    assert "phi = 0.58 outside the trained [0.5, 0.57]" in capsys.readouterr().err


def test_the_3d_model_refuses_a_2d_snapshot_in_one_line(model):
    with pytest.raises(InputError, match=r"2D snapshots, but model .* is a 3D model"):
        model.predict_snapshots(read_snapshots(RUN_2D))


@pytest.mark.parametrize("name", [MODEL, "N500_phi0.50_3d", "pooled_N500_3d"])
def test_the_3d_card_states_its_dimension(name):
    card = json.loads((ROOT / "src/rheograph/models" / name / "card.json").read_text())
    assert card["domain"]["dim"] == 3 and card["domain"]["n_particles"] == [500]
    text = (ROOT / "src/rheograph/models" / name / "card.md").read_text()
    assert "* 3D: spheres in a cubic box" in text
