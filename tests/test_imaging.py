"""Imprecise snapshots: the gap-shell inputs, graphs rebuilt from re-noised positions, the relaxation of
a noisy configuration, the noise domain of a model and the imaging model end to end."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from rheograph.errors import InputError
from rheograph.graphs.dataset import GraphSettings, NoisyGraphs, snapshot_graphs
from rheograph.graphs.features import (
    SHELL_INPUTS,
    SHELL_WIDTHS,
    relax_positions,
    shell_inputs,
    snapshot_pairs,
)
from rheograph.graphs.targets import Target, TargetSpec
from rheograph.io.configurations import wrap_into_box
from rheograph.io.snapshots import read_snapshots

ROOT_DATA = Path(__file__).resolve().parents[1] / "data" / "paper" / "multirun"
IMAGING = dict(
    edge_features=("gap", "dx", "dy", "nxny", "nxx_nyy"),
    graph_inputs=("log_stress", "position_noise", *SHELL_INPUTS),
    targets=TargetSpec(pi=Target(scale=0.1, per_stress=True)),
    noise_range=(1e-3, 0.03),
    min_strain=0.05,
)


def brute_force_pairs(positions, radii, lx, ly, offset):
    """Every pair's surface gap and unit normal by the minimum image over all pairs (O(N^2))."""
    n = radii.size
    i, j = np.triu_indices(n, 1)
    d = positions[j] - positions[i]
    images = np.round(d[:, 1] / ly)
    d[:, 0] -= images * offset
    d[:, 1] -= images * ly
    d[:, 0] -= np.round(d[:, 0] / lx) * lx
    r = np.hypot(d[:, 0], d[:, 1])
    return r - radii[i] - radii[j], d / r[:, None]


def test_shell_inputs_are_the_brute_force_pair_counts_and_fabric(tiny_files):
    snaps = read_snapshots(tiny_files[1])
    k = len(snaps) - 1
    pos, offset = snaps.positions[k], snaps.le_offset[k]
    pairs = snapshot_pairs(pos, snaps.radii, snaps.lx, snaps.ly, offset, 0.5, snaps.graph_params())
    got = shell_inputs(pairs, snaps.n_particles)
    gap, n = brute_force_pairs(pos, snaps.radii, snaps.lx, snaps.ly, offset)
    for w in SHELL_WIDTHS:
        inside = gap < w
        assert got[f"shell_pairs_{w:g}"] == pytest.approx(2 * inside.sum() / snaps.n_particles)
        assert got[f"shell_fabric_{w:g}"] == pytest.approx(np.mean(n[inside, 0] * n[inside, 1]))
        assert got[f"shell_normal_{w:g}"] == pytest.approx(np.mean(n[inside, 0] ** 2 - n[inside, 1] ** 2))
    # under shear the near-contact network is compressive along the 135 degree axis: n_x n_y < 0
    assert got["shell_fabric_0.03"] < 0
    assert got["shell_pairs_0.01"] < got["shell_pairs_0.03"] < got["shell_pairs_0.1"] < got["shell_pairs_0.3"]


def test_noisy_graphs_redraw_fresh_noise_and_keep_targets(tiny_files):
    settings = GraphSettings(**IMAGING)
    snaps = read_snapshots(tiny_files[2])
    graphs = snapshot_graphs(snaps, settings, run_id=0)
    params = {0: snaps.graph_params()}
    fixed = NoisyGraphs(graphs, settings, params, fresh=False, seed=3)
    fresh = NoisyGraphs(graphs, settings, params, fresh=True)
    torch.manual_seed(0)  # fresh draws follow torch's generator; the RMS check below is a 2.4-sigma band
    a, b = fixed[1], fixed[1]
    assert np.array_equal(a.pos.numpy(), b.pos.numpy())  # validation: one draw per graph
    c, d = fresh[1], fresh[1]
    assert not np.array_equal(c.pos.numpy(), d.pos.numpy())  # training: new noise every access
    noise_column = settings.graph_inputs.index("position_noise")
    for g in (a, c, d):
        eps = float(g.u[0, noise_column])
        assert 1e-3 <= eps <= 0.03
        assert np.array_equal(g.y_raw.numpy(), graphs[1].y_raw.numpy())
        # the positions moved by eps per coordinate (RMS), up to the wrap into the box
        moved = g.pos.numpy() - graphs[1].pos.numpy()
        moved[:, 0] -= np.round(moved[:, 0] / snaps.lx) * snaps.lx
        moved[:, 1] -= np.round(moved[:, 1] / snaps.ly) * snaps.ly
        assert np.sqrt(np.mean(moved**2)) == pytest.approx(eps, rel=0.15)
    # a vanishing noise rebuilds the exact graph
    still = NoisyGraphs(graphs, dataclasses.replace(settings, noise_range=(1e-12, 1e-12)), params, fresh=True)
    exact, rebuilt = graphs[1], still[1]
    assert np.array_equal(exact.edge_index.numpy(), rebuilt.edge_index.numpy())
    assert np.allclose(exact.edge_attr.numpy(), rebuilt.edge_attr.numpy(), atol=1e-6)
    assert np.allclose(exact.u.numpy()[0, 2:], rebuilt.u.numpy()[0, 2:], atol=1e-6)


