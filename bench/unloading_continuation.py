"""Does elastic unloading change the steady rheology of a committed run?  Continue a trajectory of the 3D
flow-curve set from its last checkpoint with ``sim.elastic_unloading=true`` (the file is read, never
written) and compare the steady η_r and Z_μ over the continuation with the run's own over strain >= 1.

    python -m bench.unloading_continuation \\
        data/flow_curves_3d/multirun/N500_phi0.58_s200_seed1_d0.002_implicit_3d/trajectory.h5 --strain 1

η_r of the continuation is σ Δt / Δγ over the whole window (the time average of the rate, as the runner's
steady value), with the standard error of five equal-strain blocks; the run's own is the same estimator
over its time series from strain 1.  Prints one JSON object; CPU seconds and steps per strain included.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

from rheograph.io.hdf5 import read_checkpoint, read_timeseries
from rheograph.sim.integrator3d import Simulation3D

BLOCKS = 5


def continuation(path: Path, strain: float, disp_max: float | None) -> dict:
    params, state = read_checkpoint(path)
    if params.DIM != 3:
        sys.exit(f"unloading_continuation: {path} is a 2D run; this benchmark continues 3D runs")
    changed = {"elastic_unloading": True, "integrator": "implicit"}
    if disp_max is not None:
        changed["disp_max"] = disp_max
    sim = Simulation3D(dataclasses.replace(params, **changed), state)
    start, cpu0 = state.strain, time.process_time()
    time_total = strain_total = z_mu_weighted = 0.0
    blocks, block_time, block_strain, steps = [], 0.0, 0.0, 0
    while strain_total < strain:
        result = sim.step()
        steps += 1
        d_strain = result.shear_rate * result.dt
        time_total += result.dt
        strain_total += d_strain
        z_mu_weighted += 2.0 * result.n_frictional / params.n_particles * d_strain
        block_time += result.dt
        block_strain += d_strain
        if strain_total >= strain * (len(blocks) + 1) / BLOCKS:
            blocks.append(params.stress * block_time / block_strain)
            block_time = block_strain = 0.0
    series = read_timeseries(path)
    steady = series["strain"] >= params.steady_state_strain
    s, t = series["strain"][steady], series["time"][steady]
    return {
        "run": str(path),
        "disp_max": sim.params.disp_max,
        "strain_window": [start, start + strain_total],
        "steps_per_strain": steps / strain_total,
        "cpu_seconds": time.process_time() - cpu0,
        "eta_r": params.stress * time_total / strain_total,
        "eta_r_blocks": blocks,
        "eta_r_se": float(np.std(blocks, ddof=1) / np.sqrt(len(blocks))),
        "z_mu": z_mu_weighted / strain_total,
        "run_eta_r": float(params.stress * (t[-1] - t[0]) / (s[-1] - s[0])),
        "run_z_mu": float(series["z_mu"][steady].mean()),
        "run_window": [float(s[0]), float(s[-1])],
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("trajectory", type=Path, help="a 3D trajectory file with a checkpoint")
    ap.add_argument("--strain", type=float, default=1.0, help="strain of the continuation")
    ap.add_argument("--disp-max", type=float, default=None, help="another step (default: the run's)")
    args = ap.parse_args(argv)
    if not args.trajectory.is_file():
        sys.exit(f"unloading_continuation: no trajectory file {args.trajectory}")
    if not args.strain > 0.0:
        sys.exit(f"unloading_continuation: --strain {args.strain} must be > 0")
    print(json.dumps(continuation(args.trajectory, args.strain, args.disp_max), indent=1))


if __name__ == "__main__":
    main()
