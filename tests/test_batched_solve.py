"""The physics inputs' resistance problems solved together in dense batches (rheograph.graphs.batched_solve)
against the sparse solver one simulation at a time, on the CPU (the path a GPU takes, on another device):
the same steps, graphs and predictions to round-off; the lockstep drivers equal the simulator's own step."""

import dataclasses

import numpy as np
import pytest
import torch
from test_device import few_snapshots

from rheograph.errors import InputError
from rheograph.graphs.batched_solve import DENSE_MAX_PARTICLES, DenseBatchSolver, physics_solver_device
from rheograph.sim import SimParams, Simulation
from rheograph.sim.integrator import own_solvers, solve_configurations, step_together
from rheograph.sim.integrator3d import Simulation3D
from rheograph.sim.params3d import SimParams3D

CPU = torch.device("cpu")


def running(sim, steps: int):
    for _ in range(steps):
        sim.step()
    return sim


def dense_frictional_sims():
    """Three running simulations of different sizes and dimensions, with lubricated gaps and frictional
    contacts: 2D N = 60 and 80 (phi 0.80, sigma/sigma0 50, 30 steps) and 3D N = 50 (phi 0.58, 60 steps)."""
    sims = [
        running(Simulation(SimParams(n_particles=n, phi=0.80, stress=50.0, seed=n, disp_max=5e-3)), 30)
        for n in (60, 80)
    ]
    sims.append(running(Simulation3D(SimParams3D(n_particles=50, phi=0.58, stress=50.0, disp_max=5e-3)), 60))
    return sims


def test_dense_batches_solve_what_each_sparse_solver_solves():
    """Velocities of one step's problems (2D and 3D, three sizes: three batches) from the dense batched
    Cholesky equal the sparse Cholesky's to round-off (the matrices' condition ~1e6 leaves ~1e-10 of
    float64's 1e-16), also when the batch budget splits them one by one."""
    sims = dense_frictional_sims()
    problems = [sim.prepare_step() for sim in sims]
    assert all(lp.n_contacts and lp.n_frictional for lp in problems)
    sparse = own_solvers(sims, problems)
    for budget in (2**31, 1):
        dense = DenseBatchSolver(CPU, max_bytes=budget)(sims, problems)
        for mine, reference in zip(dense, sparse):
            assert mine.shape == reference.shape
            np.testing.assert_allclose(mine, reference, rtol=0, atol=1e-9 * np.abs(reference).max())


def test_a_problem_the_dense_factorisation_refuses_goes_to_the_sparse_solver(monkeypatch):
    """A matrix that is not positive definite (here: negated) is handed to the simulation's own solver,
    which reports it as a simulation does; a problem with nothing interacting is solved by the drag."""
    sims = dense_frictional_sims()[:2]
    problems = [sim.prepare_step() for sim in sims]
    problems[0] = problems[0]._replace(data=-problems[0].data)
    problems[1] = problems[1]._replace(n_active=0)
    handed = []
    for sim in sims:
        monkeypatch.setattr(sim, "solve_linear", lambda lp, _sim=sim: handed.append(_sim) or lp.rhs.T)
    DenseBatchSolver(CPU)(sims, problems)
    assert len(handed) == 2 and set(handed) == set(sims)


def test_stepping_together_with_the_own_solvers_is_stepping_alone():
    """step_together (the lockstep of batched physics inputs) with each simulation's own solver takes
    exactly the steps step() takes, bit for bit, and solve_configurations is solve_configuration."""
    alone, together = dense_frictional_sims(), dense_frictional_sims()
    for _ in range(5):
        mine = step_together(together, record=True)
        theirs = [sim.step(record=True) for sim in alone]
        for a, b in zip(mine, theirs):
            assert (a.dt, a.shear_rate) == (b.dt, b.shear_rate)
            np.testing.assert_array_equal(a.stress, b.stress)
    for a, b in zip(together, alone):
        np.testing.assert_array_equal(a.state.positions, b.state.positions)
    fresh = [Simulation(SimParams(n_particles=60, phi=0.78, stress=20.0, seed=s)) for s in (1, 2)]
    expected = [Simulation(SimParams(n_particles=60, phi=0.78, stress=20.0, seed=s)) for s in (1, 2)]
    results = solve_configurations(fresh, passes=2)
    for result, sim in zip(results, expected):
        assert result.shear_rate == sim.solve_configuration(2).shear_rate
    with pytest.raises(ValueError, match="fresh simulation"):
        solve_configurations(fresh)


