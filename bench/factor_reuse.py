"""Can a recent Cholesky factor replace a fresh one?  Conjugate gradients on each step's resistance matrix,
preconditioned with the factor of an earlier step, against the direct solve .

    OPENBLAS_NUM_THREADS=1 OMP_THREAD_LIMIT=1 python -m bench.factor_reuse [--n 400 2000] [--lags 1 2 5 10]

The simulation itself runs with the exact per-step factorisation (its trajectory is unaffected); at every
step, for each refactorisation interval L, a shadow CHOLMOD factor refreshed every L steps preconditions
CG on the step's two right-hand sides (unit-rate and rate-independent forces), to the relative residual
``--rtol``.  Reported: CG iterations per solve (mean, 95th percentile, failures to converge within
``--maxiter``), the measured seconds of the CG solves, and the cost per step of the policy "refactorise every
L steps, CG in between" (factorisation / L + CG) against the direct step (factorisation + 2 solves), all
measured in this run.  φ = 0.76, σ/σ0 = 10, implicit scheme at disp_max 2e-3 (the dataset's), after a
warm-up strain into the frictional steady state.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_THREAD_LIMIT", "1")

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from scipy.sparse.linalg import LinearOperator, cg  # noqa: E402

from bench.publishing import publish
from rheograph.sim.integrator import Simulation  # noqa: E402
from rheograph.sim.params import SimParams  # noqa: E402
from rheograph.sim.solver import CholmodSolver  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


class ShadowedSolver(CholmodSolver):
    """The exact CHOLMOD solver the simulation uses, plus shadow factors refreshed every L steps that
    precondition CG on the same systems; records iterations and seconds."""

    def __init__(self, lags, rtol, maxiter):
        super().__init__()
        self.lags, self.rtol, self.maxiter = lags, rtol, maxiter
        self.shadows = {lag: CholmodSolver() for lag in lags}
        self.age = {lag: None for lag in lags}  # steps since the shadow was factorised (None: never)
        self.recording = False
        self.stats = {lag: {"iterations": [], "cg_seconds": 0.0, "failures": 0} for lag in lags}
        self.factor_seconds, self.solve_seconds, self.steps = 0.0, 0.0, 0

    def analyze(self, indptr, indices, ndof):
        super().analyze(indptr, indices, ndof)
        self.pattern = (indptr, indices, ndof)
        for lag in self.lags:  # a new pattern (neighbour-list rebuild) needs a new analysis: refresh all
            self.shadows[lag].analyze(indptr, indices, ndof)
            self.age[lag] = None

    def factorize(self, data):
        t0 = time.perf_counter()
        super().factorize(data)
        if self.recording:
            self.factor_seconds += time.perf_counter() - t0
            self.steps += 1
        indptr, indices, ndof = self.pattern
        upper = sp.csc_matrix((data, indices, indptr), shape=(ndof, ndof))
        self.matrix = (upper + sp.triu(upper, k=1).T).tocsr()
        for lag in self.lags:
            if self.age[lag] is None or self.age[lag] + 1 >= lag:
                self.shadows[lag].factorize(data)
                self.age[lag] = 0
            else:
                self.age[lag] += 1

    def solve(self, rhs):
        t0 = time.perf_counter()
        exact = super().solve(rhs)
        if not self.recording:
            return exact
        self.solve_seconds += time.perf_counter() - t0
        for lag in self.lags:
            if self.age[lag] == 0:  # fresh factor: a direct solve, counted as such
                continue
            shadow = self.shadows[lag]
            preconditioner = LinearOperator(self.matrix.shape, matvec=shadow.solve, dtype=np.float64)
            count = [0]

            def tick(_x, count=count):
                count[0] += 1

            t1 = time.perf_counter()
            x, info = cg(
                self.matrix,
                rhs,
                rtol=self.rtol,
                atol=0.0,
                maxiter=self.maxiter,
                M=preconditioner,
                callback=tick,
            )
            self.stats[lag]["cg_seconds"] += time.perf_counter() - t1
            self.stats[lag]["iterations"].append(count[0])
            if info != 0:
                self.stats[lag]["failures"] += 1
        return exact


def measure(n, args) -> list[dict]:
    params = SimParams(n_particles=n, phi=0.76, stress=10.0, disp_max=2e-3, integrator="implicit")
    sim = Simulation(params, solver="cholmod")
    solver = ShadowedSolver(args.lags, args.rtol, args.maxiter)
    sim.solver = solver
    sim._analyze()
    while sim.state.strain < args.warmup:
        sim.step()
    solver.recording = True
    strain0 = sim.state.strain
    for _ in range(args.steps):
        sim.step()
    factor = solver.factor_seconds / solver.steps
    direct = factor + solver.solve_seconds / solver.steps
    rows = []
    for lag in args.lags:
        st = solver.stats[lag]
        its = np.array(st["iterations"]) if st["iterations"] else np.zeros(1)
        # every L-th step factorises and solves directly; the others run CG with the stale factor
        policy = (direct / lag) + st["cg_seconds"] / solver.steps
        rows.append(
            dict(
                n=n,
                lag=lag,
                steps=solver.steps,
                strain=sim.state.strain - strain0,
                mean_iterations=float(its.mean()),
                p95_iterations=float(np.percentile(its, 95)),
                failures=st["failures"],
                factor_ms=1e3 * factor,
                direct_ms=1e3 * direct,
                policy_ms=1e3 * policy,
            )
        )
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[400, 2000])
    ap.add_argument("--lags", type=int, nargs="+", default=[2, 5, 10, 20])
    ap.add_argument("--rtol", type=float, default=1e-10)
    ap.add_argument("--maxiter", type=int, default=200)
    ap.add_argument("--warmup", type=float, default=0.2)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    rows = [row for n in args.n for row in measure(n, args)]
    lines = [
        f"φ = 0.76, σ/σ0 = 10, implicit, disp_max 2e-3, {args.steps} steps after strain {args.warmup}; CG to "
        f"relative residual {args.rtol:g} (at most {args.maxiter} iterations) preconditioned with a CHOLMOD "
        "factor refreshed every L steps; one thread.  Cost per step of the matrix work only (factorisation "
        "+ the two solves), measured in this run.",
        "",
        "| N | L | CG iterations per solve (mean / 95th pct) | not converged | factorisation ms "
        "| direct: factorise + 2 solves, ms/step | every L steps + CG, ms/step | ratio |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['n']} | {r['lag']} | {r['mean_iterations']:.1f} / {r['p95_iterations']:.0f} | "
            f"{r['failures']} | "
            f"{r['factor_ms']:.2f} | {r['direct_ms']:.2f} | {r['policy_ms']:.2f} | "
            f"{r['direct_ms'] / r['policy_ms']:.2f}× |"
        )
    lines += [
        "",
        "Command: `python -m bench.factor_reuse " + " ".join(sys.argv[1:]).replace(" --no-write", "") + "`",
    ]
    publish("factor_reuse", "\n".join(lines), write=not args.no_write)


if __name__ == "__main__":
    main()