def test_noisy_graphs_of_a_polydisperse_snapshot_read_each_particles_own_radius():
    """Re-noised graphs are rebuilt with the radii of the snapshot, not its species' nominal sizes: at a
    vanishing noise a 10 % polydisperse snapshot gives back its exact graph (with the nominal radii
    its gaps would be off by ~0.1 a and most edges would change)."""
    run = ROOT_DATA.parents[1] / "polydisperse/multirun/N400_phi0.76_s5_poly0.1_seed1_d0.002_implicit"
    snaps = read_snapshots(run / "trajectory.h5")
    snaps = snaps.select([len(snaps) - 1])
    assert np.std(snaps.radii[snaps.radii < 1.2]) > 0.05  # spread radii
    settings = GraphSettings(**{**IMAGING, "min_strain": 0.0, "noise_range": (1e-12, 1e-12)})
    graphs = snapshot_graphs(snaps, settings, run_id=0)
    exact, rebuilt = graphs[0], NoisyGraphs(graphs, settings, {0: snaps.graph_params()}, fresh=False)[0]
    assert np.array_equal(exact.radius.numpy(), snaps.radii)
    assert np.array_equal(exact.edge_index.numpy(), rebuilt.edge_index.numpy())
    assert np.allclose(exact.edge_attr.numpy(), rebuilt.edge_attr.numpy(), atol=1e-6)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(noise_range=(0.01,)), "noise_range"),
        (dict(noise_range=(0.05, 0.01)), "eps_min <= eps_max"),
        (dict(noise_range=(0.0, 0.01)), "0 < eps_min"),
        (dict(graph_inputs=("log_stress", "solve_viscosity")), "drop solve_viscosity"),
        (dict(edge_features=("gap", "sliding")), "contact history"),
        (dict(cutoff=0.2), "widest gap shell"),
        (dict(graph_inputs=("log_stress", "relaxed_viscosity"), noise_copies=2), "relax_strain > 0"),
        (
            dict(graph_inputs=("position_noise", "relaxed_pressure"), noise_copies=2, relax_strain=0.01),
            "log_stress",
        ),
        (
            dict(
                targets=TargetSpec(
                    eta_r=Target(scale=1.0, relative_to="relaxed_viscosity"),
                    pi=Target(scale=0.1, per_stress=True),
                ),
                noise_copies=2,
                relax_strain=0.01,
            ),
            "add relaxed_viscosity",
        ),
    ],
)
def test_imaging_settings_are_checked_by_name(change, message):
    with pytest.raises(InputError, match=message):
        GraphSettings(**{**IMAGING, **change})


