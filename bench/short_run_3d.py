"""A short 3D run: relative viscosity, Pi / sigma, Z_mu and the cost per step of the 3D simulator.

    python -m bench.short_run_3d                                  # N = 300, phi 0.5, sigma/sigma0 10
    python -m bench.short_run_3d --n 500 --steps 600 --warmup 200

A smoke benchmark of one state point, not a converged measurement: a few hundred steps cover a strain of
~0.1 to 0.5 after the start-up transient, so the averages are of the early flow.  Averages are over the
steps after ``--warmup`` (eta_r = sigma / <rate> as LF_DEM reports it under stress control); ms/step is
wall time over the same steps, with the per-phase split of ``Simulation3D.timings``.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_THREAD_LIMIT", "1")  # CHOLMOD's OpenMP (see simulate.py)

import numpy as np  # noqa: E402

from rheograph.sim.integrator3d import Simulation3D  # noqa: E402
from rheograph.sim.params3d import SimParams3D  # noqa: E402
from rheograph.sim.stress3d import particle_pressure  # noqa: E402


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--phi", type=float, default=0.5)
    ap.add_argument("--stress", type=float, default=10.0)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--warmup", type=int, default=100)
    ap.add_argument("--integrator", default="implicit")
    ap.add_argument("--disp-max", type=float, default=2e-3)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
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
    rates, pressures, z_mu, z = [], [], [], []
    t0 = time.perf_counter()
    for _ in range(args.steps):
        res = sim.step(record=True)
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


if __name__ == "__main__":
    main()
