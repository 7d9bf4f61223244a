"""Confocal-grade 3D snapshots: position noise that is coarser along the microscope's optical axis than
across it.  The noisy copies and the re-noised training graphs move the particles by the stated RMS
per axis; the model is told both precisions; a 2D snapshot, a bad range or axis are refused in one line;
the 2D noise is drawn exactly as before; predictions flag an axial precision beyond the trained one."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from rheograph.errors import InputError
from rheograph.graphs.dataset import GraphSettings, NoisyGraphs, noisy_copy, snapshot_graphs
from rheograph.io.configurations import wrap_into_box
from rheograph.io.snapshots import read_snapshots, write_bare
from rheograph.learn.predict import domain_report
from rheograph.runs.runner import run_state_point
from rheograph.sim.params3d import SimParams3D

ROOT = Path(__file__).resolve().parents[1]
PAPER_RUN = ROOT / "data" / "paper" / "multirun" / "N400_phi0.76_s10_seed1_d0.002_implicit" / "trajectory.h5"
SHELLS = tuple(
    f"shell_{kind}_{w:g}" for w in (0.01, 0.03, 0.1, 0.3) for kind in ("pairs", "fabric", "normal")
)
CONFOCAL = dict(
    min_strain=0.0,
    edge_features=("gap", "dx", "dy", "nxny", "nxx_nyy", "nyy_nzz"),
    graph_inputs=("log_stress", "position_noise", "axial_noise", *SHELLS),
    noise_range=(1e-3, 0.03),
    axial_noise_range=(0.05, 0.3),
)


@pytest.fixture(scope="module")
def snaps(tmp_path_factory):
    """A dense 3D run, N = 100, phi = 0.55, sigma/sigma0 = 10: four snapshots."""
    path = tmp_path_factory.mktemp("confocal") / "trajectory.h5"
    params = SimParams3D(
        n_particles=100, phi=0.55, stress=10.0, strain=0.1, output_interval=0.01, snapshot_interval=0.025,
        steady_state_strain=0.0, integrator="implicit", disp_max=5e-3,
    )  # fmt: skip
    assert run_state_point(params, path, progress=False).status == "completed"
    return read_snapshots(path)


def displacement(new, old, lx, ly, lz, le_offset):
    """Minimum-image displacements (N, 3) [a] of noisy positions from their originals."""
    d = new - old
    images = np.round(d[:, 1] / ly)
    d[:, 1] -= images * ly
    d[:, 0] -= images * le_offset
    d[:, 0] -= np.round(d[:, 0] / lx) * lx
    d[:, 2] -= np.round(d[:, 2] / lz) * lz
    return d


@pytest.mark.parametrize("axis", [1, 2])
def test_noisy_copies_are_coarser_along_the_optical_axis(snaps, axis):
    """RMS displacement per axis: eps_axial along the optical axis, eps across it (N x S = 400 samples
    per axis: the RMS is within 10 % at 3 standard deviations)."""
    noisy = noisy_copy(snaps, (0.01, 0.01), seed=1, axial_noise_range=(0.2, 0.2), optical_axis="xyz"[axis])
    moved = np.concatenate(
        [
            displacement(noisy.positions[k], snaps.positions[k], snaps.lx, snaps.ly, snaps.lz, o)
            for k, o in enumerate(snaps.le_offset)
        ]
    )
    rms = np.sqrt(np.mean(moved**2, axis=0))
    expected = np.full(3, 0.01)
    expected[axis] = 0.2
    assert rms == pytest.approx(expected, rel=0.1)
    assert noisy.position_noise == pytest.approx(np.full(len(snaps), 0.01), rel=1e-12)
    assert noisy.axial_noise == pytest.approx(np.full(len(snaps), 0.2), rel=1e-12)


def test_two_dimensional_noisy_copies_are_drawn_as_before():
    """Isotropic 2D noise: one eps per snapshot, then the Gaussian displacements, from one generator in
    that order (what the published imaging models were trained on)."""
    snaps = read_snapshots(PAPER_RUN)
    snaps = dataclasses.replace(
        snaps, positions=snaps.positions[:3], le_offset=snaps.le_offset[:3], strain=snaps.strain[:3]
    )
    noisy = noisy_copy(snaps, (1e-3, 0.05), seed=[4, 1])
    rng = np.random.default_rng([4, 1])
    eps = np.exp(rng.uniform(np.log(1e-3), np.log(0.05), 3))
    for k in range(3):
        p = snaps.positions[k]
        expected = wrap_into_box(p + rng.normal(0.0, eps[k], p.shape), snaps.lx, snaps.ly, snaps.le_offset[k])
        assert np.array_equal(noisy.positions[k], expected)
    assert noisy.axial_noise is None


def test_the_model_is_told_both_precisions(snaps):
    """Re-noised training graphs carry the drawn in-plane eps and the axial eps as inputs, and move the
    particles by them."""
    settings = GraphSettings(**CONFOCAL)
    graphs = snapshot_graphs(snaps, settings, run_id=0)
    exact = graphs[-1]
    assert exact.u[0, 1] == 0.0 and exact.u[0, 2] == 0.0  # simulator output: exact on every axis
    noisy = NoisyGraphs(graphs, settings, {0: snaps.graph_params()}, fresh=False, seed=2)[len(graphs) - 1]
    eps, eps_axial = float(noisy.u[0, 1]), float(noisy.u[0, 2])
    assert 1e-3 <= eps <= 0.03 and 0.05 <= eps_axial <= 0.3
    moved = displacement(
        noisy.pos.numpy(), exact.pos.numpy(), snaps.lx, snaps.ly, snaps.lz, snaps.le_offset[-1]
    )
    rms = np.sqrt(np.mean(moved**2, axis=0))
    assert rms[1] == pytest.approx(eps_axial, rel=0.3)  # 100 samples: within 30 % at 4 standard deviations
    assert max(rms[0], rms[2]) < 0.2 * eps_axial or eps_axial < 5 * eps


def test_stated_axial_precision_is_the_input_of_exact_graphs(snaps):
    settings = GraphSettings(**CONFOCAL)
    stated = dataclasses.replace(snaps, position_noise=0.02, axial_noise=0.25)
    g = snapshot_graphs(stated, settings, run_id=0)[0]
    assert float(g.u[0, 1]) == pytest.approx(0.02) and float(g.u[0, 2]) == pytest.approx(0.25)
    isotropic = dataclasses.replace(snaps, position_noise=0.02, axial_noise=None)
    assert float(snapshot_graphs(isotropic, settings, run_id=0)[0].u[0, 2]) == pytest.approx(0.02)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(noise_range=()), "beside the in-plane graph.noise_range"),
        (dict(axial_noise_range=(0.3, 0.05)), "eps_min <= eps_max"),
        (dict(axial_noise_range=(0.0, 0.3)), "0 < eps_min"),
        (dict(axial_noise_range=()), "axial_noise .* needs graph.axial_noise_range"),
        (dict(optical_axis="w"), "graph.optical_axis='w' is invalid"),
    ],
)
def test_bad_confocal_settings_are_refused_by_name(change, message):
    with pytest.raises(InputError, match=message):
        GraphSettings(**{**CONFOCAL, **change})


def test_a_two_dimensional_snapshot_has_no_optical_axis(tmp_path):
    snaps = read_snapshots(PAPER_RUN)
    with pytest.raises(InputError, match="a 2D snapshot has no optical axis"):
        snapshot_graphs(snaps, GraphSettings(**{**CONFOCAL, "edge_features": ("gap", "nxny")}), run_id=0)
    with pytest.raises(InputError, match="needs a 3D snapshot"):
        noisy_copy(snaps, (0.01, 0.01), seed=0, axial_noise_range=(0.1, 0.1))
    path = tmp_path / "flat.npz"
    write_bare(path, dataclasses.replace(snaps, position_noise=0.01, axial_noise=0.1))
    with pytest.raises(InputError, match="axial_noise = 0.1 is the precision along the optical axis of a 3D"):
        read_snapshots(path)


def test_bare_3d_files_keep_their_axial_precision(snaps, tmp_path):
    path = tmp_path / "confocal.npz"
    write_bare(path, dataclasses.replace(snaps, position_noise=0.02, axial_noise=0.3))
    back = read_snapshots(path)
    assert back.position_noise == 0.02 and back.axial_noise == 0.3


def test_predictions_flag_an_axial_precision_beyond_the_trained_one(snaps):
    settings = GraphSettings(**CONFOCAL)
    graphs = snapshot_graphs(snaps, settings, run_id=0)
    attr = np.concatenate([g.edge_attr.numpy() for g in graphs])
    domain = {
        "phi": [0.55, 0.55], "stress": [10.0, 10.0], "n_particles": [100],
        "edge_min": (attr.min(axis=0) - 1.0).tolist(), "edge_max": (attr.max(axis=0) + 1.0).tolist(),
        "position_noise": [1e-3, 0.03], "axial_noise": [0.05, 0.3],
    }  # fmt: skip

    def reasons(domain, noise, axial):
        stated = dataclasses.replace(snaps, position_noise=noise, axial_noise=axial)
        return domain_report(domain, stated, graphs, settings)[1][0]

    assert reasons(domain, 0.02, 0.25) == []
    (reason,) = reasons(domain, 0.02, 0.5)
    assert "0.5 a along the optical axis (y), beyond the 0.3 a" in reason
    # a model trained on isotropic noise: the coarsest axis decides
    isotropic = {k: v for k, v in domain.items() if k != "axial_noise"}
    (reason,) = reasons(isotropic, 0.02, 0.25)
    assert "positions known to 0.25 a, beyond the 0.03 a" in reason


def test_centres_closer_than_a_radius_are_refused_unless_the_stated_precision_explains_them(snaps):
    """A centre 0.9 a from another's is refused for exact positions and at the 2D imaging range's widest
    noise (0.05 a), but not where the precision along one axis is 0.3 a (confocal depth), which brings
    touching centres that close in one pair of ~10^3."""
    from rheograph.graphs.features3d import check_separations3d
    from rheograph.io.configurations import wrap_into_box3d

    box3 = (snaps.lx, snaps.ly, snaps.lz, float(snaps.le_offset[0]))
    pos = snaps.positions[0].copy()
    small = np.flatnonzero(snaps.radii == 1.0)[:2]
    pos[small[1]] = pos[small[0]] + np.array([0.0, 0.9, 0.0])
    pos = wrap_into_box3d(pos, *box3)
    for noise in (0.0, 0.05):
        with pytest.raises(InputError, match="are 0.9 a apart, one centre within the other particle"):
            check_separations3d("x", pos, snaps.radii, box3, noise)
    check_separations3d("x", pos, snaps.radii, box3, 0.3)


@pytest.mark.slow
def test_a_confocal_model_trains_predicts_and_is_scored_on_noise_pairs(tmp_path, capsys):
    """train.py graph=imaging_confocal on three tiny 3D runs (fold 0, 2 epochs), then: its card's domain
    holds both trained ranges, predictions flag an axial precision beyond them, and bench.confocal_noise
    scores every predictor at every noise pair, the lookup alike at all of them (it reads no positions);
    about a minute."""
    import torch
    from conftest import load_bench_script, train_tiny_fold

    import rheograph

    data = tmp_path / "data"
    data.mkdir()
    for seed, stress in enumerate((5.0, 10.0, 20.0), start=1):
        params = SimParams3D(
            n_particles=50, phi=0.6, stress=stress, strain=0.1, output_interval=0.01, snapshot_interval=0.02,
            steady_state_strain=0.0, integrator="implicit", disp_max=5e-3, seed=seed,
        )  # fmt: skip
        assert run_state_point(params, data / f"s{stress:g}.h5", progress=False).status == "completed"
    run = train_tiny_fold([data / "s5.h5"], tmp_path, "graph=imaging_confocal", "data.split=grouped")
    domain = torch.load(run / "fold0.pt", weights_only=True)["domain"]
    assert domain["position_noise"] == [1e-4, 0.05] and domain["axial_noise"] == [1e-3, 0.5]
    model = rheograph.load_model(run / "fold0.pt")
    snaps = read_snapshots(data / "s10.h5")
    inside = model.predict_snapshots(dataclasses.replace(snaps, position_noise=0.02, axial_noise=0.3))
    beyond = model.predict_snapshots(dataclasses.replace(snaps, position_noise=0.02, axial_noise=0.8))
    assert np.isfinite(inside["eta_pred"]).all() and "optical axis" not in " ".join(inside["notes"])
    assert not beyond["in_domain"].any() and "along the optical axis (y)" in beyond["notes"][0]
    bench = load_bench_script("confocal_noise")
    args = [str(run), "--folds", "0", "--noise", "0", "0.03", "--axial-noise", "0", "0.3", "--no-write"]
    assert bench.main([*args, "--cache-dir", str(tmp_path / "cache")]) == 0
    lines = capsys.readouterr().out.splitlines()
    lookup = [line for line in lines if "| lookup: mean at (φ, σ) |" in line]
    network = [line for line in lines if "| graph network |" in line]
    assert len(lookup) == len(network) == 4
    assert len({line.split("|", 3)[3] for line in lookup}) == 1  # the same scores at every noise pair


def test_a_model_over_several_volume_fractions_is_scored_at_each_apart():
    """bench.confocal_noise --phi keeps the test snapshots of one volume fraction: a predictor exact at
    φ 0.5 scores 1 there however it does at 0.56, and a φ with no test snapshot is refused in one line."""
    from conftest import load_bench_script

    from rheograph.naming import state_point_key

    bench = load_bench_script("confocal_noise")
    rng = np.random.default_rng(0)
    phi = np.repeat([0.5, 0.56], 40)
    stress = np.tile(np.repeat([2.0, 10.0], 20), 2)
    true = np.stack([np.log10(30 * stress * (1 + phi)), np.log10(stress), 3 + phi], 1) + rng.normal(
        0, 0.1, (80, 3)
    )
    pred = np.where((phi == 0.5)[:, None], true, true + rng.normal(0, 0.5, (80, 3)))
    row = (pred, true, state_point_key(phi, stress), np.zeros(80, bool), stress)
    level = (0.03, 0.3)
    results = [{(name, level): row for name in bench.PREDICTORS}]
    at_050 = bench.pooled_scores(results, [level], 0.5)[("graph network", level)]
    at_056 = bench.pooled_scores(results, [level], 0.56)[("graph network", level)]
    pooled = bench.pooled_scores(results, [level])[("graph network", level)]
    assert at_050["r2_log_eta"] == pytest.approx(1.0) and at_056["r2_log_eta"] < 0.9
    assert at_056["r2_log_eta"] < pooled["r2_log_eta"] < 1.0
    with pytest.raises(SystemExit, match="--phi 0.53: no test snapshot at that volume fraction"):
        bench.pooled_scores(results, [level], 0.53)
