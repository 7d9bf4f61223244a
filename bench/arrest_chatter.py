"""What an arrested packing costs to simulate, and why: continue shear-jammed runs from their checkpoints
for a few steps and measure the step, the shear rate and the contacts step by step.

    python -m bench.arrest_chatter [FILES ...] [--steps 40] [--no-write]

Default files: the shear-jammed runs of data/paper (status ``jammed``, checkpoint kept).  Under stress
control an arrested packing does not come to rest in the simulation: the shear rate changes sign from one
step to the next (period-2), and the fastest interaction -- a contact sliding back and forth, or a pair
crossing the CLM threshold -- moves by disp_max every step, so the adaptive step stays at disp_max / that
speed.  The flow is arrested on average (the mean shear rate, over a window, is what the jam detector
reads), but the step count per unit time is that of a fast flow: confirming an arrest costs
``jam_intervals`` stall rows of ``output_interval * jam_viscosity / stress`` time each.  Per run: median
step, steps per unit time, mean and r.m.s. shear rate, the share of steps whose shear rate changes sign,
the step-to-step change of the particle pressure (relative: what the chatter does to the arrested
packing's labels) and the share of steps that change the number of touching or frictional contacts.
Results replace the ``arrest_chatter`` section of docs/validation/speed.md unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import glob
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_THREAD_LIMIT", "1")  # CHOLMOD's OpenMP (see simulate.py)

import numpy as np  # noqa: E402

from bench.publishing import publish
from rheograph.io.hdf5 import read_checkpoint, read_run_info  # noqa: E402
from rheograph.sim.integrator import Simulation, particle_pressure  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def chatter(path: str, steps: int) -> dict:
    """Continue the run in ``path`` from its checkpoint for ``steps`` steps (the file is not changed)."""
    params, state = read_checkpoint(path)
    sim = Simulation(params, state)
    rows = []
    t0 = time.process_time()
    for _ in range(steps):
        r = sim.step(record=True)
        rows.append((r.dt, r.shear_rate, particle_pressure(r), r.n_frictional, r.n_contacts))
    cpu = (time.process_time() - t0) / steps
    dt, rate, pressure, frictional, touching = (np.array(c, dtype=np.float64) for c in zip(*rows))
    return dict(
        n=params.n_particles,
        phi=params.phi,
        stress=params.stress,
        seed=params.seed,
        dt=float(np.median(dt)),
        cpu_per_step=cpu,
        mean_rate=float(rate.mean()),
        rms_rate=float(np.sqrt((rate**2).mean())),
        sign_changes=float(np.mean(np.sign(rate[1:]) != np.sign(rate[:-1]))),
        pressure_jump=float(np.median(np.abs(np.diff(pressure))) / np.abs(pressure).mean()),
        frictional_changes=float(np.mean(np.diff(frictional) != 0)),
        contact_changes=float(np.mean(np.diff(touching) != 0)),
        stall_time=params.output_interval * params.jam_viscosity / params.stress,
        jam_intervals=params.jam_intervals,
    )


def render(results: list[dict], command: str) -> str:
    lines = [
        f"Command: `{command}` (each run continued {results[0]['steps']} steps from its checkpoint; the "
        "files are not changed).  Steps per stall row: the steps one row of the jam detector's "
        "time cadence (output_interval × jam_viscosity / σ) takes at that step; CPU per stall row at "
        "this machine's cost per step.",
        "",
        "| N | φ | σ/σ0 | seed | median dt | steps per unit time | mean γ̇ | r.m.s. γ̇ | sign changes "
        "| step-to-step ΔΠ/Π | steps changing the contact / frictional count | steps per stall row "
        "| CPU s per stall row |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        per_row = r["stall_time"] / r["dt"]
        lines.append(
            f"| {r['n']} | {r['phi']:.2f} | {r['stress']:g} | {r['seed']} | {r['dt']:.2e} "
            f"| {1 / r['dt']:.0f} "
            f"| {r['mean_rate']:+.1e} | {r['rms_rate']:.1e} | {r['sign_changes']:.0%} "
            f"| {r['pressure_jump']:.1e} | {r['contact_changes']:.0%} / {r['frictional_changes']:.0%} "
            f"| {per_row:.0f} "
            f"| {per_row * r['cpu_per_step']:.0f} |"
        )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="*", help="trajectory files or glob patterns (default: jammed runs)")
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    if args.steps < 2:
        raise SystemExit(f"--steps={args.steps}: allowed >= 2")
    patterns = args.files or [str(ROOT / "data/paper/multirun/*/trajectory.h5")]
    files = sorted({f for pattern in patterns for f in glob.glob(pattern)})
    if not args.files:
        files = [f for f in files if read_run_info(f)["status"] == "jammed"]
    if not files:
        raise SystemExit(f"no trajectory file in {patterns}")
    results = []
    for path in files:
        result = chatter(path, args.steps)
        result["steps"] = args.steps
        results.append(result)
        print(path, {k: result[k] for k in ("dt", "mean_rate", "rms_rate", "sign_changes")}, flush=True)
    shown = " ".join(os.path.relpath(f, ROOT) for f in args.files) if args.files else ""
    command = f"python -m bench.arrest_chatter {shown} --steps {args.steps}".replace("  ", " ")
    publish("arrest_chatter", render(results, command), write=not args.no_write)


if __name__ == "__main__":
    main()
