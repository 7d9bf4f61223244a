"""What do the Verlet skin's explicit zeros and the symbolic analysis cost the factorisation?  (Can the
symbolic analysis be reused across Verlet-list rebuilds?)

    OPENBLAS_NUM_THREADS=1 OMP_THREAD_LIMIT=1 python -m bench.factor_pattern [--n 400 2000]

The resistance matrix keeps one 3x3 block for every pair of the neighbour list (cut-off + skin), so that
its sparsity pattern and CHOLMOD's symbolic analysis (nested-dissection ordering, supernodes) live until
the list is rebuilt; pairs that do not interact this step hold explicit zeros.  Two questions, measured on
matrices captured from a run in the frictional steady state (φ = 0.76, σ/σ0 = 10, implicit at 2e-3, the
dataset's scheme):

* how much of a step the analyses cost: analysis time / steps between rebuilds — the most that reusing
  the analysis (its ordering) across rebuilds could save;
* how much the explicit zeros cost: the numeric factorisation of the same matrix on its list pattern
  against the pattern of its nonzero entries only, analysed for free — the most that any smaller
  pattern (smaller skin, per-step patterns) could save.

Both factorisations of one matrix alternate, medians over repetitions and captured matrices.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_THREAD_LIMIT", "1")

import numpy as np  # noqa: E402
from sksparse import cholmod  # noqa: E402

from bench.publishing import publish
from rheograph.sim.integrator import Simulation  # noqa: E402
from rheograph.sim.params import SimParams  # noqa: E402
from rheograph.sim.solver import CholmodSolver  # noqa: E402


class CapturingSolver(CholmodSolver):
    """The simulation's CHOLMOD solver; keeps the lower-triangle matrix of the latest factorisation and
    counts analyses."""

    def __init__(self):
        super().__init__()
        self.analyses = 0
        self.matrix = None

    def analyze(self, indptr, indices, ndof):
        super().analyze(indptr, indices, ndof)
        self.analyses += 1

    def factorize(self, data):
        super().factorize(data)
        self.matrix = self._lower


def call_ms(fn, *args, **kwargs) -> float:
    """Wall milliseconds of one call."""
    t0 = time.perf_counter()
    fn(*args, **kwargs)
    return 1e3 * (time.perf_counter() - t0)


def measure(n: int, warmup: float, window: int, samples: int, repeats: int) -> dict:
    params = SimParams(n_particles=n, phi=0.76, stress=10.0, integrator="implicit", disp_max=2e-3, seed=1)
    sim = Simulation(params, solver="cholmod")
    solver = CapturingSolver()
    sim.solver = solver
    sim._analyze()  # the new solver needs the current pattern's analysis
    while sim.state.strain < warmup:
        sim.step()
    analyses0, steps0 = solver.analyses, sim.state.steps
    rows = []
    every = max(1, window // samples)
    for k in range(window):
        sim.step()
        if k % every:
            continue
        verlet = solver.matrix.copy()
        nonzero = verlet.copy()
        nonzero.eliminate_zeros()
        on_list = cholmod.analyze(verlet, mode="supernodal", ordering_method=solver.ordering)
        on_nonzero = cholmod.analyze(nonzero, mode="supernodal", ordering_method=solver.ordering)
        on_list.cholesky_inplace(verlet)
        on_nonzero.cholesky_inplace(nonzero)
        t_list, t_nonzero = [], []
        for _ in range(repeats):  # alternate the two, one call each
            t_list.append(call_ms(on_list.cholesky_inplace, verlet))
            t_nonzero.append(call_ms(on_nonzero.cholesky_inplace, nonzero))
        t_analysis = np.median(
            [
                call_ms(cholmod.analyze, verlet, mode="supernodal", ordering_method=solver.ordering)
                for _ in range(5)
            ]
        )
        rows.append(
            (
                verlet.nnz,
                nonzero.nnz,
                on_list.L().nnz,
                on_nonzero.L().nnz,
                float(np.median(t_list)),
                float(np.median(t_nonzero)),
                t_analysis,
            )
        )
    steps = sim.state.steps - steps0
    rebuilds = solver.analyses - analyses0
    r = np.array(rows)
    return dict(
        n=n,
        pairs=sim.state.pair_i.shape[0],
        steps_per_rebuild=steps / max(rebuilds, 1),
        nnz_list=np.median(r[:, 0]),
        nnz_nonzero=np.median(r[:, 1]),
        fill_list=np.median(r[:, 2]),
        fill_nonzero=np.median(r[:, 3]),
        factor_list=np.median(r[:, 4]),
        factor_nonzero=np.median(r[:, 5]),
        analysis=np.median(r[:, 6]),
    )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[400, 2000])
    ap.add_argument("--warmup", type=float, default=0.15, help="strain before measuring")
    ap.add_argument("--window", type=int, default=600, help="steps measured")
    ap.add_argument("--samples", type=int, default=10, help="matrices captured in the window")
    ap.add_argument("--repeats", type=int, default=40, help="factorisations per matrix and pattern")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    lines = [
        "φ = 0.76, σ/σ0 = 10, implicit, disp_max 2e-3, neighbour skin 0.4 (the defaults), after strain "
        f"{args.warmup}; {args.samples} matrices captured over {args.window} steps, each factorised "
        f"{args.repeats}× on either pattern (alternating); medians; one thread.  Analyses per step = "
        "analysis time / steps between rebuilds.",
        "",
        "| N | listed pairs | steps per list rebuild | nnz (lower): list / nonzero | nnz(L): list / nonzero "
        "| factorisation ms: list / nonzero only | analysis ms | analyses per step, share of a factorisation "
        "| explicit zeros, share of a factorisation |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n in args.n:
        m = measure(n, args.warmup, args.window, args.samples, args.repeats)
        # both relative to the factorisation on the list pattern, timed the same way (wall, one call)
        analysis_share = m["analysis"] / m["steps_per_rebuild"] / m["factor_list"]
        zeros_share = 1.0 - m["factor_nonzero"] / m["factor_list"]
        lines.append(
            f"| {n} | {m['pairs']} | {m['steps_per_rebuild']:.0f} | {m['nnz_list']:.0f} / "
            f"{m['nnz_nonzero']:.0f} | {m['fill_list']:.0f} / {m['fill_nonzero']:.0f} | "
            f"{m['factor_list']:.3f} / {m['factor_nonzero']:.3f} | {m['analysis']:.2f} | "
            f"{100 * analysis_share:.1f} % | {100 * zeros_share:.1f} % |"
        )
        print(lines[-1], flush=True)
    lines += ["", "Command: `python -m bench.factor_pattern --n " + " ".join(map(str, args.n)) + "`"]
    publish("factor_pattern", "\n".join(lines), not args.no_write)


if __name__ == "__main__":
    main()