def test_a_short_shear_relaxes_the_overlaps_that_noise_creates(tiny_files):
    snaps = read_snapshots(tiny_files[1])
    params = {**snaps.graph_params(), **snaps.numerics}
    k = len(snaps) - 1
    rng = np.random.default_rng(0)
    noisy = wrap_into_box(
        snaps.positions[k] + rng.normal(0.0, 0.01, snaps.positions[k].shape),
        snaps.lx,
        snaps.ly,
        snaps.le_offset[k],
    )

    def largest_overlap(pos, offset):  # units of delta_sigma
        return snapshot_pairs(pos, snaps.radii, snaps.lx, snaps.ly, offset, 0.5, params)["overlap"].max()

    exact = largest_overlap(snaps.positions[k], snaps.le_offset[k])
    relaxed, offset, reached, *_ = relax_positions(
        noisy, snaps.radii, snaps.lx, snaps.ly, snaps.le_offset[k], params, 0.05
    )
    # noise of 0.01 a makes overlaps of ~30x those the springs hold; a short stretch of the flow brings
    # them back to the simulator's own (here, phi = 0.72: 36 -> 7.7 / 2.4 / 0.8 delta_sigma after 0.01 /
    # 0.02 / 0.05 strain, exact 0.95; at phi = 0.76, N = 400, 0.01 suffices: 48 -> 1.5, exact 1.5)
    assert largest_overlap(noisy, snaps.le_offset[k]) > 5 * exact
    assert largest_overlap(relaxed, offset) < 2 * exact
    # the box was sheared by the strain asked for (the image offset moved by about 0.05 Ly)
    moved = (offset - snaps.le_offset[k]) % snaps.lx
    assert 0.05 <= reached < 0.055 and reached * snaps.ly == pytest.approx(moved, rel=1e-9)
    # a step budget too short for the strain (as for an arrested packing, which creeps) stops there and
    # says how far it got
    _, offset, reached, *_ = relax_positions(
        noisy, snaps.radii, snaps.lx, snaps.ly, snaps.le_offset[k], params, 0.05, max_steps=3
    )
    assert 0 < reached < 0.05 and reached * snaps.ly == pytest.approx(
        (offset - snaps.le_offset[k]) % snaps.lx
    )


def test_relaxation_observables_are_those_of_the_configuration_it_reaches(tiny_files):
    from rheograph.graphs.features import solve_viscosity

    snaps = read_snapshots(tiny_files[2])
    params = {**snaps.graph_params(), **snaps.numerics}
    k = len(snaps) - 1
    pos, radii, lx, ly, offset = snaps.positions[k], snaps.radii, snaps.lx, snaps.ly, snaps.le_offset[k]
    # no strain to go: the observables are one resistance solve of the snapshot as given, springs
    # unstretched — the one-solve's first pass, and the CLM count that the graph inputs make of it
    still = relax_positions(pos, radii, lx, ly, offset, params, 0.0)
    assert np.array_equal(still.positions, pos) and still.strain == 0.0
    assert still.viscosity == solve_viscosity(pos, radii, lx, ly, offset, params, passes=1)
    assert still.viscosity_early == still.viscosity
    settings = GraphSettings(
        edge_features=("gap",), graph_inputs=("log_stress", "frictional_coordination", "spring_pressure")
    )
    (graph,) = snapshot_graphs(
        dataclasses.replace(
            snaps,
            positions=pos[None],
            le_offset=offset[None],
            strain=snaps.strain[[k]],
            targets=snaps.targets[[k]],
            jammed=snaps.jammed[[k]],
            contacts=None,
        ),
        settings,
        run_id=0,
        training=False,
    )
    assert still.z_mu == pytest.approx(float(graph.u[0, 1]), abs=1e-12)
    # with springs unstretched and gaps closing, Pi is the spring sum plus lubrication and dashpots: the
    # springs carry most of it in a dense flow at sigma/sigma0 = 50
    assert 0.5 < float(graph.physics[0, 1]) / still.pressure < 1.5
    # a short stretch of flow from exact positions continues the run's own flow: the springs it loads
    # bring eta_r back to the recorded value (here within 0.8 %, where the one-solve is 16 % high: the
    # tangential springs the snapshot does not record), Pi within 0.5 %, Z_mu within two contacts of 64
    relaxed = relax_positions(pos, radii, lx, ly, offset, params, 0.004)
    assert 0.004 <= relaxed.strain < 0.006
    eta, pressure, z_mu = snaps.targets[k]
    assert abs(np.log(still.viscosity / eta)) > 0.1
    assert abs(np.log(relaxed.viscosity / eta)) < 0.03
    assert relaxed.pressure == pytest.approx(pressure, rel=0.03)
    assert abs(relaxed.z_mu - z_mu) <= 4 / snaps.n_particles


def test_noise_domain_of_exact_and_imaging_models():
    from rheograph.learn.predict import noise_reason

    exact = {"position_noise": 0.0}
    imaging = {"position_noise": [1e-4, 0.05]}
    assert noise_reason(exact, 2.2e-5) == ""  # LF_DEM's 6-digit rounding
    assert "use an imaging model" in noise_reason(exact, 0.01)
    assert noise_reason(imaging, 0.01) == ""
    assert "beyond the 0.05 a" in noise_reason(imaging, 0.1)
    assert "exact model" in noise_reason(imaging, 0.0)


