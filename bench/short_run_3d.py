"""A short 3D run: relative viscosity, Pi / sigma, Z_mu and the cost per step of the 3D simulator.

    python -m bench.short_run_3d                                  # N = 300, phi 0.5, sigma/sigma0 10
    python -m bench.short_run_3d --n 500 --steps 600 --warmup 200

A smoke benchmark of one state point, not a converged measurement: a few hundred steps cover a strain of
~0.1 to 0.5 after the start-up transient, so the averages are of the early flow.  Averages are over the
steps after ``--warmup`` (eta_r = sigma / <rate> as LF_DEM reports it under stress control); ms/step is
wall time over the same steps, with the per-phase split of ``Simulation3D.timings``.

The cost of a step against N, with each size's peak memory (one process per N, so that its peak
resident set is its own):

    python -m bench.short_run_3d --sizes 500 2000 8000 --phi 0.56 --steps 60 --warmup 20 \
        --section step_cost_3d --page validation/speed.md

per N: the median CPU time of a step (``time.process_time``, the steps after the warm-up), per
particle-step and against the smallest N, the share of the factorisation in it, and the process's peak
resident memory (``ru_maxrss``).  ``--json PATH``
keeps one run's numbers (what ``--sizes`` gathers).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_THREAD_LIMIT", "1")  # CHOLMOD's OpenMP (see simulate.py)

import numpy as np  # noqa: E402

from bench.publishing import Section, command_line, publish  # noqa: E402
from rheograph.sim.integrator3d import Simulation3D  # noqa: E402
from rheograph.sim.params3d import SimParams3D  # noqa: E402
from rheograph.sim.stress3d import particle_pressure  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--phi", type=float, default=0.5)
    ap.add_argument("--stress", type=float, default=10.0)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--warmup", type=int, default=100)
    ap.add_argument("--integrator", default="implicit")
    ap.add_argument("--disp-max", type=float, default=2e-3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", type=Path, help="keep this run's numbers here")
    ap.add_argument("--sizes", type=int, nargs="+", help="one run per N, each in its own process")
    ap.add_argument(
        "--section", help="with --sizes: publish the table as this section of --page (else print)"
    )
    ap.add_argument("--page", default="validation/speed.md")
    args = ap.parse_args(argv)
    if args.sizes:
        return scaling(args, argv)
    params = SimParams3D(
        n_particles=args.n, phi=args.phi, stress=args.stress, integrator=args.integrator,
        disp_max=args.disp_max, seed=args.seed,
    )  # fmt: skip
    t0 = time.perf_counter()
    sim = Simulation3D(params)
    start = time.perf_counter() - t0
    for _ in range(args.warmup):
        sim.step()  # also compiles the kernels
    sim.timings.clear()
    strain0 = sim.state.strain
    rates, pressures, z_mu, z, cpu = [], [], [], [], []
    t0 = time.perf_counter()
    for _ in range(args.steps):
        c0 = time.process_time()
        res = sim.step(record=True)
        cpu.append(time.process_time() - c0)
        rates.append(res.shear_rate)
        pressures.append(particle_pressure(res.stress))
        z_mu.append(2.0 * res.n_frictional / args.n)
        z.append(2.0 * res.n_contacts / args.n)
    wall = time.perf_counter() - t0
    eta = args.stress / np.mean(rates)
    print(
        f"N={args.n} phi={args.phi} sigma/sigma0={args.stress} {args.integrator} disp_max={args.disp_max} "
        f"box={sim.state.lx:.3f} start {start:.1f} s"
    )
    print(f"strain {strain0:.3f} -> {sim.state.strain:.3f} in {args.steps} steps after {args.warmup} warm-up")
    print(
        f"eta_r = {eta:.3f}  Pi/sigma = {np.mean(pressures) / args.stress:.4f}  Z = {np.mean(z):.3f}  "
        f"Z_mu = {np.mean(z_mu):.3f}"
    )
    phases = "  ".join(f"{k} {1e3 * v / args.steps:.2f}" for k, v in sim.timings.items())
    print(f"{1e3 * wall / args.steps:.2f} ms/step ({phases} ms)")
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    "n": args.n,
                    "phi": args.phi,
                    "stress": args.stress,
                    "steps": args.steps,
                    "strain": [strain0, sim.state.strain],
                    "cpu_per_step_median_s": statistics.median(cpu),
                    "wall_per_step_s": wall / args.steps,
                    "phases_s": {k: v / args.steps for k, v in sim.timings.items()},
                    "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                }
            )
            + "\n"
        )
    return 0


def scaling(args, argv) -> int:
    """One run per N of ``--sizes`` in its own process; the table of the cost of a step against N."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            out = Path(tmp) / f"n{n}.json"
            command = [sys.executable, "-m", "bench.short_run_3d", "--n", str(n), "--phi", str(args.phi),
                       "--stress", str(args.stress), "--steps", str(args.steps), "--warmup", str(args.warmup),
                       "--integrator", args.integrator, "--disp-max", str(args.disp_max),
                       "--seed", str(args.seed), "--json", str(out)]  # fmt: skip
            done = subprocess.run(command, capture_output=True, text=True)
            if done.returncode != 0 or not out.is_file():
                tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
                raise SystemExit(f"short_run_3d: the run at N = {n} failed: {tail[0]}")
            rows.append(json.loads(out.read_text()))
            print(f"N = {n}: {1e3 * rows[-1]['cpu_per_step_median_s']:.1f} ms per step", flush=True)
    base = rows[0]["cpu_per_step_median_s"] / rows[0]["n"]
    cells = []
    for row in rows:
        per_particle = row["cpu_per_step_median_s"] / row["n"]
        factor_share = row["phases_s"].get("factorisation", 0.0) / row["wall_per_step_s"]
        cells.append(
            [
                f"{row['n']:,}",
                f"{1e3 * row['cpu_per_step_median_s']:.1f}",
                f"{1e6 * per_particle:.1f}",
                f"{per_particle / base:.2f}",
                f"{100 * factor_share:.0f} %",
                f"{row['peak_rss_mb']:,.0f}",
            ]
        )
    command = command_line("short_run_3d", argv)
    section = Section(
        f"**The cost of a 3D step against N** (φ = {args.phi:g}, σ/σ0 = {args.stress:g}, {args.integrator}, "
        f"disp_max {args.disp_max:g}; {args.steps} steps after {args.warmup} from each size's own start, one "
        "process per N on one core): the median CPU time of a step, per particle-step and against the "
        "smallest N, the factorisation's share of the step (wall time) and the process's peak resident "
        "memory (the factor's fill per particle: the factorisation table above).",
        "",
    )
    section.table(
        ["N", "ms per step", "µs per particle-step", "ratio", "factorisation", "peak memory (MB)"],
        cells,
    )  # fmt: skip
    section.add("", f"Command: `{command}`")
    publish(
        args.section or "step_cost_3d",
        section,
        args.section is not None,
        page=args.page,
        record={"runs": rows},
        command=command,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
