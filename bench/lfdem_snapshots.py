"""A shipped surrogate on snapshots of another code: LF_DEM runs, read from their par_*.dat files (6-digit
positions), scored against LF_DEM's own η_r, Π and Z_μ, beside the physics-only rows; and the cost of
predicting 1000 snapshots.

    python -m bench.lfdem_snapshots --runs /work/lfdem_runs/s*/par_*.dat --model N400_phi0.76

The LF_DEM runs are made outside the project (bench/vs_lfdem.py says how to build LF_DEM; configuration
output every 0.1 strain, ``out_data_particle`` and ``out_data_interaction`` on).  Snapshots at strain >= 1
(``--min-strain``) are scored: R² on log10 η_r and Π, linear Z_μ, over all runs together.  Physics-only
rows need no training: the one-solve η_r, the contact-spring pressure and the counted Z_μ computed from
the same positions (the ``eta_solve``, ``pressure_spring``, ``z_mu_counted`` columns of a
prediction).  Results replace the marked section of docs/validation/position_noise.md unless ``--no-write``.

With ``--noise ε`` Gaussian noise of ε per coordinate [a] (seeded, ``--seed``) is added to LF_DEM's
positions and declared to the model with the rounding (``position_noise`` = √(rounding² + ε²)): an
imaging model on snapshots of a code it was never trained on.

    python -m bench.lfdem_snapshots --runs ... --model N400_phi0.76_imaging --noise 0.01 \
        --section lfdem_snapshots_imaging
"""

from __future__ import annotations

import argparse
import glob
import sys
import time
from pathlib import Path

import numpy as np

from bench.publishing import command_line, publish
from bench.publishing import table as table_block
from bench.zero_shot_n import lookup_mean  # noqa: E402

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


def state_means(paths: list[str], min_strain: float) -> dict:
    """{σ/σ0: (φ, N, (3,) means)} over the flowing snapshots at strain >= ``min_strain`` of rheograph
    trajectories (globs): geometric means of η_r and Π (the scores are in log), mean of Z_μ — what their
    data says at each stress without reading a snapshot."""
    from rheograph.io.snapshots import read_snapshots

    files: list[str] = []
    for pattern in paths:  # quoted globs expand here
        found = sorted(glob.glob(pattern))
        if not found:
            sys.exit(f"lfdem_snapshots: --lookup {pattern} matches no file")
        files.extend(found)
    pooled: dict = {}
    for path in files:
        snaps = read_snapshots(path)
        keep = (snaps.strain >= min_strain) & ~snaps.jammed
        if np.any(snaps.targets[keep, :2] <= 0.0):  # the lookup is a geometric mean
            first = float(snaps.strain[keep][np.any(snaps.targets[keep, :2] <= 0.0, axis=1)][0])
            sys.exit(
                f"lfdem_snapshots: --lookup {path} has η_r or Π <= 0 at strain {first:.3g} (a start-up "
                f"transient): raise --min-strain"
            )
        key = (round(float(snaps.stress), 9), round(snaps.phi, 6), snaps.n_particles)
        pooled.setdefault(key, []).append(snaps.targets[keep])
    means = {}
    for (stress, phi, n), parts in pooled.items():
        if stress in means:
            sys.exit(f"lfdem_snapshots: --lookup mixes state points at σ/σ0 = {stress:g}: give one φ and N")
        if not sum(len(t) for t in parts):
            sys.exit(
                f"lfdem_snapshots: --lookup has no flowing snapshot at strain >= {min_strain:g}, "
                f"σ/σ0 = {stress:g}"
            )
        means[stress] = (phi, n, lookup_mean(parts))
    return means