def test_imaging_model_end_to_end_needs_the_noise_level(tiny_files, tmp_path):
    """Trains a tiny imaging model through train.py and predicts bare snapshots with it."""
    from conftest import train_tiny_fold

    from rheograph.learn.predict import load_model

    run_dir = train_tiny_fold(tiny_files, tmp_path, "graph=imaging")
    model = load_model(run_dir)
    # the bundle is a Lightning checkpoint of the same model
    from rheograph.learn.module import SurrogateModule

    checkpoint = SurrogateModule.load_from_checkpoint(
        run_dir / "fold0.pt", map_location="cpu", weights_only=True
    )
    bundle = model.models[0][0].state_dict()
    assert all(torch.equal(v, checkpoint.state_dict()[k]) for k, v in bundle.items())
    snaps = read_snapshots(tiny_files[2])
    values = dict(
        positions=snaps.positions[-2:], radii=snaps.radii, box=[snaps.lx, snaps.ly],
        le_offset=snaps.le_offset[-2:], stress=snaps.stress, phi=snaps.phi,
        mu=0.5, kn_coefficient=2e4, kt_ratio=0.5, delta=1e-3, lub_max_gap=0.5,
    )  # fmt: skip
    with pytest.raises(InputError, match="position_noise"):
        model.predict(**values)
    inside = model.predict(**values, position_noise=0.01)
    assert inside["in_domain"].tolist() == [1, 1] and np.isfinite(inside["eta_pred"]).all()
    beyond = model.predict(**values, position_noise=0.2)
    assert beyond["in_domain"].tolist() == [0, 0] and "beyond the 0.05 a" in beyond["notes"][0]
    # the noise level is an input: the prediction depends on it
    assert not np.allclose(inside["eta_pred"], beyond["eta_pred"])


def test_state_mean_table_interpolates_in_log_stress_at_the_nearest_phi():
    import torch

    from rheograph.learn.module import state_mean, state_table

    phi = torch.tensor([0.76, 0.76, 0.76, 0.76, 0.80, 0.80])
    stress = torch.tensor([1.0, 1.0, 10.0, 100.0, 1.0, 100.0])
    values = torch.tensor(
        [
            [1.0, 2.0, 0.0],
            [3.0, 4.0, 0.2],
            [5.0, 6.0, 1.0],
            [7.0, 8.0, 2.0],
            [9.0, 1.0, 0.5],
            [11.0, 2.0, 2.5],
        ]
    )
    scored = torch.ones_like(values, dtype=torch.bool)
    scored[5, 0] = False  # an arrested packing: no eta_r at (0.80, 100)
    table = state_table(phi, torch.log(stress), values, scored)
    query_phi = torch.tensor([0.761, 0.76, 0.79, 0.80, 0.76])
    query_stress = torch.tensor([1.0, np.sqrt(10.0), 100.0, 10.0, 1000.0])
    got = state_mean(table, query_phi, torch.log(query_stress)).numpy()
    assert np.allclose(got[0], [2.0, 3.0, 0.1])  # mean of the two snapshots at (0.76, 1)
    assert np.allclose(got[1], [3.5, 4.5, 0.55])  # halfway in log sigma between 1 and 10
    # phi 0.79 -> the nearest trained phi 0.80; eta_r known there only at sigma = 1
    assert np.allclose(got[2], [9.0, 2.0, 2.5])
    assert np.allclose(got[3], [9.0, 1.5, 1.5])
    assert np.allclose(got[4], [7.0, 8.0, 2.0])  # held constant beyond the trained stresses


def test_a_model_on_the_state_mean_predicts_the_lookup_when_its_network_says_nothing(tiny_files):
    import torch
    from conftest import resgcn
    from torch_geometric.loader import DataLoader

    from rheograph.learn.module import SurrogateModule

    settings = GraphSettings(**IMAGING)
    graphs = [g for f in tiny_files for g in snapshot_graphs(read_snapshots(f), settings, run_id=0)]
    batch = next(iter(DataLoader(graphs, batch_size=len(graphs))))
    module = SurrogateModule(
        net=resgcn(len(settings.edge_features), len(settings.graph_inputs)), targets=settings.targets,
        on_state_mean=True,
    )  # fmt: skip
    module.fit_target_scaling(batch.y, batch.stress, batch.u, phi=batch.phi, jammed=batch.jammed)
    # the standardised output z = -mean/std is a learned value of 0: the prediction is the state mean
    zero = (-module.target_mean / module.target_std).expand(len(graphs), 3).float()
    pred = module._transformed(zero, batch).double()
    for stress in np.unique(batch.stress.numpy()):
        at = batch.stress.numpy() == stress
        y = batch.y.double()[at]
        assert torch.allclose(pred[at, 0], y[:, 0].mean().expand(int(at.sum())), atol=1e-5)
        assert torch.allclose(pred[at, 2], y[:, 2].mean().expand(int(at.sum())), atol=1e-5)
        # Pi: the mean of asinh(Pi / (s sigma)), mapped back to sigma0
        per_stress = torch.asinh(torch.sinh(y[:, 1]) / stress)
        expected = torch.asinh(torch.sinh(per_stress.mean()) * stress)
        assert torch.allclose(pred[at, 1], expected.expand(int(at.sum())), atol=1e-5)


