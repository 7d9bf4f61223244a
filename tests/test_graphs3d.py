"""3D snapshot graphs: edges and features under the symmetries of simple shear, a brute-force neighbour
cross-check, the physics inputs (one resistance solve, spring-sum pressure, counted frictional contacts,
relaxation) against the 3D simulator's own values, the 3D readers (rheograph trajectories, bare files,
LF_DEM 3D), and 2D/3D model refusals."""

import dataclasses
import itertools
import shutil
from pathlib import Path

import numpy as np
import pytest

from rheograph.errors import InputError
from rheograph.graphs.dataset import GraphSettings, SnapshotGraphDataset, snapshot_graphs
from rheograph.graphs.features import EDGE_FEATURES, overlap_unit
from rheograph.graphs.features3d import (
    check_separations3d,
    relax_positions3d,
    snapshot_edges3d,
    solve_viscosity3d,
)
from rheograph.io.configurations import wrap_into_box3d
from rheograph.io.snapshots import read_snapshots, snapshots_from_values, write_bare
from rheograph.runs.runner import run_state_point
from rheograph.sim.contacts import NONE
from rheograph.sim.integrator3d import SimState3D, Simulation3D
from rheograph.sim.params3d import SimParams3D
from rheograph.sim.stress3d import particle_pressure, spring_stress

ROOT = Path(__file__).resolve().parents[1]
LFDEM_3D = ROOT / "data" / "lfdem_reference_3d" / "phi0.56_n500"
# a dense frictional 3D run (N = 50, phi = 0.6, sigma/sigma0 = 20): contacts from the start
DENSE_3D = dict(
    n_particles=50,
    phi=0.6,
    stress=20.0,
    strain=0.1,
    output_interval=0.01,
    snapshot_interval=0.05,
    steady_state_strain=0.0,
    integrator="implicit",
    disp_max=5e-3,
)
ALL_3D = (*EDGE_FEATURES, "nyy_nzz")
# features whose value changes sign with the direction of the edge (vectors); the rest are pair scalars
VECTOR_FEATURES = ("dx", "dy", "sin", "cos")


@pytest.fixture(scope="module")
def dense_3d(tmp_path_factory):
    path = tmp_path_factory.mktemp("graphs3d") / "trajectory.h5"
    outcome = run_state_point(SimParams3D(**DENSE_3D), path, progress=False)
    assert outcome.status == "completed"
    return path


@pytest.fixture(scope="module")
def snaps(dense_3d):
    return read_snapshots(dense_3d)


def graph_params(snaps):
    return {**snaps.graph_params(), **snaps.numerics}


def edges_of(positions, snaps, le_offset, cutoff=0.5, contacts=None):
    box3 = (snaps.lx, snaps.ly, snaps.lz, le_offset)
    return snapshot_edges3d(positions, snaps.radii, box3, cutoff, graph_params(snaps), contacts)


def test_3d_features_are_invariant_under_translation_and_periodic_images(snaps):
    """A uniform shift of every centre (through the Lees–Edwards faces, wrapped back) and a particle
    moved by whole periods (x + lx, y + ly with the offset, z + lz) change no edge and no feature."""
    k = 1
    pos, offset = snaps.positions[k], float(snaps.le_offset[k]) + 1.3  # a sheared box's images
    index, feats, _ = edges_of(pos, snaps, offset, contacts=snaps.contacts[k])
    shift = np.array([2.9, 0.6 * snaps.ly, -0.4 * snaps.lz])
    moved = wrap_into_box3d(pos + shift, snaps.lx, snaps.ly, snaps.lz, offset)
    imaged = pos.copy()
    imaged[7] += [snaps.lx + offset, snaps.ly, -snaps.lz]
    imaged = wrap_into_box3d(imaged, snaps.lx, snaps.ly, snaps.lz, offset)
    assert np.abs(imaged - pos).max() < 1e-12
    for other in (moved,):
        index2, feats2, _ = edges_of(other, snaps, offset, contacts=snaps.contacts[k])
        np.testing.assert_array_equal(index2, index)
        for name in feats:
            np.testing.assert_allclose(feats2[name], feats[name], atol=1e-9, err_msg=name)
    assert set(feats) == set(ALL_3D)


