"""What CHOLMOD is handed: the symmetrised full matrix or its lower triangle alone (what CHOLMOD reads,
the default).  Times the numeric factorisation of one resistance matrix captured from a
flowing run, the two hand-overs alternating, and checks that their solutions agree bit for bit.

    OPENBLAS_NUM_THREADS=1 OMP_THREAD_LIMIT=1 python -m bench.cholmod_handover [--n 400 2000]

φ = 0.76, σ/σ0 = 10, implicit scheme at disp_max 2e-3 (the dataset's), matrix taken after --warmup steps.
Prints a markdown table (medians over --repeats alternating batches of --batch factorisations).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_THREAD_LIMIT", "1")

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402

from rheograph.sim.integrator import Simulation  # noqa: E402
from rheograph.sim.params import SimParams  # noqa: E402
from rheograph.sim.solver import CholmodSolver  # noqa: E402


class FullMatrixHandover(CholmodSolver):
    """The earlier hand-over: the upper triangle symmetrised into the full matrix by a gather map."""

    def analyze(self, indptr, indices, ndof):
        nnz = indices.shape[0]
        position = sp.csc_matrix(
            (np.arange(1, nnz + 1, dtype=np.float64), indices, indptr), shape=(ndof, ndof)
        )
        full = (position + sp.triu(position, k=1).T).tocsc()
        full.sort_indices()
        self._gather = full.data.astype(np.int64) - 1
        self._lower = full  # the attribute factorize() fills and hands over
        self._factor = self._cholmod.analyze(full, mode="supernodal", ordering_method=self.ordering)


def captured_matrix(n: int, warmup: int):
    """(data, indptr, indices, ndof) of the resistance matrix of the last of ``warmup`` steps."""
    sim = Simulation(SimParams(n_particles=n, phi=0.76, stress=10.0, integrator="implicit", disp_max=2e-3))
    taken = {}
    original = sim.solver.factorize

    def spy(data):
        taken["data"] = data.copy()
        return original(data)

    sim.solver.factorize = spy
    for _ in range(warmup):
        sim.step()
    return taken["data"], sim.indptr, sim.indices, 3 * n


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[400, 2000])
    ap.add_argument("--warmup", type=int, default=1500, help="steps before the matrix is captured")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--batch", type=int, default=200, help="factorisations per timed batch")
    args = ap.parse_args(argv)
    print("| N | nnz (upper) | full matrix, ms | lower triangle, ms | ratio | max |Δx| / |x| |")
    print("|---|---|---|---|---|---|")
    for n in args.n:
        data, indptr, indices, ndof = captured_matrix(n, args.warmup)
        solvers = {"full": FullMatrixHandover(), "lower": CholmodSolver()}
        for s in solvers.values():
            s.analyze(indptr, indices, ndof)
            s.factorize(data)
        rhs = np.random.default_rng(0).normal(size=(ndof, 2))
        x_full, x_lower = solvers["full"].solve(rhs), solvers["lower"].solve(rhs)
        diff = np.abs(x_full - x_lower).max() / np.abs(x_full).max()
        ms = {k: [] for k in solvers}
        for _ in range(args.repeats):
            for name, solver in solvers.items():
                t0 = time.perf_counter()
                for _ in range(args.batch):
                    solver.factorize(data)
                ms[name].append((time.perf_counter() - t0) / args.batch * 1e3)
        full, lower = np.median(ms["full"]), np.median(ms["lower"])
        print(f"| {n} | {indices.shape[0]} | {full:.3f} | {lower:.3f} | {full / lower:.2f}× | {diff:.1e} |")


if __name__ == "__main__":
    main()
