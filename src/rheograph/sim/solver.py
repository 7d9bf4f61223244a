"""Sparse symmetric positive-definite solver behind one small interface.

``analyze`` is called when the sparsity pattern changes (symbolic analysis: fill-reducing ordering,
elimination tree, supernodes); ``factorize`` with new values on the same pattern reuses it.  Matrices
are given as the *upper* triangle in CSC form (what ``rheograph.sim.assembly`` writes).

Backends (``SOLVERS``):

* ``cholmod`` — supernodal Cholesky (SuiteSparse CHOLMOD through scikit-sparse) with nested-dissection
  ordering.  Measured 1.5x faster than qdldl at N = 2000 (docs/validation/speed.md): the supernodes turn
  the dense frontal updates into BLAS calls and nested dissection fills less than AMD on these 2D,
  mesh-like matrices.  Needs Debian's ``libsuitesparse-dev`` (installed by ``make install``) and the
  ``cholmod`` extra.
* ``qdldl`` — LDLᵀ with AMD ordering from a pip wheel; works everywhere.
* ``amg`` — conjugate gradients preconditioned by aggregation algebraic multigrid (pyamg), each solve
  started from the previous step's solution.  Its cost per particle does not grow with N, where a 3D
  direct factor's does (nested-dissection separators of N^{2/3} particles): measured faster than
  ``cholmod`` from N = 2000 spheres and 3.5x faster at N = 8000 in steady flow (docs/validation/speed.md).  It
  solves to a relative residual ``AMG_RTOL``; a solve that does not get there within ``AMG_MAX_ITERATIONS``
  is redone by the direct solver on the same matrix (counted in ``fallbacks``).
* ``auto`` (default) — ``cholmod`` where it can be imported, else ``qdldl``; for 3D spheres from
  ``AMG_AUTO_PARTICLES`` on, ``amg``.

The direct solvers agree to round-off; ``amg`` to its tolerance (velocities to ~1e-5 of the largest).
"""

from __future__ import annotations

import logging
import warnings

import numpy as np
import scipy.sparse as sp

from rheograph.errors import InputError

log = logging.getLogger("rheograph")

# relative residual |A x - b| / |b| the multigrid-preconditioned CG solves to: velocities to ~1e-5 of
# the largest, a displacement error ~1e-8 a per step, far below a step's discretisation error (a run's
# means move by ~1e-2 between disp_max 2e-3 and 1e-3); 1e-8 costs a third more (measured in steady flow)
AMG_RTOL = 1e-6
# a steady dense suspension takes 20-25 iterations (phi 0.56, any N measured); far more means the
# hierarchy does not fit this matrix, and the direct solver is cheaper than going on
AMG_MAX_ITERATIONS = 300
# ``auto`` picks ``amg`` for 3D spheres from this N on (steady flow: cholmod 1.6x cheaper at N = 1000, amg
# 17 % cheaper at 2000; docs/validation/speed.md); below this, the direct solver's exactness is kept
AMG_AUTO_PARTICLES = 2000
# per-particle degrees of freedom -> dimension: (U_x, U_y, w_z) for discs, (U, w) for spheres
_DIMENSION_OF_DOF = {3: 2, 6: 3}