def test_3d_features_are_invariant_under_the_symmetries_of_simple_shear(snaps):
    """Simple shear (flow x, gradient y) is symmetric under the reflection z -> -z and the point inversion
    r -> -r (the Lees–Edwards offset unchanged): every scalar feature of every pair is unchanged, a
    vector feature becomes that of the reversed edge.  A rotation about the gradient axis is not a
    symmetry: it changes the flow-frame features."""
    k = 1
    pos, offset = snaps.positions[k], float(snaps.le_offset[k]) + 0.7
    contacts = snaps.contacts[k]
    index, feats, pairs = edges_of(pos, snaps, offset, contacts=contacts)
    n_pairs = pairs["i"].size
    assert n_pairs > 50 and feats["contact"].sum() > 20 and feats["tangential_stretch"].max() > 0
    reflect = np.diag([1.0, 1.0, -1.0])
    # the recorded stretches transform with the positions (a vector, like the pair normal)
    for transform, vector_sign in ((reflect, 1.0), (-np.eye(3), -1.0)):
        moved = wrap_into_box3d(pos @ transform.T, snaps.lx, snaps.ly, snaps.lz, offset)
        moved_contacts = (contacts[0], contacts[1], np.asarray(contacts[2]) @ transform.T)
        index2, feats2, _ = edges_of(moved, snaps, offset, contacts=moved_contacts)
        np.testing.assert_array_equal(index2, index)
        for name in feats:
            sign = vector_sign if name in VECTOR_FEATURES else 1.0
            np.testing.assert_allclose(feats2[name], sign * feats[name], atol=1e-9, err_msg=name)
    # a quarter turn about the gradient axis (x -> z, z -> -x) in a cube: the pairs are those of the
    # rotated configuration, but the shear-plane projections change
    turn = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    turned = wrap_into_box3d(pos @ turn.T, snaps.lx, snaps.ly, snaps.lz, 0.0)
    _, feats3, _ = edges_of(turned, snaps, 0.0)
    _, feats0, _ = edges_of(pos, snaps, 0.0)
    np.testing.assert_allclose(np.sort(feats3["gap"]), np.sort(feats0["gap"]), atol=1e-9)
    assert not np.allclose(np.sort(feats3["nxny"]), np.sort(feats0["nxny"]), atol=1e-3)


def brute_force_gaps(pos, radii, lx, ly, lz, offset, cutoff):
    """{(i, j): surface gap} of every pair closer than ``cutoff``, over all 27 periodic images of j
    (the image across y shifted by the offset): independent of the simulator's neighbour search."""
    found = {}
    for i, j in itertools.combinations(range(len(radii)), 2):
        best = np.inf
        for ny, nx, nz in itertools.product((-1, 0, 1), repeat=3):
            d = pos[j] + [nx * lx + ny * offset, ny * ly, nz * lz] - pos[i]
            best = min(best, float(np.sqrt(d @ d)))
        gap = best - radii[i] - radii[j]
        if gap < cutoff:
            found[(i, j)] = gap
    return found


@pytest.mark.parametrize("offset", [0.0, 3.7, -5.1])
def test_3d_edges_match_a_brute_force_search_of_all_images(offset):
    """Edges of a box large enough for the cell list (N = 100: three cells a side at cutoff 0.5) equal
    the pairs within the cutoff over all periodic images, with the same gaps."""
    params = SimParams3D(n_particles=100, phi=0.5, stress=1.0)
    sim = Simulation3D(params)
    s = sim.state
    assert min(s.lx, s.ly, s.lz) // (2 * 1.4 + 0.5) >= 3  # the cell list, not its all-pairs fallback
    mapping = {"delta": 1e-3, "kn_coefficient": 2e4, "stress": 1.0, "kt_ratio": 0.5}
    pos = wrap_into_box3d(s.positions, s.lx, s.ly, s.lz, offset)
    _, feats, pairs = snapshot_edges3d(pos, s.radii, (s.lx, s.ly, s.lz, offset), 0.5, mapping)
    expected = brute_force_gaps(pos, s.radii, s.lx, s.ly, s.lz, offset, 0.5)
    got = {
        (int(i), int(j)): xi * a for i, j, xi, a in zip(pairs["i"], pairs["j"], pairs["xi"], pairs["abar"])
    }
    assert set(got) == set(expected) and len(got) > 100
    np.testing.assert_allclose([got[k] for k in expected], list(expected.values()), atol=1e-10)


