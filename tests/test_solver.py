"""Sparse Cholesky backends: same solution as a dense solve, symbolic reuse, clear errors."""

import numpy as np
import pytest

from rheograph.sim import SimParams, Simulation
from rheograph.sim.assembly import dense_from_upper_csc
from rheograph.sim.solver import (
    AMG_AUTO_PARTICLES,
    AMG_RTOL,
    DIRECT_SOLVERS,
    AMGSolver,
    cholmod_available,
    make_solver,
    resolve_solver_name,
)

needs_cholmod = pytest.mark.skipif(not cholmod_available(), reason="scikit-sparse missing")
BACKENDS = ["qdldl", pytest.param("cholmod", marks=needs_cholmod)]


def captured_matrices(n_steps=200, every=50, sim=None):
    """Resistance matrices (upper CSC data) of a flowing dense suspension (``sim``: by default 80 discs),
    on one Verlet pattern; and the number of unknowns."""
    if sim is None:
        sim = Simulation(SimParams(n_particles=80, phi=0.76, stress=10.0, strain=1.0), solver="qdldl")
    taken = []
    original = sim.solver.factorize

    def spy(data):
        taken.append((data.copy(), sim.indptr.copy(), sim.indices.copy()))
        return original(data)

    sim.solver.factorize = spy
    for _ in range(n_steps):
        sim.step()
    return taken[::every], sim.DOF * sim.state.radii.shape[0]


@pytest.mark.parametrize("name", BACKENDS)
def test_backend_matches_dense_solve_and_reuses_the_analysis(name):
    matrices, ndof = captured_matrices()
    assert len(matrices) == 4
    solver = make_solver(name)
    assert solver.name == name
    rhs = np.random.default_rng(3).normal(size=(2, ndof))
    pattern = None
    for data, indptr, indices in matrices:
        same = (
            pattern is not None and np.array_equal(indptr, pattern[0]) and np.array_equal(indices, pattern[1])
        )
        if not same:
            solver.analyze(indptr, indices, ndof)
            pattern = (indptr, indices)
        solver.factorize(data)
        dense = dense_from_upper_csc(data, indices, indptr, ndof)
        for b in rhs:
            x = solver.solve(b)
            # the matrix spans ~1/delta = 1e3 in scale: compare residuals relative to |A| |x|
            scale = np.abs(dense).max() * np.abs(x).max()
            assert np.abs(dense @ x - b).max() < 1e-10 * scale
            np.testing.assert_allclose(x, np.linalg.solve(dense, b), rtol=1e-7, atol=1e-9 * np.abs(x).max())
        # several right-hand sides in one call (the integrator's two columns): the same solutions
        both = solver.solve(np.asfortranarray(rhs.T))
        assert both.shape == (ndof, 2)
        for k, b in enumerate(rhs):
            np.testing.assert_allclose(
                both[:, k], solver.solve(b), rtol=1e-12, atol=1e-14 * np.abs(both).max()
            )


@needs_cholmod
def test_backends_give_the_same_trajectory_to_round_off():
    runs = {}
    start = Simulation(SimParams(n_particles=80, phi=0.76, stress=10.0, strain=1.0, seed=4)).state.positions
    for name in DIRECT_SOLVERS:
        sim = Simulation(SimParams(n_particles=80, phi=0.76, stress=10.0, strain=1.0, seed=4), solver=name)
        for _ in range(150):
            sim.step()
        runs[name] = sim.state.positions.copy()
    # 150 steps of a chaotic dynamics amplify round-off only mildly at this length
    assert np.abs(runs["qdldl"] - start).max() > 1e-2  # the particles did move
    np.testing.assert_allclose(runs["cholmod"], runs["qdldl"], atol=1e-8)


def test_unknown_solver_is_refused_with_the_allowed_names():
    with pytest.raises(ValueError, match="solver='umfpack' is unknown: allowed 'auto' or one of"):
        resolve_solver_name("umfpack")
    assert resolve_solver_name("auto") == ("cholmod" if cholmod_available() else "qdldl")


def test_multigrid_solves_to_its_tolerance_and_starts_from_the_last_solution():
    matrices, ndof = captured_matrices()
    solver = AMGSolver(dof_per_particle=3)
    rhs = np.random.default_rng(5).normal(size=(ndof, 2))
    pattern = None
    for data, indptr, indices in matrices:
        if pattern is None or not (
            np.array_equal(indptr, pattern[0]) and np.array_equal(indices, pattern[1])
        ):
            solver.analyze(indptr, indices, ndof)
            pattern = (indptr, indices)
        solver.factorize(data)
        dense = dense_from_upper_csc(data, indices, indptr, ndof)
        x = solver.solve(rhs)
        for k in range(2):
            assert np.linalg.norm(dense @ x[:, k] - rhs[:, k]) <= AMG_RTOL * np.linalg.norm(rhs[:, k])
            exact = np.linalg.solve(dense, rhs[:, k])
            assert np.abs(x[:, k] - exact).max() < 1e-4 * np.abs(exact).max()
        assert 0 < max(solver.iterations) < 100
        # the same problem again: the previous solution already solves it
        solver.solve(rhs)
        assert solver.iterations == [0, 0]
    assert solver.fallbacks == 0


