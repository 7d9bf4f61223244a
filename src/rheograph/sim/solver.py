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
* ``auto`` (default) — ``cholmod`` where it can be imported, else ``qdldl``.

Both are exact direct solvers: trajectories differ only by round-off.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from rheograph.errors import InputError


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


SOLVERS = {"cholmod": CholmodSolver, "qdldl": QDLDLSolver}


def cholmod_available() -> bool:
    try:
        import sksparse.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


def resolve_solver_name(name: str) -> str:
    """The backend ``name`` stands for (``auto``: cholmod where installed, else qdldl)."""
    if name == "auto":
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


def make_solver(name: str | SparseSPDSolver) -> SparseSPDSolver:
    """The backend ``name`` stands for (``resolve_solver_name``), or ``name`` itself when it is one."""
    if isinstance(name, SparseSPDSolver):
        return name
    return SOLVERS[resolve_solver_name(name)]()
