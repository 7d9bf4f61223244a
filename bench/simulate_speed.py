"""Simulator speed: wall and CPU seconds per unit strain, per particle-step, with a per-phase breakdown,
at phi = 0.76, sigma/sigma0 = 10 (the LF_DEM reference point) for several N and disp_max.

    python -m bench.simulate_speed                      # N = 400, 1000, 2000; disp_max 2e-3, 1e-3
    python -m bench.simulate_speed --n 400 --disp 2e-3  # a subset

Each case is warmed up (past the frictionless start-up transient, numba compiled) and then timed over
``--windows`` consecutive strain windows; medians are reported.  Results replace the marked section of
docs/validation/speed.md.  Run it alone on the machine: timings of a shared machine are noisy.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_THREAD_LIMIT", "1")  # CHOLMOD's OpenMP (see simulate.py)

import numpy as np  # noqa: E402

from bench.publishing import publish, table
from rheograph.sim import SimParams, Simulation  # noqa: E402
from rheograph.sim.params import scheme_settings  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PHASES = ("neighbours", "assembly", "factorisation", "solve", "stress", "update")


def measure(n, disp, scheme, solver, skin, warmup, window, windows):
    """``scheme`` is an integrator name, with ``-lagged`` appended for LF_DEM's lagged step control."""
    params = SimParams(
        n_particles=n,
        phi=0.76,
        stress=10.0,
        disp_max=disp,
        **scheme_settings(scheme),
        neighbour_skin=skin,
    )
    sim = Simulation(params, solver=solver)
    while sim.state.strain < warmup:
        sim.step()
    results = []
    for _ in range(windows):
        sim.timings.clear()
        steps0, strain0 = sim.state.steps, sim.state.strain
        w0, c0 = time.perf_counter(), time.process_time()
        while sim.state.strain < strain0 + window:
            sim.step()
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        nsteps, dstrain = sim.state.steps - steps0, sim.state.strain - strain0
        results.append(
            dict(
                wall_per_strain=wall / dstrain,
                cpu_per_strain=cpu / dstrain,
                steps_per_strain=nsteps / dstrain,
                us_per_particle_step=1e6 * wall / (nsteps * n),
                ms_per_step=1e3 * wall / nsteps,
                **{f"frac_{k}": sim.timings[k] / wall for k in PHASES},
            )
        )
    return {k: float(np.median([r[k] for r in results])) for k in results[0]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[400, 1000, 2000])
    ap.add_argument("--disp", type=float, nargs="+", default=[2e-3, 1e-3])
    ap.add_argument(
        "--integrators",
        nargs="+",
        default=["euler", "implicit"],
        help="integrator names; append -lagged for LF_DEM's step control (e.g. euler-lagged)",
    )
    ap.add_argument("--solvers", nargs="+", default=["cholmod", "qdldl"])
    ap.add_argument("--skins", type=float, nargs="+", default=[SimParams.neighbour_skin])
    ap.add_argument("--warmup", type=float, default=0.3, help="strain before timing")
    ap.add_argument("--windows", type=int, default=3)
    ap.add_argument("--particle-steps", type=float, default=3e6, help="work per timing window")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    header = [
        "N", "disp_max", "integrator", "solver", "skin", "wall s/strain", "CPU s/strain", "steps/strain",
        "ms/step", "µs/particle-step", "neighbours", "assembly", "factorise", "solve", "stress", "update",
    ]  # fmt: skip
    rows, measured = [], []
    cases = [
        (integrator, disp, n, solver, skin)
        for integrator in args.integrators
        for disp in args.disp
        for n in args.n
        for solver in args.solvers
        for skin in args.skins
    ]
    for integrator, disp, n, solver, skin in cases:
        # strain window holding about --particle-steps particle-steps (~15 steps per 1e-3 strain)
        window = max(0.01, args.particle_steps / (n * 15.0 / disp * 1e-3) * 1e-3)
        r = measure(n, disp, integrator, solver, skin, args.warmup, window, args.windows)
        row = [
            f"{n}", f"{disp:g}", integrator, solver, f"{skin:g}", f"{r['wall_per_strain']:.1f}",
            f"{r['cpu_per_strain']:.1f}", f"{r['steps_per_strain']:.0f}", f"{r['ms_per_step']:.2f}",
            f"{r['us_per_particle_step']:.2f}", *(f"{100 * r['frac_' + k]:.0f}%" for k in PHASES),
        ]  # fmt: skip
        print(" | ".join(row), flush=True)
        rows.append(row)
        measured.append(
            {"n": n, "disp_max": disp, "integrator": integrator, "solver": solver, "skin": skin, **r}
        )
    command = "python -m bench.simulate_speed " + " ".join(
        f"--{k.replace('_', '-')} {' '.join(map(str, v)) if isinstance(v, list) else v}"
        for k, v in vars(args).items()
        if k != "no_write"
    )
    blocks = [
        f"Machine: {os.cpu_count()} cores, single-threaded simulator "
        "(OPENBLAS_NUM_THREADS=OMP_THREAD_LIMIT=1); "
        f"φ = 0.76, σ/σ0 = 10; medians of {args.windows} windows after {args.warmup} strain of warm-up.\n",
        table(header, rows),
        f"\nCommand: `{command}`",
    ]
    publish(
        "simulate_speed",
        blocks,
        not args.no_write,
        page="validation/speed.md",
        record={"measured": measured},
        command=command,
    )


if __name__ == "__main__":
    main()