def test_positions_only_model_predicts_without_the_stress(tiny_files, tmp_path):
    """graph=imaging_positions: trained through train.py, it predicts eta_r, Z_mu and mu_eff = sigma/Pi
    from positions alone; Pi in sigma0 only where the snapshot states sigma.  Exact models refuse a
    snapshot without a stress by name."""
    from conftest import train_tiny_fold

    from rheograph.learn.predict import load_model

    run_dir = train_tiny_fold(
        tiny_files, tmp_path, "experiment=imaging", "graph=imaging_positions", "data.split=random"
    )
    model = load_model(run_dir)
    snaps = read_snapshots(tiny_files[2])
    values = dict(
        positions=snaps.positions[-2:], radii=snaps.radii, box=[snaps.lx, snaps.ly],
        le_offset=snaps.le_offset[-2:], phi=snaps.phi, position_noise=0.01,
        mu=0.5, kn_coefficient=2e4, kt_ratio=0.5, delta=1e-3, lub_max_gap=0.5,
    )  # fmt: skip
    blind = model.predict(stress=None, **values)
    assert np.isfinite(blind["eta_pred"]).all() and np.isfinite(blind["z_mu_pred"]).all()
    assert np.isnan(blind["pressure_pred"]).all() and (blind["mu_eff_pred"] > 0).all()
    told = model.predict(stress=snaps.stress, **values)
    # the stress changes nothing the model reads; it only converts Pi / sigma to sigma0
    assert np.allclose(told["eta_pred"], blind["eta_pred"])
    assert np.allclose(told["pressure_pred"], snaps.stress * blind["pressure_per_stress_pred"])
    exact = load_model("N400_phi0.76")
    with pytest.raises(InputError, match="imposed stress"):
        exact.predict(stress=None, **{**values, "position_noise": None})


def test_shipped_imaging_model_serves_noisy_snapshots_and_the_exact_one_points_to_it():
    import rheograph

    path = ROOT_DATA / "N400_phi0.76_s10_seed1_d0.002_implicit" / "trajectory.h5"
    snaps = read_snapshots(path)
    rng = np.random.default_rng(0)
    positions = snaps.positions[-1] + rng.normal(0.0, 0.01, snaps.positions[-1].shape)
    values = dict(
        positions=positions, radii=snaps.radii, box=(snaps.lx, snaps.ly), le_offset=snaps.le_offset[-1],
        stress=snaps.stress, phi=snaps.phi, mu=0.5, kn_coefficient=2e4, kt_ratio=0.5, delta=1e-3,
        lub_max_gap=0.5, position_noise=0.01, eta_r=snaps.targets[-1:, 0],
    )  # fmt: skip
    exact = rheograph.load_model("N400_phi0.76").predict(**values)
    assert exact["in_domain"][0] == 0 and "N400_phi0.76_imaging" in exact["notes"][0]
    imaging = rheograph.load_model("N400_phi0.76_imaging").predict(**values)
    assert imaging["in_domain"][0] == 1 and imaging["notes"][0] == ""
    # within a factor 2 of the simulator's eta_r at 0.01 a of noise (the exact model is off by orders)
    assert 0.5 < imaging["eta_pred"][0] / snaps.targets[-1, 0] < 2.0


