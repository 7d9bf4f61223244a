"""Sparse symmetric positive-definite solver behind one small interface.

``analyze`` is called when the sparsity pattern changes (symbolic analysis: ordering, elimination tree);
``factorize`` with new values on the same pattern reuses it.  Matrices are given as the *upper* triangle
in CSC form.  Backend: qdldl (pip wheel, works everywhere); another backend (e.g. CHOLMOD through
scikit-sparse) plugs in by subclassing ``SparseSPDSolver`` and registering in ``SOLVERS``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


class SparseSPDSolver:
    name = "base"

    def analyze(self, indptr: np.ndarray, indices: np.ndarray, ndof: int) -> None:
        raise NotImplementedError

    def factorize(self, data: np.ndarray) -> None:
        raise NotImplementedError

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        raise NotImplementedError


class QDLDLSolver(SparseSPDSolver):
    """LDL^T factorisation (qdldl) with AMD ordering; ``update`` keeps the symbolic analysis."""

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
        return self._factor.solve(rhs)


SOLVERS = {"qdldl": QDLDLSolver}


def make_solver(name: str) -> SparseSPDSolver:
    if name not in SOLVERS:
        raise ValueError(f"sim solver={name!r} is unknown: allowed {sorted(SOLVERS)}")
    return SOLVERS[name]()