def test_counted_frictional_contacts_are_the_simulators_z_mu(snaps):
    """The frictional_coordination input (pairs with F_n > F_CL from positions and sigma) equals the
    simulator's recorded Z_mu at every snapshot, and the one-solve with one pass reproduces the recorded
    eta_r of the start (strain 0, where the simulator has no spring history either): exactly from the
    simulator's positions, to the file's position quantisation from the file's."""
    settings = GraphSettings(
        min_strain=0.0,
        edge_features=ALL_3D,
        graph_inputs=("log_stress", "solve_viscosity", "frictional_coordination", "spring_pressure"),
    )
    graphs = snapshot_graphs(snaps, settings, 0)
    assert len(graphs) == 2 and graphs[0].pos.shape == (50, 3) and graphs[0].box.shape == (1, 4)
    for g in graphs:
        assert g.y_raw[0, 2] > 1.0
        assert g.u[0, 2].item() == pytest.approx(g.y_raw[0, 2].item(), abs=1e-6)
        assert g.area.item() == pytest.approx(snaps.lx * snaps.ly * snaps.lz, rel=1e-6)
    params = graph_params(snaps)
    box3 = (snaps.lx, snaps.ly, snaps.lz, float(snaps.le_offset[0]))
    eta = solve_viscosity3d(snaps.positions[0], snaps.radii, box3, params, passes=1)
    # the file stores positions quantised to 5e-8 a (rheograph.io.hdf5): 2e-6 of eta_r here
    assert eta == pytest.approx(snaps.targets[0, 0], rel=1e-5)
    # exact on the simulator's own start
    sim = Simulation3D(SimParams3D(**DENSE_3D))
    start = sim.state.positions.copy()
    first = DENSE_3D["stress"] / sim.step().shear_rate
    assert first == pytest.approx(snaps.targets[0, 0], rel=1e-12)
    assert solve_viscosity3d(start, snaps.radii, box3, params, passes=1) == pytest.approx(first, rel=1e-12)
    assert graphs[0].physics[0, 0].item() == pytest.approx(
        solve_viscosity3d(snaps.positions[0], snaps.radii, box3, params), rel=1e-12
    )


def test_spring_pressure_is_the_trace_of_the_3d_simulators_contact_spring_stress(snaps):
    """The physics-only Pi, (2 pi sigma / V) sum r a_bar overlap / delta_sigma, is -tr/3 of the 3D
    simulator's contact-spring stress at that configuration (tangential springs carry no trace)."""
    k = 1
    params = SimParams3D(**{**DENSE_3D, "n_particles": snaps.n_particles})
    state = SimState3D(
        positions=snaps.positions[k].copy(),
        radii=snaps.radii,
        lx=snaps.lx,
        ly=snaps.ly,
        lz=snaps.lz,
        le_offset=float(snaps.le_offset[k]),
    )
    sim = Simulation3D(params, state)
    lp = sim.linear_problem()
    virial = spring_stress(sim.state.pair_i, lp.nvec, lp.r, lp.f_on_i, sim.state.contact_state)
    expected = particle_pressure(sim.stress_factor * virial)
    (graph,) = snapshot_graphs(
        dataclasses.replace(snaps, positions=snaps.positions[k : k + 1], le_offset=snaps.le_offset[k : k + 1],
                            strain=snaps.strain[k : k + 1], targets=snaps.targets[k : k + 1],
                            jammed=snaps.jammed[k : k + 1], contacts=None),
        GraphSettings(), 0, training=False,
    )  # fmt: skip
    assert expected > 0 and (sim.state.contact_state != NONE).sum() > 20
    assert graph.physics[0, 1].item() == pytest.approx(expected, rel=1e-10)
    # and its sum per volume is the contact_normal feature's
    _, feats, pairs = edges_of(snaps.positions[k], snaps, float(snaps.le_offset[k]))
    volume = snaps.lx * snaps.ly * snaps.lz
    total = feats["contact_normal"][: pairs["i"].size].sum()
    assert 2 * np.pi * snaps.stress * total / volume == pytest.approx(expected, rel=1e-10)
    assert overlap_unit(2e4) == pytest.approx(6 * np.pi / 2e4)


def test_3d_relaxation_reaches_its_strain_and_measures_the_relaxed_configuration(snaps):
    params = graph_params(snaps)
    box3 = (snaps.lx, snaps.ly, snaps.lz, float(snaps.le_offset[1]))
    relaxed = relax_positions3d(snaps.positions[1].copy(), snaps.radii, box3, params, strain=0.005)
    assert relaxed.positions.shape == (50, 3) and 0.005 <= relaxed.strain < 0.006
    assert np.isfinite(relaxed.viscosity) and relaxed.viscosity > 0 and relaxed.pressure > 0
    moved = np.abs(relaxed.positions - snaps.positions[1]).max(axis=1)  # a few wrap across the box
    assert 0 < np.median(moved) < 0.1
    # its Z_mu is the count from the relaxed positions
    _, feats, pairs = edges_of(relaxed.positions, snaps, relaxed.le_offset)
    assert relaxed.z_mu == pytest.approx(2 * feats["frictional"][: pairs["i"].size].sum() / 50)
    settings = GraphSettings(
        min_strain=0.0,
        relax_strain=0.005,
        graph_inputs=("log_stress", "relaxed_viscosity", "relaxed_coordination"),
    )
    (graph,) = snapshot_graphs(snaps, settings, 0, training=True)[1:]
    assert graph.relaxed_strain.item() >= 0.005 and graph.u[0, 2].item() == pytest.approx(relaxed.z_mu)