def main(argv=None) -> int:
    from rheograph.io.configurations import noisy_positions
    from rheograph.io.snapshots import read_snapshots
    from rheograph.learn.predict import load_model

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", nargs="+", required=True, help="LF_DEM par_*.dat files")
    ap.add_argument("--model", default="N400_phi0.76")
    ap.add_argument("--min-strain", type=float, default=1.0)
    ap.add_argument("--timing-snapshots", type=int, default=1000)
    ap.add_argument("--noise", type=float, default=0.0, help="Gaussian position noise per coordinate [a]")
    ap.add_argument("--seed", type=int, default=0, help="seed of the noise")
    ap.add_argument(
        "--section",
        default="lfdem_snapshots",
        help="the marked section (default: docs/validation/position_noise.md's)",
    )
    ap.add_argument(
        "--page",
        help="the docs page of a new section (default: the page its record already names)",
    )
    ap.add_argument(
        "--lookup",
        nargs="+",
        default=[],
        help="rheograph trajectories at the runs' φ: their mean at each σ is scored as the lookup row",
    )
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    if not (np.isfinite(args.noise) and args.noise >= 0.0):
        sys.exit(f"lfdem_snapshots: --noise {args.noise}: give a noise level >= 0 (units of a)")
    rng = np.random.default_rng(args.seed)
    lookup = state_means(args.lookup, args.min_strain) if args.lookup else {}

    def load(path):
        """The run's snapshots, with the noise of ``--noise`` added and declared."""
        snaps = read_snapshots(path)
        if args.noise > 0.0:
            snaps.positions = np.stack(
                [noisy_positions(snaps, k, args.noise, rng) for k in range(len(snaps))]
            )
            snaps.position_noise = float(np.hypot(snaps.position_noise or 0.0, args.noise))
        return snaps

    model = load_model(args.model)
    rows, physics, true, per_run, looked_up = [], [], [], [], []
    start = time.perf_counter()
    for path in sorted(args.runs):
        snaps = load(path)
        table = model.predict_snapshots(snaps)
        keep = snaps.strain >= args.min_strain
        pred = np.stack([table[f"{t}_pred"] for t in ("eta", "pressure", "z_mu")], axis=1)[keep]
        sim = np.stack([table[f"{t}_sim"] for t in ("eta", "pressure", "z_mu")], axis=1)[keep]
        phys = np.stack([table[c] for c in ("eta_solve", "pressure_spring", "z_mu_counted")], axis=1)[keep]
        if lookup:
            if round(float(snaps.stress), 9) not in lookup:
                sys.exit(f"lfdem_snapshots: --lookup has no trajectory at σ/σ0 = {snaps.stress:g} ({path})")
            phi, n, mean = lookup[round(float(snaps.stress), 9)]
            if abs(phi - snaps.phi) > 1e-3 or n != snaps.n_particles:
                sys.exit(
                    f"lfdem_snapshots: --lookup runs are at φ = {phi:g}, N = {n}; {path} at "
                    f"φ = {snaps.phi:g}, N = {snaps.n_particles}"
                )
            looked_up.append(np.repeat(mean[None], len(pred), axis=0))
        rows.append(pred)
        physics.append(phys)
        true.append(sim)
        row = [
            f"{snaps.stress:g}", f"{snaps.numerics.get('disp_max', float('nan')):g}", f"{keep.sum()}",
            f"{snaps.position_noise:.1e}", f"{sim[:, 0].mean():.1f}", f"{pred[:, 0].mean():.1f}",
            f"{sim[:, 1].mean():.2f}", f"{pred[:, 1].mean():.2f}", f"{sim[:, 2].mean():.3f}",
            f"{pred[:, 2].mean():.3f}", f"{table['in_domain'][keep].mean():.2f}",
            *([f"{looked_up[-1][0, 0]:.1f}"] if lookup else []),
        ]  # fmt: skip
        per_run.append((snaps.stress, row))
    seconds = time.perf_counter() - start
    pred, phys, sim = np.concatenate(rows), np.concatenate(physics), np.concatenate(true)
    net, solve = scores(pred, sim), scores(phys, sim)
    base = scores(np.concatenate(looked_up), sim) if lookup else None

    # cost: the first run's snapshots repeated up to --timing-snapshots, one process, after warm-up
    snaps = load(sorted(args.runs)[0])
    reps = int(np.ceil(args.timing_snapshots / len(snaps)))
    snaps.positions = np.concatenate([snaps.positions] * reps)[: args.timing_snapshots]
    for name in ("le_offset", "strain", "jammed"):
        setattr(snaps, name, np.concatenate([getattr(snaps, name)] * reps)[: args.timing_snapshots])
    snaps.targets = np.concatenate([snaps.targets] * reps)[: args.timing_snapshots]
    t0 = time.perf_counter()
    model.predict_snapshots(snaps)
    cost = time.perf_counter() - t0

    command = command_line("lfdem_snapshots", argv)
    noise = (
        f", plus Gaussian noise of {args.noise:g} a per coordinate (seed {args.seed}) declared to the model"
        if args.noise > 0.0
        else ""
    )
    scored = [
        [f"graph network ({args.model})", f"{net[0]:.4f}", f"{net[1]:.5f}", f"{net[2]:.5f}"],
        ["physics only: one-solve η_r, contact-spring Π, counted Z_μ", f"{solve[0]:.4f}", f"{solve[1]:.5f}"]
        + [f"{solve[2]:.5f}"],
    ]
    if lookup:
        scored.append(
            [
                "lookup: mean of the rheograph runs at each σ",
                *(f"{base[k]:.{d}f}" for k, d in enumerate((4, 5, 5))),
            ]
        )
    per_run_header = ["σ/σ0", "LF_DEM disp_max", "snapshots", "position noise declared [a]", "η_r LF_DEM"]
    per_run_header += ["η_r predicted", "Π LF_DEM", "Π predicted", "Z_μ LF_DEM", "Z_μ predicted", "in domain"]
    per_run_header += ["η_r lookup"] if lookup else []
    blocks = [
        f"### A shipped model on LF_DEM snapshots ({args.model}"
        + (f", ε = {args.noise:g} a)" if noise else ")"),
        "",
        f"{len(sim)} snapshots at strain ≥ {args.min_strain:g} of {len(rows)} LF_DEM runs, read from their "
        f"`par_*.dat` (positions to LF_DEM's 6 printed digits{noise}) with LF_DEM's own η_r = σ/γ̇, Π and Z_μ "
        "(contact states of `int_*.dat`) as the truth; all runs scored together.\n",
        table_block(["predictor", "R² log η_r", "R² log Π", "R² Z_μ"], scored),
        "",
        table_block(per_run_header, [row for _, row in sorted(per_run)]),
        "\n"
        f"Prediction cost: {args.timing_snapshots} N = {snaps.n_particles} snapshots in {cost:.1f} s on one "
        f"core (one call, graphs built and the one-solve included; {1e3 * cost / args.timing_snapshots:.1f} "
        f"ms per snapshot); the scored runs took {seconds:.0f} s including reading and warm-up.\n\n"
        f"Command: `{command}`",
    ]
    publish(args.section, blocks, not args.no_write, page=args.page, command=command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
