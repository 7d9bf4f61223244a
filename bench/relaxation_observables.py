"""What a relaxation measures: η_r, Π and Z_μ along a short shear of a (noisy) snapshot under the
simulator's own dynamics, against the snapshot's recorded values — no learning.

Every ``--every``-th snapshot (strain >= 1, flowing) of the given trajectories gets Gaussian noise of ε per
coordinate and is sheared at its imposed stress up to ``--max-strain``
(``rheograph.graphs.features.relax_positions`` does the same up to ``graph.relax_strain``); each step is
a resistance solve with the tangential springs the relaxation has loaded so far.  The table gives, per
ε and strain Δγ into the relaxation, R² of the step's log10 η_r, log10 Π and Z_μ against the recorded
ones — as measured, and after removing one mean offset over all rows (what a model that learns a
correction to the value starts from) — next to the one-solve of the positions reached at ``--solve-at``
(springs unstretched, the ``solve_viscosity`` input) and the lookup of the mean at (φ, σ) over the other
trajectories given at that state point (seeds not sampled).

    python -m bench.relaxation_observables 'data/paper/multirun/N400_phi0.76_*_seed[12]_*/trajectory.h5' \\
        --lookup 'data/paper/multirun/N400_phi0.76_*_seed3_*/trajectory.h5'

Results replace the marked section (``--section``) of docs/validation/position_noise.md unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import glob
import sys
import zlib
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from bench.publishing import command_line, publish


def relaxation_path(path: str, every: int, noises, max_strain: float, solve_at: float, seed: int) -> list:
    """Rows (stress, eps, recorded (eta, Pi, Z_mu), strains (S,), eta (S,), Pi (S,), Z_mu (S,), one-solve
    eta at ``solve_at``) for every ``every``-th flowing snapshot of ``path`` at strain >= 1."""
    from rheograph.graphs.features import solve_viscosity
    from rheograph.io.configurations import noisy_positions
    from rheograph.io.snapshots import read_snapshots
    from rheograph.sim.integrator import SimState, Simulation, particle_pressure
    from rheograph.sim.params import SimParams

    snaps = read_snapshots(path)
    params = {**snaps.graph_params(), **snaps.numerics}
    sim_params = SimParams.from_mapping({**params, "integrator": "implicit"})
    rng = np.random.default_rng([seed, zlib.crc32(Path(path).parent.name.encode())])
    rows = []
    for k in np.flatnonzero((snaps.strain >= 1.0) & ~snaps.jammed)[::every]:
        for eps in noises:
            noisy = noisy_positions(snaps, k, eps, rng)
            sim = Simulation(
                sim_params,
                SimState(
                    positions=noisy,
                    radii=snaps.radii.copy(),
                    lx=snaps.lx,
                    ly=snaps.ly,
                    le_offset=snaps.le_offset[k],
                ),
            )
            strain, eta, pressure, z_mu, solved = [], [], [], [], np.nan
            while sim.state.strain < max_strain and len(strain) < 4000:
                if np.isnan(solved) and sim.state.strain >= solve_at:
                    solved = solve_viscosity(
                        sim.state.positions, snaps.radii, snaps.lx, snaps.ly, sim.state.le_offset, params
                    )
                result = sim.step(record=True)
                strain.append(sim.state.strain)
                eta.append(sim_params.stress / result.shear_rate)
                pressure.append(particle_pressure(result))
                z_mu.append(2.0 * result.n_frictional / snaps.n_particles)
            rows.append(
                (snaps.stress, eps, snaps.targets[k], *map(np.array, (strain, eta, pressure, z_mu)), solved)
            )
    return rows


def state_means(paths) -> dict:
    """{stress: (mean log10 eta, mean log10 Pi, mean Z_mu)} over the flowing snapshots at strain >= 1."""
    from rheograph.io.snapshots import read_snapshots

    pooled = {}
    for path in paths:
        snaps = read_snapshots(path)
        keep = (snaps.strain >= 1.0) & ~snaps.jammed
        t = snaps.targets[keep]
        pooled.setdefault(snaps.stress, []).append(
            np.stack([np.log10(t[:, 0]), np.log10(t[:, 1]), t[:, 2]], 1)
        )
    return {s: np.concatenate(v).mean(axis=0) for s, v in pooled.items()}


def r2(pred, true) -> float:
    return float(1.0 - np.sum((pred - true) ** 2) / np.sum((true - true.mean()) ** 2))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("trajectories", help="glob of the trajectories to relax snapshots of")
    ap.add_argument("--lookup", required=True, help="glob of other trajectories at the same state points")
    ap.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.001, 0.003, 0.01])
    ap.add_argument("--strains", type=float, nargs="+", default=[0.0025, 0.005, 0.01, 0.02, 0.04])
    ap.add_argument("--every", type=int, default=4, help="every n-th snapshot at strain >= 1")
    ap.add_argument("--solve-at", type=float, default=0.01, help="strain of the one-solve comparison")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--section", default="relaxation_observables")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    if not 0.0 <= args.solve_at < max(args.strains):
        raise SystemExit(
            f"--solve-at {args.solve_at:g} must lie in [0, the largest --strains {max(args.strains):g})"
        )
    paths = sorted(glob.glob(args.trajectories))
    if not paths:
        raise SystemExit(f"no trajectory matches {args.trajectories}")
    means = state_means(sorted(glob.glob(args.lookup)))
    job = (args.every, args.noise, max(args.strains), args.solve_at, args.seed)
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        rows = [
            row for part in pool.map(relaxation_path, paths, *([v] * len(paths) for v in job)) for row in part
        ]
    strains_head = " | ".join(f"Δγ {g:g}" for g in args.strains)
    lines = [
        "### What the relaxation measures",
        "",
        f"{len(paths)} trajectories, every {args.every}th flowing snapshot at strain ≥ 1, noise ε per "
        f"coordinate (units of a), each sheared at its imposed stress to {max(args.strains):g}.  R² "
        "against the recorded value of the snapshot: of the relaxation step's value at Δγ (log10 for "
        "η_r and Π; 'offset': after removing one mean offset over all rows of that ε), of the one-solve "
        f"of the positions reached at Δγ {args.solve_at:g} (springs unstretched), and of the other "
        "trajectories' mean at (φ, σ) (lookup).",
        "",
        f"| ε [a] | rows | observable | lookup | one-solve at {args.solve_at:g} | {strains_head} |",
        "|---|---|---|---|---|" + "---|" * len(args.strains),
    ]
    for eps in args.noise:
        mine = [r for r in rows if r[1] == eps]
        if not all(r[0] in means for r in mine):
            raise SystemExit(f"--lookup has no trajectory at some stress of {args.trajectories}")
        for col, label, log in (
            (0, "η_r", True),
            (0, "η_r (offset)", True),
            (1, "Π", True),
            (2, "Z_μ", False),
        ):
            true = np.array([r[2][col] for r in mine])
            true = np.log10(true) if log else true
            lookup = np.array([means[r[0]][col] for r in mine])
            cells = [f"{r2(lookup, true):.3f}"]
            if col == 0:
                solved = np.log10(np.array([r[7] for r in mine]))
                shift = np.mean(true - solved) if "offset" in label else 0.0
                cells.append(f"{r2(solved + shift, true):.3f}")
            else:
                cells.append("–")
            for g in args.strains:
                at = np.array([r[4 + col][min(np.searchsorted(r[3], g), r[3].size - 1)] for r in mine])
                with np.errstate(invalid="ignore", divide="ignore"):
                    pred = np.log10(at) if log else at
                ok = np.isfinite(pred)
                shift = np.mean(true[ok] - pred[ok]) if "offset" in label else 0.0
                cells.append(
                    f"{r2(pred[ok] + shift, true[ok]):.3f}" + ("" if ok.all() else f" ({(~ok).sum()} ∞)")
                )
            lines.append(f"| {eps:g} | {len(mine)} | {label} | " + " | ".join(cells) + " |")
    lines += ["", f"Command: `{command_line('relaxation_observables.py', argv)}`"]
    publish(args.section, "\n".join(lines), not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
