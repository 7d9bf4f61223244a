"""What a larger box costs: CPU per particle-step, peak memory, Cholesky fill and output size per run,
against N, from finished (or checkpointed) runs at the same state points, all from one machine.

    python -m bench.large_n data/paper/multirun data/large_n/multirun --phi 0.76

Per run: CPU seconds and steps recorded in the trajectory (``summary/cpu_seconds``, ``summary/steps``;
for a run still going, its last checkpoint's counters), the peak resident memory of the process that
ran it (``summary/peak_memory_mb``, where recorded), the file's size, and — from one step taken from the
run's last checkpoint — the CHOLMOD factor's fill nnz(L) / nnz(tril A) and its nnz per degree of
freedom.  A cost per particle-step flat in N means the step is O(N); nested dissection on a 2D mesh-like
matrix gives fill O(N log N) and factorisation flops O(N^1.5), so a slow growth is expected.  Results
replace the marked section of docs/jamming.md unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import h5py
import numpy as np

from bench.publishing import command_line, publish, table


def run_cost(path: Path) -> dict | None:
    from rheograph.io.hdf5 import read_run_info, readable_path

    readable = readable_path(path)  # a run still going: its last checkpoint's copy
    info = read_run_info(readable)
    params, summary = info["params"], info.get("summary") or {}
    with h5py.File(readable, "r") as h5:
        counters = json.loads(h5["checkpoint"].attrs["counters"])
    # a finished run's summary, or a running one's last checkpoint
    cpu = float(summary.get("cpu_seconds", counters.get("cpu_seconds", np.nan)))
    steps, strain = int(info["steps"]), float(info["strain"])
    return {
        "path": path,
        "n": int(params["n_particles"]),
        "phi": float(params["phi"]),
        "stress": float(params["stress"]),
        "disp_max": float(params["disp_max"]),
        "status": info["status"],
        "strain": strain,
        "cpu": cpu,
        "steps": steps,
        "peak_mb": float(summary.get("peak_memory_mb", counters.get("peak_memory_mb", np.nan))),
        "size_mb": path.stat().st_size / 1e6,
    }


def factor_fill(path: Path) -> tuple[float, float, float]:
    """(nnz(L) / nnz(tril A), nnz(L) per degree of freedom, the factor's values in MB at 8 bytes per
    nonzero) of the factor of one step from the run's last checkpoint (CHOLMOD; NaN with another
    backend)."""
    from rheograph.io.hdf5 import read_checkpoint, readable_path
    from rheograph.sim.integrator import Simulation
    from rheograph.sim.solver import CholmodSolver, cholmod_available

    if not cholmod_available():
        return np.nan, np.nan, np.nan
    params, state = read_checkpoint(readable_path(path))
    sim = Simulation(params, state, solver="cholmod")
    sim.step()
    solver = sim.solver
    assert isinstance(solver, CholmodSolver)
    nnz_l = solver._factor.L().nnz
    return nnz_l / solver._lower.nnz, nnz_l / solver._lower.shape[0], 8e-6 * nnz_l


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("directories", nargs="+", help="directories of trajectory files (searched recursively)")
    ap.add_argument("--phi", type=float, default=0.76)
    ap.add_argument("--stress", type=float, nargs="*", help="only these sigma/sigma0 (default: all)")
    ap.add_argument("--seed", type=int, default=1, help="the seed compared at every N")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    rows = []
    for directory in args.directories:
        for path in sorted(Path(directory).rglob("trajectory.h5")):
            row = run_cost(path)
            if not np.isclose(row["phi"], args.phi) or f"_seed{args.seed}_" not in str(path):
                continue
            if args.stress and not any(np.isclose(row["stress"], s) for s in args.stress):
                continue
            # runs that did not record their CPU time (older files: their logs' wall seconds include the
            # start-up) are left out
            if "implicit" not in path.parent.name or row["steps"] <= 0 or not np.isfinite(row["cpu"]):
                continue
            row["fill"], row["nnz_per_dof"], row["factor_mb"] = factor_fill(path)
            rows.append(row)
    rows.sort(key=lambda r: (r["stress"], r["n"]))
    reference = {(r["stress"], r["disp_max"]): r for r in rows if r["n"] == 400}
    lines = [
        f"φ = {args.phi:g}, seed {args.seed}, implicit scheme, one machine (runs of a sweep, one "
        "per core, the other core busy).  µs/particle-step = CPU s / (steps × N); the ratio is to "
        "N = 400 at the same stress.  Fill: CHOLMOD (nested dissection) from one step of the run's last "
        "checkpoint; factor MB: its values at 8 bytes each.  Peak memory: the high-water mark of the "
        "process that ran the sweep (the ~300 MB of imported libraries included; runs of one sweep share "
        "a process).\n",
    ]
    header = ["σ/σ0", "disp_max", "N", "status", "strain", "CPU s/strain", "steps/strain", "µs/particle-step"]
    header += [
        "ratio to N = 400",
        "peak memory MB",
        "fill nnz(L)/nnz(A)",
        "nnz(L)/dof",
        "factor MB",
        "file MB",
    ]
    body = []
    for r in rows:
        per = 1e6 * r["cpu"] / (r["steps"] * r["n"])
        ref = reference.get((r["stress"], r["disp_max"]))
        ratio = per / (1e6 * ref["cpu"] / (ref["steps"] * ref["n"])) if ref else np.nan
        body.append(
            [f"{r['stress']:g}", f"{r['disp_max']:g}", f"{r['n']}", r["status"], f"{r['strain']:.2f}"]
            + [
                f"{r['cpu'] / r['strain']:.1f}",
                f"{r['steps'] / r['strain']:.0f}",
                f"{per:.2f}",
                f"{ratio:.2f}",
            ]
            + [f"{r['peak_mb']:.0f}", f"{r['fill']:.2f}", f"{r['nnz_per_dof']:.1f}", f"{r['factor_mb']:.1f}"]
            + [f"{r['size_mb']:.1f}"]
        )
    command = command_line("large_n", argv)
    lines += [table(header, body), f"\nCommand: `{command}`"]
    publish("large_n_cost", lines, not args.no_write, page="jamming.md", command=command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
