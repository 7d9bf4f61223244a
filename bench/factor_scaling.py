"""Why a step costs more per particle in a larger box: the sparse Cholesky factor of the resistance
matrix, per N, on the matrix of a flowing configuration.

    python -m bench.factor_scaling --n 400 2000 8000 20000 --page jamming.md

Per N: a φ = 0.76, σ/σ0 = 200 run (implicit, disp_max 2e-3) is stepped past its start-up (``--warmup``
steps), then its current matrix is analysed (CHOLMOD, nested dissection, supernodal: the simulator's
solver) and factorised ``--repeats`` times.  Reported: the factor's nonzeros per particle, its
floating-point work per particle (Σ_j c_j², c_j the nonzeros of column j of L: the multiply-adds of a
column Cholesky), the CPU time of one numeric factorisation per particle (median of ``--windows``
windows) and the rate that makes (GFlop/s), and the time of one symbolic analysis.

Nested dissection of a two-dimensional contact network makes nnz(L) grow like N log N and the work
like N^{3/2} (separators of √N particles, eliminated as dense blocks); how much of that shows in the time
depends on how well the dense kernels run on larger blocks.  Run it alone on the machine.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_THREAD_LIMIT", "1")  # CHOLMOD's OpenMP (see simulate.py)

import numpy as np  # noqa: E402

from bench.publishing import command_line, publish, table
from rheograph.sim import SimParams, Simulation  # noqa: E402
from rheograph.sim.params import scheme_settings  # noqa: E402

# the flowing state point whose matrix is factorised: dense and frictional, per dimension
STATE = {2: dict(phi=0.76, stress=200.0), 3: dict(phi=0.56, stress=200.0)}


def measure(n: int, warmup: int, repeats: int, windows: int, orderings, dim: int = 2) -> list[dict]:
    """One row per fill-reducing ordering, all on the same matrix (2D discs, or 3D spheres: 6 degrees
    of freedom a particle instead of 3)."""
    from sksparse import cholmod

    if dim == 3:
        from rheograph.sim.integrator3d import Simulation3D
        from rheograph.sim.params3d import SimParams3D

        params = SimParams3D(n_particles=n, **STATE[3], disp_max=2e-3, **scheme_settings("implicit"))
        sim = Simulation3D(params, solver="cholmod")
    else:
        params = SimParams(n_particles=n, **STATE[2], disp_max=2e-3, **scheme_settings("implicit"))
        sim = Simulation(params, solver="cholmod")
    for _ in range(warmup):
        sim.step()
    lower = sim.solver._lower.copy()  # the lower triangle CHOLMOD factorises, this step's values
    rows = []
    for ordering in orderings:
        t0 = time.process_time()
        factor = cholmod.analyze(lower, mode="supernodal", ordering_method=ordering)
        analysis = time.process_time() - t0
        factor.cholesky_inplace(lower)
        per_window = []
        for _ in range(windows):
            t0 = time.process_time()
            for _ in range(repeats):
                factor.cholesky_inplace(lower)
            per_window.append((time.process_time() - t0) / repeats)
        seconds = float(np.median(per_window))
        column_counts = np.diff(factor.L().tocsc().indptr).astype(np.float64)
        flops = float(np.sum(column_counts**2))
        rows.append(
            dict(
                n=n,
                ordering=ordering,
                nnz_per_particle=column_counts.sum() / n,
                flops_per_particle=flops / n,
                us_per_particle=1e6 * seconds / n,
                gflops=flops / seconds / 1e9,
                analysis_ms=1e3 * analysis,
            )
        )
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[400, 2000, 8000, 20000])
    ap.add_argument("--dim", type=int, choices=(2, 3), default=2, help="discs (2) or spheres (3)")
    ap.add_argument("--warmup", type=int, default=40, help="steps before the matrix is taken")
    ap.add_argument("--windows", type=int, default=5)
    ap.add_argument(
        "--particle-factorisations",
        type=float,
        default=2e5,
        help="repeats per window: this many particle-factorisations (at least 3)",
    )
    ap.add_argument(
        "--orderings",
        nargs="+",
        default=["nesdis"],
        help="CHOLMOD orderings to compare (the simulator uses nesdis), e.g. nesdis metis amd",
    )
    ap.add_argument("--page", default=None, help="docs page with the marked section (default: its record's)")
    ap.add_argument("--section", default="factor_scaling")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    if any(n < 16 for n in args.n) or args.warmup < 0 or args.windows < 1:
        sys.exit("factor_scaling: --n must be >= 16, --warmup >= 0 and --windows >= 1")
    known = ("natural", "amd", "metis", "nesdis", "colamd", "default", "best")
    if set(args.orderings) - set(known):
        sys.exit(f"factor_scaling: --orderings {args.orderings}: allowed CHOLMOD orderings {list(known)}")
    args.n = sorted(set(args.n))
    rows = []
    for n in args.n:
        repeats = max(3, int(args.particle_factorisations / n))
        rows += measure(n, args.warmup, repeats, args.windows, args.orderings, args.dim)
        print(rows[-len(args.orderings) :], flush=True)
    first = {r["ordering"]: r for r in reversed(rows)}  # each ordering's smallest-N row
    state = STATE[args.dim]
    shape = " of spheres (3D, 6 degrees of freedom each)" if args.dim == 3 else ""
    lines = [
        f"One numeric factorisation of the resistance matrix (CHOLMOD, nested dissection, supernodal) of a "
        f"flowing φ = {state['phi']:g}, σ/σ0 = {state['stress']:g} configuration{shape} (implicit, disp_max "
        f"2e-3, {args.warmup} steps past the start), CPU time per particle (median of {args.windows} "
        f"windows); work = Σ_j c_j² over the columns of L.  Ratios to N = {min(args.n)} with the same "
        "ordering.\n",
    ]
    header = ["N", "ordering", "nnz(L) per particle", "work per particle (flop)", "ratio", "µs per particle"]
    header += ["ratio", "GFlop/s", "analysis ms"]
    body = []
    for r in rows:
        base = first[r["ordering"]]
        body.append(
            [f"{r['n']}", r["ordering"], f"{r['nnz_per_particle']:.0f}", f"{r['flops_per_particle']:.3g}"]
            + [f"{r['flops_per_particle'] / base['flops_per_particle']:.2f}", f"{r['us_per_particle']:.2f}"]
            + [f"{r['us_per_particle'] / base['us_per_particle']:.2f}", f"{r['gflops']:.1f}"]
            + [f"{r['analysis_ms']:.1f}"]
        )
    command = command_line("factor_scaling", argv)
    lines += [table(header, body), f"\nCommand: `{command}`"]
    publish(args.section, lines, not args.no_write, page=args.page, command=command)


if __name__ == "__main__":
    main()