def test_the_multigrid_preconditioner_is_symmetric_positive_definite():
    """CG converges as analysed only with a symmetric positive-definite preconditioner: the V-cycle's
    smoothing after the coarse correction must be the adjoint of the smoothing before it (forward sweeps
    before, backward after).  Its matrix, column by column, on a captured resistance matrix of discs
    and on one of spheres."""
    from rheograph.sim.integrator3d import Simulation3D
    from rheograph.sim.params3d import SimParams3D

    # systems large enough for a hierarchy of two levels (a single level is a dense solve: symmetric
    # whatever the smoother)
    discs = Simulation(SimParams(n_particles=400, phi=0.76, stress=10.0, strain=1.0), solver="qdldl")
    spheres = Simulation3D(SimParams3D(n_particles=150, phi=0.5, stress=10.0, seed=2), solver="qdldl")
    for sim in (discs, spheres):
        matrices, ndof = captured_matrices(n_steps=10, every=9, sim=sim)
        data, indptr, indices = matrices[-1]
        dof = sim.DOF
        solver = AMGSolver(dof_per_particle=dof)
        solver.analyze(indptr, indices, ndof)
        solver.factorize(data)
        assert solver.levels() >= 2
        apply = solver.preconditioner()
        m = np.column_stack([apply.matvec(e) for e in np.eye(ndof)])
        assert np.abs(m - m.T).max() <= 1e-10 * np.abs(m).max(), dof
        assert np.linalg.eigvalsh(0.5 * (m + m.T)).min() > 0.0, dof


def test_multigrid_that_misses_its_tolerance_falls_back_to_the_direct_solve(caplog):
    (data, indptr, indices), ndof = captured_matrices(n_steps=50)[0][-1], 240
    solver = AMGSolver(dof_per_particle=3, max_iterations=1)
    solver.analyze(indptr, indices, ndof)
    solver.factorize(data)
    b = np.random.default_rng(6).normal(size=ndof)
    with caplog.at_level("WARNING", logger="rheograph"):
        x = solver.solve(b)
    dense = dense_from_upper_csc(data, indices, indptr, ndof)
    np.testing.assert_allclose(x, np.linalg.solve(dense, b), rtol=1e-7, atol=1e-9 * np.abs(x).max())
    assert solver.fallbacks == 1
    assert "redone by the direct solver" in caplog.text


def test_multigrid_steps_spheres_like_the_direct_solver():
    from rheograph.sim.integrator3d import Simulation3D
    from rheograph.sim.params3d import SimParams3D

    params = SimParams3D(n_particles=120, phi=0.55, stress=10.0, seed=2)
    direct, multigrid = Simulation3D(params, solver="qdldl"), Simulation3D(params, solver="amg")
    assert multigrid.solver.name == "amg" and multigrid.solver.dof_per_particle == 6
    for _ in range(30):
        problems = [sim.prepare_step() for sim in (direct, multigrid)]
        velocities = [sim.solve_linear(lp) for sim, lp in zip((direct, multigrid), problems)]
        scale = np.abs(velocities[0]).max(axis=0)
        assert np.all(np.abs(velocities[1] - velocities[0]).max(axis=0) <= 1e-4 * scale)
        for sim, lp, v in zip((direct, multigrid), problems, velocities):
            sim.complete_step(lp, v, False)
    assert 0 < max(multigrid.solver.iterations) < 100 and multigrid.solver.fallbacks == 0
    np.testing.assert_allclose(multigrid.state.positions, direct.state.positions, atol=1e-6)


def test_auto_takes_multigrid_for_large_sphere_systems_only():
    direct = "cholmod" if cholmod_available() else "qdldl"
    assert resolve_solver_name("auto", 6, AMG_AUTO_PARTICLES) == "amg"
    assert resolve_solver_name("auto", 6, AMG_AUTO_PARTICLES - 1) == direct
    assert resolve_solver_name("auto", 3, 100 * AMG_AUTO_PARTICLES) == direct  # discs: the direct factor
    assert resolve_solver_name("amg") == "amg"
    assert make_solver("auto", 6, AMG_AUTO_PARTICLES).name == "amg"