def test_3d_overlapping_centres_and_short_boxes_are_refused(snaps):
    pos = snaps.positions[0].copy()
    pos[3] = pos[4] + [0.1, 0.0, 0.0]
    box3 = (snaps.lx, snaps.ly, snaps.lz, 0.0)
    with pytest.raises(InputError, match="particles 3 and 4"):
        check_separations3d("x", pos, snaps.radii, box3)
    squeezed = dataclasses.replace(snaps, positions=np.stack([pos, pos]))
    with pytest.raises(InputError, match="one centre within the other"):
        snapshot_graphs(squeezed, GraphSettings(min_strain=0.0), 0)
    with pytest.raises(InputError, match=r"too large for .* x .* x .* a\) must exceed"):
        snapshot_graphs(snaps, GraphSettings(min_strain=0.0, cutoff=1.5), 0)


def test_a_3d_only_feature_is_refused_on_a_2d_snapshot():
    values = dict(
        positions=[[0.0, 0.0], [3.0, 0.0]], radii=[1.0, 1.0], box=[10.0, 10.0], le_offset=0.0, stress=1.0,
        phi=2 * np.pi / 100, mu=1.0, kn_coefficient=2e4, kt_ratio=0.5, delta=1e-3, lub_max_gap=0.5,
    )  # fmt: skip
    snaps = snapshots_from_values(values, "two")
    with pytest.raises(InputError, match=r"2D snapshot.*3D-only feature\(s\) \['nyy_nzz'\]"):
        snapshot_graphs(snaps, GraphSettings(edge_features=("gap", "nyy_nzz")), 0, training=False)


def test_bare_3d_files_read_and_round_trip(snaps, tmp_path):
    """A bare .npz with (N, 3) positions and a box of three edges is a 3D snapshot; write_bare writes
    one back; a dim key that disagrees, or 2D positions in a 3D box, are refused by name."""
    path = tmp_path / "three.npz"
    write_bare(path, snaps)
    back = read_snapshots(path)
    assert back.dim == 3 and back.lz == snaps.lz
    np.testing.assert_allclose(back.positions, snaps.positions, atol=1e-12)
    g1 = snapshot_graphs(back, GraphSettings(min_strain=0.0), 0, training=False)
    g2 = snapshot_graphs(snaps, GraphSettings(min_strain=0.0), 0, training=False)
    np.testing.assert_allclose(g1[1].edge_attr.numpy(), g2[1].edge_attr.numpy())
    values = dict(np.load(path))
    with pytest.raises(InputError, match="dim = 2 but the box has 3 edges"):
        snapshots_from_values({**values, "dim": 2}, "x")
    assert snapshots_from_values({**values, "dim": 3}, "x").dim == 3
    with pytest.raises(InputError, match=r"positions must be \(S, N, 3\)"):
        snapshots_from_values({**values, "positions": values["positions"][..., :2]}, "x")
    with pytest.raises(InputError, match="volume fraction"):
        snapshots_from_values({**values, "phi": 0.5}, "x")


