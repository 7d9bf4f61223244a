"""Which multigrid hierarchy pays: set-up time, solve time and CG iterations of ``solver=amg``'s
preconditioner under other pyamg settings, on one captured steady resistance matrix of spheres.

    python bench/amg_settings.py --n 8000

The matrix and the integrator's two right-hand sides are taken at the fourth step from the last
checkpoint of a steady N = 500 run (φ 0.56, σ/σ0 200) replicated into N (``bench.short_run_3d``); each
setting builds its hierarchy three times and solves both columns to a relative residual of 1e-6 from
the previous step's solutions (medians of CPU time).  Prints a table; publishes nothing.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

START = ROOT / "data/flow_curves_3d/multirun/N500_phi0.56_s200_seed1_d0.002_implicit_3d/trajectory.h5"


def captured_problem(n: int):
    """(matrix, right-hand sides, previous solutions, translations) of the solver at the 4th step."""
    from bench.short_run_3d import replicated_start
    from rheograph.sim import solver as solvers
    from rheograph.sim.integrator3d import Simulation3D

    params, state = replicated_start(START, n)
    sim = Simulation3D(params, state=state, solver="amg")
    taken = {}
    original = solvers.AMGSolver.solve

    def spy(self, rhs):
        previous = np.zeros(rhs.shape) if self._previous is None else self._previous.copy()
        taken.update(A=self._matrix, rhs=rhs.copy(), x0=previous, B=self._translations)
        return original(self, rhs)

    solvers.AMGSolver.solve = spy
    try:
        for _ in range(4):
            sim.step()
    finally:
        solvers.AMGSolver.solve = original
    return taken["A"], taken["rhs"], taken["x0"], taken["B"]


def settings() -> dict:
    forward = ("block_gauss_seidel", {"sweep": "forward", "iterations": 2})
    backward = ("block_gauss_seidel", {"sweep": "backward", "iterations": 2})
    symmetric = ("block_gauss_seidel", {"sweep": "symmetric"})
    plain = dict(smooth=None, improve_candidates=None, max_coarse=100)
    return {
        "smoothed aggregation, symmetric sweeps (max_coarse 300)": dict(
            smooth="jacobi", max_coarse=300, presmoother=symmetric, postsmoother=symmetric
        ),
        "plain aggregation, symmetric sweeps": dict(plain, presmoother=symmetric, postsmoother=symmetric),
        "plain aggregation, 2 forward / 2 backward (rheograph)": dict(
            plain, presmoother=forward, postsmoother=backward
        ),
        "plain aggregation, 3 forward / 3 backward": dict(
            plain,
            presmoother=("block_gauss_seidel", {"sweep": "forward", "iterations": 3}),
            postsmoother=("block_gauss_seidel", {"sweep": "backward", "iterations": 3}),
        ),
        "plain aggregation, Chebyshev degree 3": dict(
            plain, presmoother=("chebyshev", {"degree": 3}), postsmoother=("chebyshev", {"degree": 3})
        ),
    }


def measure(a, rhs, x0, translations, options: dict, repeats: int = 3) -> dict:
    import pyamg
    import scipy.sparse as sp
    from scipy.sparse.linalg import cg

    setups, solves, iterations = [], [], []
    for _ in range(repeats):
        t0 = time.process_time()
        matrix = sp.bsr_matrix(a)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            hierarchy = pyamg.smoothed_aggregation_solver(
                matrix, B=translations, symmetry="symmetric", strength=("symmetric", {"theta": 0.0}),
                **options,
            )  # fmt: skip
        t1 = time.process_time()
        preconditioner = hierarchy.aspreconditioner(cycle="V")
        count = [0]

        def tally(_x, count=count):
            count[0] += 1

        for k in range(rhs.shape[1]):
            cg(matrix, rhs[:, k], x0=x0[:, k], rtol=1e-6, atol=0.0, M=preconditioner, maxiter=300,
               callback=tally)  # fmt: skip
        setups.append(t1 - t0)
        solves.append(time.process_time() - t1)
        iterations.append(count[0])
    return {
        "setup_ms": 1e3 * float(np.median(setups)),
        "solve_ms": 1e3 * float(np.median(solves)),
        "iterations": int(np.median(iterations)),
        "levels": len(hierarchy.levels),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=8000, help="spheres (the N = 500 start replicated)")
    args = ap.parse_args(argv)
    a, rhs, x0, translations = captured_problem(args.n)
    print(f"N = {args.n}: {a.shape[0]} unknowns, {rhs.shape[1]} right-hand sides")
    print("| setting | set-up ms | solve ms | CG iterations (both columns) | levels |")
    print("|---|---|---|---|---|")
    for name, options in settings().items():
        row = measure(a, rhs, x0, translations, options)
        cells = (name, f"{row['setup_ms']:.0f}", f"{row['solve_ms']:.0f}", row["iterations"], row["levels"])
        print("| " + " | ".join(str(c) for c in cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
