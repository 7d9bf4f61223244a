"""A shipped surrogate on snapshots of another code: LF_DEM runs, read from their par_*.dat files (6-digit
positions), scored against LF_DEM's own η_r, Π and Z_μ, beside the physics-only rows; and the cost of
predicting 1000 snapshots.

    python bench/lfdem_snapshots.py --runs /work/lfdem_runs/s*/par_*.dat --model N400_phi0.76

The LF_DEM runs are made outside the project (bench/vs_lfdem.py says how to build LF_DEM; configuration
output every 0.1 strain, ``out_data_particle`` and ``out_data_interaction`` on).  Snapshots at strain >= 1
(``--min-strain``) are scored: R² on log10 η_r and Π, linear Z_μ, over all runs together.  Physics-only
rows need no training: the one-solve η_r, the contact-spring pressure and the counted Z_μ computed from
the same positions (the ``eta_solve``, ``pressure_spring``, ``z_mu_counted`` columns of a
prediction).  Results replace the marked section of docs/benchmarks.md unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from simulate_speed import command_line, publish  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def r2(pred, true):
    return 1.0 - np.sum((true - pred) ** 2) / np.sum((true - true.mean()) ** 2)


def scores(pred: np.ndarray, true: np.ndarray) -> tuple[float, float, float]:
    """R² log10 η_r, log10 Π (positive values), Z_μ."""
    out = []
    for k in (0, 1):
        ok = (pred[:, k] > 0) & (true[:, k] > 0)
        out.append(r2(np.log10(pred[ok, k]), np.log10(true[ok, k])))
    out.append(r2(pred[:, 2], true[:, 2]))
    return tuple(out)


def main(argv=None) -> int:
    from rheograph.io.snapshots import read_snapshots
    from rheograph.learn.predict import load_model

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", nargs="+", required=True, help="LF_DEM par_*.dat files")
    ap.add_argument("--model", default="N400_phi0.76")
    ap.add_argument("--min-strain", type=float, default=1.0)
    ap.add_argument("--timing-snapshots", type=int, default=1000)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)

    model = load_model(args.model)
    rows, physics, true, per_run = [], [], [], []
    start = time.perf_counter()
    for path in sorted(args.runs):
        snaps = read_snapshots(path)
        table = model.predict_snapshots(snaps)
        keep = snaps.strain >= args.min_strain
        pred = np.stack([table[f"{t}_pred"] for t in ("eta", "pressure", "z_mu")], axis=1)[keep]
        sim = np.stack([table[f"{t}_sim"] for t in ("eta", "pressure", "z_mu")], axis=1)[keep]
        phys = np.stack([table[c] for c in ("eta_solve", "pressure_spring", "z_mu_counted")], axis=1)[keep]
        rows.append(pred)
        physics.append(phys)
        true.append(sim)
        row = (
            f"| {snaps.stress:g} | {snaps.numerics.get('disp_max', float('nan')):g} | {keep.sum()} | "
            f"{snaps.position_noise:.1e} | {sim[:, 0].mean():.1f} | {pred[:, 0].mean():.1f} | "
            f"{sim[:, 1].mean():.2f} | {pred[:, 1].mean():.2f} | {sim[:, 2].mean():.3f} | "
            f"{pred[:, 2].mean():.3f} | {table['in_domain'][keep].mean():.2f} |"
        )
        per_run.append((snaps.stress, row))
    seconds = time.perf_counter() - start
    pred, phys, sim = np.concatenate(rows), np.concatenate(physics), np.concatenate(true)
    net, solve = scores(pred, sim), scores(phys, sim)

    # cost: the first run's snapshots repeated up to --timing-snapshots, one process, after warm-up
    snaps = read_snapshots(sorted(args.runs)[0])
    reps = int(np.ceil(args.timing_snapshots / len(snaps)))
    snaps.positions = np.concatenate([snaps.positions] * reps)[: args.timing_snapshots]
    for name in ("le_offset", "strain", "jammed"):
        setattr(snaps, name, np.concatenate([getattr(snaps, name)] * reps)[: args.timing_snapshots])
    snaps.targets = np.concatenate([snaps.targets] * reps)[: args.timing_snapshots]
    t0 = time.perf_counter()
    model.predict_snapshots(snaps)
    cost = time.perf_counter() - t0

    command = command_line("lfdem_snapshots.py", argv)
    lines = [
        f"### A shipped model on LF_DEM snapshots ({args.model})",
        "",
        f"{len(sim)} snapshots at strain ≥ {args.min_strain:g} of {len(rows)} LF_DEM runs, read from their "
        "`par_*.dat` (positions to LF_DEM's 6 printed digits) with LF_DEM's own η_r = σ/γ̇, Π and Z_μ "
        "(contact states of `int_*.dat`) as the truth; all runs scored together.",
        "",
        "| predictor | R² log η_r | R² log Π | R² Z_μ |",
        "|---|---|---|---|",
        f"| graph network ({args.model}) | {net[0]:.4f} | {net[1]:.5f} | {net[2]:.5f} |",
        f"| physics only: one-solve η_r, contact-spring Π, counted Z_μ | {solve[0]:.4f} | {solve[1]:.5f} | "
        f"{solve[2]:.5f} |",
        "",
        "| σ/σ0 | LF_DEM disp_max | snapshots | position rounding RMS [a] | η_r LF_DEM | η_r predicted | "
        "Π LF_DEM | Π predicted | Z_μ LF_DEM | Z_μ predicted | in domain |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        *[row for _, row in sorted(per_run)],
        "",
        f"Prediction cost: {args.timing_snapshots} N = {snaps.n_particles} snapshots in {cost:.1f} s on one "
        f"core (one call, graphs built and the one-solve included; {1e3 * cost / args.timing_snapshots:.1f} "
        f"ms per snapshot); the scored runs took {seconds:.0f} s including reading and warm-up.",
        "",
        f"Command: `{command}`",
    ]
    publish("lfdem_snapshots", "\n".join(lines), not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