@pytest.mark.parametrize(
    ("model", "source"),
    [
        ("N400_phi0.76", None),
        ("N400_phi0.76_imaging", None),  # the relaxation's 0.01 strain, stepped together
        (
            "N500_phi0.56_3d",
            "data/flow_curves_3d/multirun/N500_phi0.56_s10_seed1_d0.002_implicit_3d/trajectory.h5",
        ),
    ],
)
def test_graphs_with_dense_batched_physics_inputs_equal_the_sparse_ones(model, source):
    """Two snapshots' graphs through the dense batches (on the CPU device) and through the sparse path:
    the one-solve eta_r, the relaxation's observables and positions to round-off, the rest identical."""
    from rheograph.graphs.dataset import snapshot_graphs
    from rheograph.io.snapshots import read_snapshots
    from rheograph.learn.predict import load_model

    if source is None:
        snaps = few_snapshots(2)
    else:
        full = read_snapshots(source)
        snaps = dataclasses.replace(full.select(slice(len(full) - 2, len(full))), contacts=None)
    if model.endswith("_imaging"):
        snaps.position_noise = 0.01
    surrogate = load_model(model)
    numerics = surrogate.solve_numerics(snaps.phi, snaps.n_particles)
    sparse = snapshot_graphs(snaps, surrogate.settings, 0, numerics, training=False)
    dense = snapshot_graphs(snaps, surrogate.settings, 0, numerics, training=False, solve_device=CPU)
    for a, b in zip(dense, sparse):
        np.testing.assert_allclose(a.physics.numpy(), b.physics.numpy(), rtol=1e-9)
        np.testing.assert_allclose(a.u.numpy(), b.u.numpy(), rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(a.pos.numpy(), b.pos.numpy(), rtol=0, atol=1e-9)
        assert a.edge_index.shape == b.edge_index.shape
        assert a.relaxed_strain.isnan().all() == (not model.endswith("_imaging"))


def test_the_physics_solver_choice():
    """auto: dense batches on a CUDA device up to DENSE_MAX_PARTICLES, the sparse solver otherwise; an
    unknown choice refused in one line (the API and predict.py)."""
    cuda = torch.device("cuda")  # a device name: nothing runs on it here
    assert physics_solver_device("auto", cuda, DENSE_MAX_PARTICLES) == cuda
    assert physics_solver_device("auto", cuda, DENSE_MAX_PARTICLES + 1) is None
    assert physics_solver_device("auto", CPU, 400) is None
    assert physics_solver_device("sparse", cuda, 1200) is None
    assert physics_solver_device("dense", CPU, 10**6) == CPU
    with pytest.raises(InputError, match=r"physics_solver='qr' is unknown"):
        physics_solver_device("qr", CPU, 1200)
    from rheograph.learn.predict import load_model

    with pytest.raises(InputError, match=r"physics_solver='qr' is unknown"):
        load_model("N400_phi0.76", physics_solver="qr")


def test_predictions_through_dense_batches_equal_the_sparse_ones():
    from rheograph.learn.predict import load_model

    snaps = few_snapshots(3)
    sparse = load_model("N400_phi0.76", physics_solver="sparse").predict_snapshots(snaps)
    dense = load_model("N400_phi0.76", physics_solver="dense").predict_snapshots(snaps)
    for column in ("eta_pred", "pressure_pred", "z_mu_pred", "eta_solve", "pressure_spring", "z_mu_counted"):
        np.testing.assert_allclose(dense[column], sparse[column], rtol=1e-6)


def test_dense_matrices_beyond_the_memory_granted_are_refused_in_one_line(monkeypatch):
    from rheograph.resources import MEMORY_LIMIT_ENV

    sims = dense_frictional_sims()[:1]
    problems = [sim.prepare_step() for sim in sims]
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "0.0001")  # 100 kB: less than one 180 x 180 problem's three copies
    with pytest.raises(InputError, match=r"dense matrices \(1 x 180 rows.*use physics_solver=sparse"):
        DenseBatchSolver(CPU)(sims, problems)