def test_every_shipped_imaging_model_is_the_one_named_for_tracked_positions_at_its_area_fraction():
    """For positions known to particle-tracking precision, the models offered (in the exact models'
    notes) at each imaging model's (φ, N) are the imaging models, and never an exact one."""
    from rheograph.learn.predict import TRACKING_PRECISION, models_for_noise, trained_noise
    from rheograph.learn.registry import list_models, model_paths, read_card

    imaging = [name for name in list_models() if "imaging" in name]
    assert {"N400_phi0.70_imaging", "N400_phi0.76_imaging", "N400_phi0.80_imaging"} <= set(imaging)
    for name in imaging:
        card = read_card(model_paths(name)[0])
        low, high = trained_noise({"position_noise": card["position_noise"]})
        assert low <= TRACKING_PRECISION <= high, name
        (phi, _), n_particles = card["domain"]["phi"], card["domain"]["n_particles"][0]
        offered = models_for_noise(phi, n_particles, TRACKING_PRECISION)
        assert name in offered and all("imaging" in other for other in offered), (name, offered)


def test_undeclared_position_noise_is_flagged_by_its_overlaps_and_names_the_imaging_model():
    """A snapshot that does not state its precision reads as exact; noise of 0.003 a makes overlaps
    beyond any the simulator produced at that stress (the exact model is then off by a factor 10-40),
    and the flag says why and which model serves measured positions."""
    import rheograph

    path = ROOT_DATA / "N400_phi0.76_s10_seed2_d0.002_implicit" / "trajectory.h5"
    snaps = read_snapshots(path)
    rng = np.random.default_rng(0)
    values = dict(
        positions=snaps.positions[-1] + rng.normal(0.0, 0.003, snaps.positions[-1].shape),
        radii=snaps.radii, box=(snaps.lx, snaps.ly), le_offset=snaps.le_offset[-1], stress=snaps.stress,
        phi=snaps.phi, mu=0.5, kn_coefficient=2e4, kt_ratio=0.5, delta=1e-3, lub_max_gap=0.5,
    )  # fmt: skip
    table = rheograph.load_model("N400_phi0.76").predict(**values)
    assert table["in_domain"][0] == 0
    assert "'overlap'" in table["notes"][0] and "use N400_phi0.76_imaging" in table["notes"][0]
    # the exact snapshot itself is not flagged
    values["positions"] = snaps.positions[-1]
    assert rheograph.load_model("N400_phi0.76").predict(**values)["in_domain"][0] == 1


def test_a_snapshot_whose_relaxation_runs_out_of_steps_is_flagged(monkeypatch):
    """An arrested packing creeps (phi = 0.80, sigma/sigma0 = 200 at N = 400: ~2000 steps for 0.01
    strain against 50-90 for a flowing one; one that does not move would never get there): relaxation
    stops at its step budget, and the prediction says its inputs read a partly repaired configuration."""
    import rheograph
    from rheograph.graphs import features

    monkeypatch.setattr(features, "RELAX_MAX_STEPS", 5)
    path = ROOT_DATA / "N400_phi0.76_s10_seed1_d0.002_implicit" / "trajectory.h5"
    snaps = read_snapshots(path)
    values = dict(
        positions=snaps.positions[-1], radii=snaps.radii, box=(snaps.lx, snaps.ly),
        le_offset=snaps.le_offset[-1], stress=snaps.stress, phi=snaps.phi, mu=0.5, kn_coefficient=2e4,
        kt_ratio=0.5, delta=1e-3, lub_max_gap=0.5, position_noise=0.01,
    )  # fmt: skip
    table = rheograph.load_model("N400_phi0.76_imaging").predict(**values)
    assert table["in_domain"][0] == 0
    assert "relaxation cut short of its 0.01 strain by its step budget" in table["notes"][0]


def test_a_snapshot_of_another_system_size_is_flagged_and_names_the_model_trained_at_it():
    import rheograph

    path = ROOT_DATA / "N2000_phi0.76_s10_seed1_d0.002_implicit" / "trajectory.h5"
    snaps = read_snapshots(path)
    values = dict(
        positions=snaps.positions[-1], radii=snaps.radii, box=(snaps.lx, snaps.ly),
        le_offset=snaps.le_offset[-1], stress=snaps.stress, phi=snaps.phi, mu=0.5, kn_coefficient=2e4,
        kt_ratio=0.5, delta=1e-3, lub_max_gap=0.5,
    )  # fmt: skip
    table = rheograph.load_model("N400_phi0.76").predict(**values)
    assert table["in_domain"][0] == 0
    assert "N = 2000 not among the trained N [400] (use N2000_phi0.76)" in table["notes"][0]
    assert rheograph.load_model("N2000_phi0.76").predict(**values)["in_domain"][0] == 1
