"""Sparse Cholesky backends: same solution as a dense solve, symbolic reuse, clear errors."""

import numpy as np
import pytest

from rheograph.sim import SimParams, Simulation
from rheograph.sim.assembly import dense_from_upper_csc
from rheograph.sim.solver import SOLVERS, cholmod_available, make_solver, resolve_solver_name

needs_cholmod = pytest.mark.skipif(not cholmod_available(), reason="scikit-sparse missing")
BACKENDS = ["qdldl", pytest.param("cholmod", marks=needs_cholmod)]


def captured_matrices(n_steps=200, every=50):
    """Resistance matrices (upper CSC data) of a flowing dense suspension, on one Verlet pattern."""
    sim = Simulation(SimParams(n_particles=80, phi=0.76, stress=10.0, strain=1.0), solver="qdldl")
    taken = []
    original = sim.solver.factorize

    def spy(data):
        taken.append((data.copy(), sim.indptr.copy(), sim.indices.copy()))
        return original(data)

    sim.solver.factorize = spy
    for _ in range(n_steps):
        sim.step()
    return taken[::every], 3 * sim.state.radii.shape[0]


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
    for name in SOLVERS:
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