class SparseSPDSolver:
    name = "base"

    def analyze(self, indptr: np.ndarray, indices: np.ndarray, ndof: int) -> None:
        raise NotImplementedError

    def factorize(self, data: np.ndarray) -> None:
        raise NotImplementedError

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solution of A x = rhs for rhs (n,) or several right-hand sides at once (n, k)."""
        raise NotImplementedError


class QDLDLSolver(SparseSPDSolver):
    """LDLᵀ factorisation (qdldl) with AMD ordering; ``update`` keeps the symbolic analysis."""

    name = "qdldl"

    def __init__(self) -> None:
        import qdldl

        self._qdldl = qdldl
        self._factor = None
        self._matrix = None

    def analyze(self, indptr, indices, ndof):
        self._matrix = sp.csc_matrix((np.zeros(indices.shape[0]), indices, indptr), shape=(ndof, ndof))
        self._factor = None

    def factorize(self, data):
        self._matrix.data = data
        if self._factor is None:
            self._factor = self._qdldl.Solver(self._matrix, upper=True)
        else:
            self._factor.update(self._matrix, upper=True)

    def solve(self, rhs):
        if rhs.ndim == 1:
            return self._factor.solve(rhs)
        return np.stack([self._factor.solve(np.ascontiguousarray(col)) for col in rhs.T], axis=1)


class CholmodSolver(SparseSPDSolver):
    """Supernodal Cholesky (CHOLMOD) with nested-dissection ordering, symbolic factor reused.

    CHOLMOD (through scikit-sparse) reads the *lower* triangle of a CSC matrix; ``analyze`` precomputes
    the gather map that transposes the assembled upper triangle into it, so a factorisation costs one
    ``take`` of nnz values plus the numeric factorisation.  Handing over the lower triangle alone rather
    than the symmetrised full matrix halves what is copied and scanned: 7 % less per factorisation at
    N = 400 (2.10 vs 2.26 ms on a shared core, medians of 7 x 200; factors bitwise identical).
    """

    name = "cholmod"
    ordering = "nesdis"  # measured: 20 % less fill and time than AMD at N = 2000 (docs/validation/speed.md)

    def __init__(self) -> None:
        from sksparse import cholmod

        self._cholmod = cholmod
        self._factor = None
        self._lower = None
        self._gather = None

    def analyze(self, indptr, indices, ndof):
        nnz = indices.shape[0]
        # carry each upper entry's position through the transpose: lower.data[k] = upper.data[gather[k]]
        position = sp.csc_matrix(
            (np.arange(1, nnz + 1, dtype=np.float64), indices, indptr), shape=(ndof, ndof)
        )
        lower = position.T.tocsc()
        lower.sort_indices()
        self._gather = lower.data.astype(np.int64) - 1
        self._lower = lower
        self._factor = self._cholmod.analyze(lower, mode="supernodal", ordering_method=self.ordering)

    def factorize(self, data):
        np.take(data, self._gather, out=self._lower.data)
        self._factor.cholesky_inplace(self._lower)

    def solve(self, rhs):
        # several columns in one call: one pass over the factor (0.17 vs 0.23 ms for two
        # separate solves at N = 400, measured on a loaded core)
        return self._factor(rhs)


class DeferredAnalysis(SparseSPDSolver):
    """``solver`` whose symbolic analysis waits for the first factorisation on its pattern: for a
    simulation whose problems are mostly solved elsewhere (in dense batches on a GPU,
    ``rheograph.graphs.batched_solve``), which then pays for the analysis only where it falls back."""

    def __init__(self, solver: SparseSPDSolver) -> None:
        self.solver = solver
        self.name = solver.name
        self._pattern = None

    def analyze(self, indptr, indices, ndof):
        self._pattern = (indptr, indices, ndof)

    def factorize(self, data):
        if self._pattern is not None:
            self.solver.analyze(*self._pattern)
            self._pattern = None
        self.solver.factorize(data)

    def solve(self, rhs):
        return self.solver.solve(rhs)


class AMGSolver(SparseSPDSolver):
    """Conjugate gradients preconditioned by aggregation multigrid (pyamg), warm-started.

    The matrix is handed to pyamg in blocks of one particle's ``dof_per_particle`` unknowns, with the
    rigid translations as the near-null space: lubrication and contact springs resist only relative
    motion, so a cluster of near-touching particles translating together is what the one-body drag alone
    resists, the slow mode that plain CG converges on last.  (Rigid rotations would need the positions;
    measured, they save no iteration and make each dearer.)  The hierarchy is rebuilt at each
    ``factorize`` (a tenth of a step in steady flow; a smoothed-aggregation hierarchy kept for two or ten
    steps cost more iterations than it saved).  ``solve`` starts each right-hand side column from the
    solution of the same column in the previous call: the integrator's columns (springs, unit-rate flow)
    change little from step to step.

    ``dof_per_particle``: 3 (discs) or 6 (spheres); ``rtol``: relative residual; a solve that misses it in
    ``max_iterations`` is redone by the direct solver (``fallbacks`` counts them).
    """

    name = "amg"

    def __init__(
        self,
        dof_per_particle: int = 6,
        rtol: float = AMG_RTOL,
        max_iterations: int = AMG_MAX_ITERATIONS,
    ) -> None:
        import pyamg

        if dof_per_particle not in _DIMENSION_OF_DOF:
            raise InputError(
                f"solver='amg': dof_per_particle={dof_per_particle}, allowed 3 (discs) or 6 (spheres)"
            )
        self._pyamg = pyamg
        self.dof_per_particle = dof_per_particle
        self.rtol = rtol
        self.max_iterations = max_iterations
        self.iterations: list[int] = []  # CG iterations of the last solve, per right-hand side column
        self.fallbacks = 0
        self._matrix = None
        self._gather = None
        self._hierarchy = None
        self._previous = None
        self._pattern = None
        self._direct = None
        self._direct_is_current = False
        self._data = None

    def analyze(self, indptr, indices, ndof):
        nnz = indices.shape[0]
        block = self.dof_per_particle
        # where each entry of the full symmetric matrix, in pyamg's block layout, comes from in the
        # assembled upper triangle: positions 1..nnz carried through the symmetrisation; 0 marks the
        # structural zeros of partly filled blocks (gathered from an appended 0)
        upper = sp.csc_matrix((np.arange(1, nnz + 1, dtype=np.float64), indices, indptr), shape=(ndof, ndof))
        full = (upper + upper.T - sp.diags(upper.diagonal())).tocsr()
        full.sort_indices()
        blocks = full.tobsr(blocksize=(block, block))
        blocks.sort_indices()
        self._gather = blocks.data.ravel().astype(np.int64) - 1
        self._gather[self._gather < 0] = nnz
        self._blocks = (blocks.indices, blocks.indptr, blocks.data.shape, (ndof, ndof))
        translations = np.zeros((ndof, _DIMENSION_OF_DOF[block]))
        for axis in range(translations.shape[1]):
            translations[axis::block, axis] = 1.0
        self._translations = translations
        self._pattern = (indptr, indices, ndof)
        self._hierarchy = None
        self._direct = None
        if self._previous is not None and self._previous.shape[0] != ndof:
            self._previous = None

    def factorize(self, data):
        indices, indptr, shape, size = self._blocks
        values = np.append(data, 0.0)[self._gather].reshape(shape)
        # a new matrix each time: pyamg caches spectral radii on the matrix object, stale for new values;
        # blocks of listed pairs beyond the lubrication cut-off are all zero and must not count as
        # connections when aggregating (measured: 35 against 65 iterations with them)
        self._matrix = sp.bsr_matrix((values, indices.copy(), indptr.copy()), shape=size)
        self._matrix.eliminate_zeros()
        # two forward block Gauss-Seidel sweeps before the coarse correction and two backward after
        # it: a symmetric V-cycle, as CG needs; measured 43 against 48 iterations of symmetric sweeps
        # (forward then backward, each side) at the same cost per iteration
        presmoother = ("block_gauss_seidel", {"sweep": "forward", "iterations": 2})
        postsmoother = ("block_gauss_seidel", {"sweep": "backward", "iterations": 2})
        with warnings.catch_warnings():
            # pyamg warns when the near-null space has fewer vectors (the translations) than a block
            # has unknowns: chosen so, see the class docstring
            warnings.filterwarnings("ignore", "Having less target vectors", UserWarning)
            # plain aggregation: the piecewise-constant translations as interpolation, neither the
            # prolongator nor the candidates smoothed (measured in steady flow at N = 8000: a sixth of
            # the set-up for 48 against 41 iterations of the same cost); a coarsest level of at most
            # 100 unknowns, solved densely
            self._hierarchy = self._pyamg.smoothed_aggregation_solver(
                self._matrix,
                B=self._translations,
                symmetry="symmetric",
                strength=("symmetric", {"theta": 0.0}),
                smooth=None,
                improve_candidates=None,
                max_coarse=100,
                presmoother=presmoother,
                postsmoother=postsmoother,
            )
        self._direct_is_current = False
        self._data = data

    def preconditioner(self):
        """One V-cycle of the current hierarchy as a linear operator (ndof x ndof): what CG applies to
        each residual; symmetric positive definite, as CG requires."""
        return self._hierarchy.aspreconditioner(cycle="V")

    def levels(self) -> int:
        """Levels of the current hierarchy (1: the matrix is solved densely, no coarse correction)."""
        return len(self._hierarchy.levels)

    def solve(self, rhs):
        from scipy.sparse.linalg import cg

        columns = rhs[:, None] if rhs.ndim == 1 else rhs
        if self._previous is None or self._previous.shape != columns.shape:
            self._previous = np.zeros(columns.shape)
        preconditioner = self.preconditioner()
        solution = np.empty(columns.shape)
        self.iterations = []
        for k in range(columns.shape[1]):
            count = [0]

            def tally(_x, count=count):
                count[0] += 1

            x, info = cg(
                self._matrix, columns[:, k], x0=self._previous[:, k], rtol=self.rtol, atol=0.0,
                M=preconditioner, maxiter=self.max_iterations, callback=tally,
            )  # fmt: skip
            if info != 0 or not np.all(np.isfinite(x)):
                x = self._direct_solve(columns[:, k])
            solution[:, k] = x
            self.iterations.append(count[0])
        self._previous = solution.copy()
        return solution[:, 0] if rhs.ndim == 1 else solution

    def _direct_solve(self, b: np.ndarray) -> np.ndarray:
        """``b`` solved exactly on the current matrix: CG did not reach ``rtol`` (counted, logged once)."""
        self.fallbacks += 1
        if self.fallbacks == 1:
            log.warning(
                "solver=amg: a solve missed its tolerance %.0e in %d iterations and was redone by the "
                "direct solver (further ones are counted in the solver's fallbacks)",
                self.rtol,
                self.max_iterations,
            )
        if self._direct is None:
            self._direct = make_solver("cholmod" if cholmod_available() else "qdldl")
            self._direct.analyze(*self._pattern)
        if not self._direct_is_current:
            self._direct.factorize(self._data)
            self._direct_is_current = True
        return self._direct.solve(b)


SOLVERS = {"cholmod": CholmodSolver, "qdldl": QDLDLSolver, "amg": AMGSolver}
DIRECT_SOLVERS = ("cholmod", "qdldl")


def cholmod_available() -> bool:
    try:
        import sksparse.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


def resolve_solver_name(
    name: str, dof_per_particle: int | None = None, n_particles: int | None = None
) -> str:
    """The backend ``name`` stands for.  ``auto``: ``amg`` for spheres (6 unknowns a particle) from
    ``AMG_AUTO_PARTICLES`` on, else cholmod where installed, else qdldl."""
    if name == "auto":
        if dof_per_particle == 6 and n_particles is not None and n_particles >= AMG_AUTO_PARTICLES:
            return "amg"
        return "cholmod" if cholmod_available() else "qdldl"
    if name not in SOLVERS:
        raise InputError(f"solver={name!r} is unknown: allowed 'auto' or one of {sorted(SOLVERS)}")
    if name == "cholmod" and not cholmod_available():
        raise InputError(
            "solver='cholmod' needs scikit-sparse and SuiteSparse (`make install` sets both up; or "
            "`apt-get install libsuitesparse-dev && pip install -e '.[cholmod]'`); "
            "solver=qdldl works everywhere"
        )
    return name


def make_solver(
    name: str | SparseSPDSolver, dof_per_particle: int | None = None, n_particles: int | None = None
) -> SparseSPDSolver:
    """The backend ``name`` stands for (``resolve_solver_name``, for a system of ``n_particles`` with
    ``dof_per_particle`` unknowns each where known), or ``name`` itself when it is one."""
    if isinstance(name, SparseSPDSolver):
        return name
    resolved = resolve_solver_name(name, dof_per_particle, n_particles)
    if resolved == "amg":
        return AMGSolver(6 if dof_per_particle is None else dof_per_particle)
    return SOLVERS[resolved]()