def test_lfdem_3d_par_file_is_mapped_onto_our_axes(tmp_path):
    """LF_DEM's 3D par_ snapshot (vorticity y, gradient z) read as ours = (x, z, -y): the one resistance
    solve of its strain-0 configuration gives LF_DEM's first shear rate (0.553951 at sigma/sigma0 = 10)
    to its printed digits; with the axes unmapped it would not."""
    par = tmp_path / "par_s10_disp1e-3.dat"
    shutil.copy(LFDEM_3D / "par0_s10_disp1e-3.dat", par)
    shutil.copy(LFDEM_3D / "data_s10_disp1e-3.dat", tmp_path / "data_s10_disp1e-3.dat")
    # LF_DEM copies its start into input_<name>.dat: the box to full precision (the par header's 6 digits
    # move the periodic images by 3e-5 a, which shifts the first shear rate by 9e-5)
    shutil.copy(LFDEM_3D / "D3N500VF0.56Bidi1.4_0.5Cubic_1_.dat", tmp_path / "input_s10_disp1e-3.dat")
    snaps = read_snapshots(par, LFDEM_3D / "parameters_3d_s10_disp1e-3.txt")
    assert snaps.dim == 3 and snaps.kind == "lfdem" and snaps.positions.shape == (1, 500, 3)
    assert snaps.phi == pytest.approx(0.56, abs=1e-4) and snaps.stress == 10.0
    raw = np.loadtxt(par, comments="#")[:, 2:5]
    np.testing.assert_allclose(snaps.positions[0][:, 0], raw[:, 0], atol=1e-9)
    np.testing.assert_allclose(snaps.positions[0][:, 1], raw[:, 2], atol=1e-9)
    assert np.allclose(np.abs(snaps.positions[0][:, 2]), np.abs(raw[:, 1]), atol=1e-9)
    np.testing.assert_allclose(snaps.positions[0][:, 2], -raw[:, 1], atol=1e-9)
    params = {**snaps.graph_params(), **snaps.numerics}
    box3 = (snaps.lx, snaps.ly, snaps.lz, float(snaps.le_offset[0]))
    eta = solve_viscosity3d(snaps.positions[0], snaps.radii, box3, params, passes=1)
    assert snaps.lx == snaps.ly == snaps.lz == pytest.approx(17.6389303175718, rel=1e-15)
    assert 10.0 / eta == pytest.approx(0.553951, rel=2e-6)
    assert snaps.targets[0, 0] == pytest.approx(10.0 / 0.553951, rel=1e-6)
    # the 2D reading of the same rows (the x-z plane, vorticity dropped) is not this configuration
    unmapped = snaps.positions[0][:, [0, 2, 1]]
    eta_unmapped = solve_viscosity3d(unmapped, snaps.radii, box3, params, passes=1)
    assert abs(10.0 / eta_unmapped - 0.553951) > 1e-3


def test_a_3d_dataset_builds_and_records_its_dimension(dense_3d, tmp_path):
    from rheograph.learn.datamodule import suspension_record

    settings = GraphSettings(min_strain=0.0, edge_features=("gap", "nxny", "nyy_nzz", "frictional"))
    dataset = SnapshotGraphDataset([dense_3d], settings, tmp_path)
    assert len(dataset) == 2 and dataset[0].pos.shape == (50, 3)
    assert suspension_record([dense_3d])["dim"] == 3


@pytest.mark.slow
def test_train_py_trains_a_3d_model_that_predicts_3d_snapshots(tmp_path):
    """train.py on three tiny 3D runs (fold 0, 2 epochs): its bundle records dim 3, and the model
    predicts a 3D trajectory (about 45 s)."""
    import torch
    from conftest import train_tiny_fold

    import rheograph

    data = tmp_path / "data"
    data.mkdir()
    for seed, stress in enumerate((5.0, 10.0, 20.0), start=1):
        params = SimParams3D(**{**DENSE_3D, "stress": stress, "snapshot_interval": 0.02, "seed": seed})
        assert run_state_point(params, data / f"s{stress:g}.h5", progress=False).status == "completed"
    run = train_tiny_fold(
        [data / "s5.h5"],
        tmp_path,
        "graph.edge_features=[gap,nxny,nyy_nzz,frictional]",
        "graph.graph_inputs=[log_stress,solve_viscosity,frictional_coordination,spring_pressure]",
    )
    assert torch.load(run / "fold0.pt", weights_only=True)["domain"]["dim"] == 3
    snaps = read_snapshots(data / "s10.h5")
    table = rheograph.load_model(run).predict_snapshots(snaps)
    assert np.isfinite(table["eta_pred"]).all() and len(table["eta_pred"]) == len(snaps) >= 5


def test_solve_configuration_restarts_each_pass_from_the_snapshot(snaps):
    """Each pass of the one-solve starts again from the snapshot, only the dt its implicit springs assume
    carried over: two passes are one step of a fresh simulation told that dt."""
    params = SimParams3D(**DENSE_3D)

    def fresh(dt_assumed=0.0):
        state = SimState3D(
            positions=snaps.positions[1].copy(), radii=snaps.radii, lx=snaps.lx, ly=snaps.ly, lz=snaps.lz,
            le_offset=float(snaps.le_offset[1]), dt_assumed=dt_assumed,
        )  # fmt: skip
        return Simulation3D(params, state)

    first = fresh()
    first.step()
    two = fresh()
    result = two.solve_configuration(passes=2)
    assert two.state.steps == 1
    assert result.shear_rate == fresh(first.state.dt_assumed).step().shear_rate
    with pytest.raises(ValueError, match="fresh simulation"):
        two.solve_configuration()