def test_a_graph_cache_built_with_dense_batches_equals_the_sparse_one(tiny_files, tmp_path):
    """The training set's cache with data.physics_solver=dense (on the CPU, as on a GPU trainer) holds
    the sparse build's graphs, the one-solve eta_r to round-off; an unknown choice is refused in one line."""
    from rheograph.graphs.dataset import GraphSettings, SnapshotGraphDataset
    from rheograph.learn.datamodule import SnapshotDataModule

    settings = GraphSettings(min_strain=0.05)
    sparse = SnapshotGraphDataset(tiny_files, settings, tmp_path / "sparse")
    dense = SnapshotGraphDataset(tiny_files, settings, tmp_path / "dense", physics=("dense", CPU))
    assert len(dense) == len(sparse) > 20
    np.testing.assert_allclose(dense.physics.numpy(), sparse.physics.numpy(), rtol=1e-9)
    assert not np.array_equal(dense.physics.numpy(), sparse.physics.numpy())  # the other solver, truly
    np.testing.assert_array_equal(dense.edge_attr.numpy(), sparse.edge_attr.numpy())
    with pytest.raises(InputError, match=r"physics_solver='gpu' is unknown"):
        SnapshotDataModule(tiny_files, physics_solver="gpu")


def test_snapshots_stepped_together_in_chunks_give_the_same_graphs(monkeypatch):
    """Three snapshots in chunks of two (two batches) give the graphs of one batch, bit for bit, and
    the one-solve of the sparse path to round-off; their simulations analyse no sparse pattern."""
    import rheograph.graphs.dataset as dataset
    from rheograph.learn.predict import load_model
    from rheograph.sim.solver import CholmodSolver

    analysed = []
    original = CholmodSolver.analyze
    monkeypatch.setattr(CholmodSolver, "analyze", lambda self, *a: analysed.append(1) or original(self, *a))
    snaps = few_snapshots(3)
    model = load_model("N400_phi0.76")
    numerics = model.solve_numerics(snaps.phi, snaps.n_particles)
    whole = dataset.snapshot_graphs(snaps, model.settings, 0, numerics, training=False, solve_device=CPU)
    assert analysed == []
    monkeypatch.setattr(dataset, "SOLVED_TOGETHER", 2)
    chunked = dataset.snapshot_graphs(snaps, model.settings, 0, numerics, training=False, solve_device=CPU)
    sparse = dataset.snapshot_graphs(snaps, model.settings, 0, numerics, training=False)
    assert len(analysed) == 3  # the sparse path analyses each snapshot's pattern once
    for a, b, c in zip(chunked, whole, sparse):
        np.testing.assert_array_equal(a.physics.numpy(), b.physics.numpy())
        np.testing.assert_allclose(a.physics.numpy(), c.physics.numpy(), rtol=1e-9)


def test_a_deferred_analysis_solves_as_the_solver_it_defers():
    """A simulation with DeferredAnalysis takes the steps of one with its solver, bit for bit."""
    from rheograph.sim.solver import DeferredAnalysis, make_solver

    params = SimParams(n_particles=60, phi=0.80, stress=50.0, seed=60, disp_max=5e-3)
    deferred = Simulation(params, solver=DeferredAnalysis(make_solver("auto")))
    direct = Simulation(params)
    for _ in range(20):
        assert deferred.step().shear_rate == direct.step().shear_rate
    np.testing.assert_array_equal(deferred.state.positions, direct.state.positions)
