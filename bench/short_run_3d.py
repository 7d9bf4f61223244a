"""A short 3D run: relative viscosity, Pi / sigma, Z_mu and the cost per step of the 3D simulator.

    python -m bench.short_run_3d                                  # N = 300, phi 0.5, sigma/sigma0 10
    python -m bench.short_run_3d --n 500 --steps 600 --warmup 200

A smoke benchmark of one state point, not a converged measurement: a few hundred steps cover a strain of
~0.1 to 0.5 after the start-up transient, so the averages are of the early flow.  Averages are over the
steps after ``--warmup`` (eta_r = sigma / <rate> as LF_DEM reports it under stress control); ms/step is
wall time over the same steps, with the per-phase split of ``Simulation3D.timings``.

The cost of a step against N, with each size's peak memory (one process per N and solver, so that its
peak resident set is its own):

    python -m bench.short_run_3d --sizes 500 2000 8000 --phi 0.56 --steps 60 --warmup 20 \
        --solvers cholmod amg --section step_cost_3d --page validation/speed.md

per N and solver: the median CPU time of a step (``time.process_time``, the steps after the warm-up), per
particle-step and against the smallest N with the first solver, the share of the factorisation (for
``amg``: the multigrid set-up) and of the solves in it, the mean CG iterations per right-hand side
(``amg``), and the process's peak resident memory (``ru_maxrss``).  ``--json PATH`` keeps one run's
numbers (what ``--sizes`` gathers).

A fresh start has few close pairs, so its matrix is easier for an iterative solver than that of steady
flow.  ``--start TRAJECTORY`` starts every size from the last checkpoint of a steady 3D run instead,
replicated periodically (Lees-Edwards images kept) into the most cube-like box of N particles: N must be
the run's N times a whole number (8 x 500 = 4000 is a 2 x 2 x 2 cube, 16 x 500 = 8000 a 4 x 2 x 2
box; an elongated box has smaller separators, which favours the direct factor).
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


def arguments(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--phi", type=float, default=0.5)
    ap.add_argument("--stress", type=float, default=10.0)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--warmup", type=int, default=100)
    ap.add_argument("--integrator", default="implicit")
    ap.add_argument("--disp-max", type=float, default=2e-3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--solver", default="auto", help="auto, cholmod, qdldl or amg (rheograph.sim.solver)")
    ap.add_argument("--solvers", nargs="+", help="with --sizes: one run per N and solver")
    ap.add_argument("--start", type=Path, help="a steady 3D trajectory whose last checkpoint is replicated")
    ap.add_argument("--json", type=Path, help="keep this run's numbers here")
    ap.add_argument("--sizes", type=int, nargs="+", help="one run per N, each in its own process")
    ap.add_argument(
        "--section", help="with --sizes: publish the table as this section of --page (else print)"
    )
    ap.add_argument("--page", default="validation/speed.md")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = arguments(argv)
    if args.sizes:
        return scaling(args, argv)
    if args.start is not None:
        params, state = replicated_start(args.start, args.n)
        args.phi, args.stress = params.phi, params.stress
    else:
        params = SimParams3D(
            n_particles=args.n, phi=args.phi, stress=args.stress, integrator=args.integrator,
            disp_max=args.disp_max, seed=args.seed,
        )  # fmt: skip
        state = None
    t0 = time.perf_counter()
    sim = Simulation3D(params, state=state, solver=args.solver)
    start = time.perf_counter() - t0
    for _ in range(args.warmup):
        sim.step()  # also compiles the kernels
    sim.timings.clear()
    strain0 = sim.state.strain
    rates, pressures, z_mu, z, cpu, iterations = [], [], [], [], [], []
    t0 = time.perf_counter()
    for _ in range(args.steps):
        c0 = time.process_time()
        res = sim.step(record=True)
        cpu.append(time.process_time() - c0)
        iterations += getattr(sim.solver, "iterations", [])
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
                    "solver": sim.solver.name,
                    "start": "fresh" if args.start is None else str(args.start),
                    "box": [sim.state.lx, sim.state.ly, sim.state.lz],
                    "cg_iterations_mean": float(np.mean(iterations)) if iterations else None,
                    "fallbacks": getattr(sim.solver, "fallbacks", 0),
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


def most_cubic_tiling(copies: int) -> tuple[int, int, int]:
    """Whole numbers (nx, ny, nz) with product ``copies`` whose largest over smallest is least."""
    best = None
    for nx in range(1, copies + 1):
        for ny in range(1, copies // nx + 1):
            if copies % (nx * ny) == 0:
                tiles = (nx, ny, copies // (nx * ny))
                if best is None or max(tiles) / min(tiles) < max(best) / min(best):
                    best = tiles
    return best


def replicated_start(path: Path, n: int):
    """``path``'s last checkpoint (params, state) replicated into n particles (``most_cubic_tiling``).

    Copies are shifted by whole box edges; a copy one box up in y is also shifted by the Lees-Edwards
    offset, so that the replicated box's images (offset multiplied by the copies in y) are those of the
    original flow.  The neighbour list and contact history are rebuilt (contacts restart unstretched)."""

    from rheograph.io.hdf5 import read_checkpoint

    params, state = read_checkpoint(path)
    n0 = state.radii.shape[0]
    if state.positions.shape[1] != 3 or n % n0:
        raise SystemExit(f"short_run_3d: --start {path}: a 3D run whose N ({n0}) divides every size ({n})")
    return replicate(params, state, n)


def replicate(params, state, n: int):
    """(params, state) of ``n`` particles: ``state`` copied ``n / N`` times (``replicated_start``)."""
    import dataclasses

    from rheograph.sim.geometry import wrap_offset
    from rheograph.sim.geometry3d import wrap_positions
    from rheograph.sim.integrator3d import SimState3D

    n0 = state.radii.shape[0]
    nx, ny, nz = most_cubic_tiling(n // n0)
    copies = []
    for j in range(ny):
        for i in range(nx):
            for k in range(nz):
                shift = np.array([i * state.lx + j * state.le_offset, j * state.ly, k * state.lz])
                copies.append(state.positions + shift)
    positions = np.concatenate(copies)
    lx, ly, lz = nx * state.lx, ny * state.ly, nz * state.lz
    le_offset = wrap_offset(ny * state.le_offset, lx)
    # into the primary box centred on the origin, the frame the cell list's Lees-Edwards layers assume
    wrap_positions(positions, lx, ly, lz, le_offset)
    tiled = SimState3D(
        positions=positions, radii=np.tile(state.radii, nx * ny * nz), lx=lx, ly=ly, lz=lz,
        le_offset=le_offset, time=state.time, strain=state.strain, dt_assumed=state.dt_assumed,
    )  # fmt: skip
    return dataclasses.replace(params, n_particles=n), tiled


def scaling(args, argv) -> int:
    """One run per N of ``--sizes`` (and solver of ``--solvers``) in its own process; the table of the
    cost of a step against N."""
    if args.start is not None:  # the state point is the start's
        from rheograph.io.hdf5 import read_params

        stored = read_params(args.start)
        args.phi, args.stress = stored["phi"], stored["stress"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for solver in args.solvers or [args.solver]:
            for n in args.sizes:
                out = Path(tmp) / f"n{n}_{solver}.json"
                command = [sys.executable, "-m", "bench.short_run_3d", "--n", str(n), "--phi", str(args.phi),
                           "--stress", str(args.stress), "--steps", str(args.steps),
                           "--warmup", str(args.warmup),
                           "--integrator", args.integrator, "--disp-max", str(args.disp_max),
                           "--seed", str(args.seed), "--solver", solver, "--json", str(out)]  # fmt: skip
                if args.start is not None:
                    command += ["--start", str(args.start)]
                done = subprocess.run(command, capture_output=True, text=True)
                if done.returncode != 0 or not out.is_file():
                    tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
                    raise SystemExit(f"short_run_3d: the run at N = {n} ({solver}) failed: {tail[0]}")
                rows.append(json.loads(out.read_text()))
                print(
                    f"N = {n}, {solver}: {1e3 * rows[-1]['cpu_per_step_median_s']:.1f} ms per step",
                    flush=True,
                )
    return publish_rows(args, argv, rows)


def publish_rows(args, argv, rows: list[dict]) -> int:
    """The table of ``scaling``'s runs (one dict per N and solver, what ``--json`` writes), published;
    ``args`` and ``argv`` those of the command that measured them."""
    base = rows[0]["cpu_per_step_median_s"] / rows[0]["n"]
    cells = []
    for row in rows:
        per_particle = row["cpu_per_step_median_s"] / row["n"]
        phases = row["phases_s"]
        iterations = row.get("cg_iterations_mean")
        cells.append(
            [
                f"{row['n']:,}",
                row.get("solver", "cholmod"),
                " × ".join(f"{edge / min(row['box']):.0f}" for edge in row["box"])
                if "box" in row
                else "1 × 1 × 1",
                f"{1e3 * row['cpu_per_step_median_s']:.1f}",
                f"{1e6 * per_particle:.1f}",
                f"{per_particle / base:.2f}",
                f"{100 * phases.get('factorisation', 0.0) / row['wall_per_step_s']:.0f} %",
                f"{100 * phases.get('solve', 0.0) / row['wall_per_step_s']:.0f} %",
                "–" if iterations is None else f"{iterations:.0f}",
                f"{row['peak_rss_mb']:,.0f}",
            ]
        )
    command = command_line("short_run_3d", argv)
    start = (
        "from each size's own start"
        if args.start is None
        else f"from the last checkpoint of `{args.start}` (steady flow) replicated into each N"
    )
    section = Section(
        f"**The cost of a 3D step against N** (φ = {args.phi:g}, σ/σ0 = {args.stress:g}, {args.integrator}, "
        f"disp_max {args.disp_max:g}; {args.steps} steps after {args.warmup} {start}, one process per N and "
        "solver on one core): the box's edges relative to its smallest, the median CPU time of a step, per "
        "particle-step and against the first row, the shares of the step (wall time) of the factorisation "
        "(for `amg`: the multigrid set-up) and of the solves, the conjugate-gradient iterations per "
        "right-hand side (`amg`), and the process's peak resident memory.",
        "",
    )
    section.table(
        ["N", "solver", "box", "ms per step", "µs per particle-step", "ratio", "factorisation", "solves",
         "CG iterations", "peak memory (MB)"],
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
