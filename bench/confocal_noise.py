"""How a 3D surrogate reads confocal-grade snapshots: Gaussian noise of ε per coordinate across the
microscope's optical axis and ε_z along it (units of the small radius a; the axis is the model's
``graph.optical_axis``) on the held-out test trajectories of a finished 3D training run, each fold's model
on its own test trajectories, against the lookup of the training mean at (φ, σ) (which reads no
positions) and gradient-boosted trees on the descriptors of the noisy positions.  Per noise pair and
predictor: R² of log η_r, log Π and Z_μ pooled over the folds' test snapshots.

    python -m bench.confocal_noise outputs/confocal_3d/RUN --noise 0 0.01 0.03 0.05 --axial-noise 0 0.1 0.3

One noise draw per (pair, snapshot), seeded (``--seed``).  The table replaces the marked section
``--section`` of its page (docs/validation/surrogate_3d.md) unless ``--no-write``.  A model over several
volume fractions is scored per volume fraction (``--phi 0.5 0.56``: the test snapshots at each, one
section ``<section>_phi<φ>`` each), as R² pooled over volume fractions would count the spread between
them as skill.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

from bench.publishing import Section, command_line, publish
from bench.snapshot_noise import ROOT, fold_rows

METRICS = (("r2_log_eta", "R² log η_r"), ("r2_log_pressure", "R² log Π"), ("r2_z_mu", "R² Z_μ"))
PREDICTORS = ("graph network", "lookup: mean at (φ, σ)", "trees on descriptors + σ")


def pooled_scores(results: list[dict], levels, phi: float | None = None) -> dict:
    """{(predictor, level): {metric: value}} over the folds' rows ``results`` (``fold_rows`` each), of the
    snapshots at volume fraction ``phi`` only where given."""
    from rheograph.learn.module import fold_metrics

    scores = {}
    for name, level in itertools.product(PREDICTORS, levels):
        parts = [rows[(name, level)] for rows in results]
        pred, true, groups, jammed, stress = (np.concatenate([p[i] for p in parts]) for i in range(5))
        if phi is not None:
            # state_point_key = round(phi, 6) * 1e6 + round(sigma, 6)
            at = np.isclose((groups - np.round(stress, 6)) / 1e6, round(phi, 6), atol=1e-9)
            if not at.any():
                raise SystemExit(f"confocal_noise: --phi {phi:g}: no test snapshot at that volume fraction")
            pred, true, groups, jammed = pred[at], true[at], groups[at], jammed[at]
        scores[(name, level)] = fold_metrics(pred, true, groups, jammed)
    return scores


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", help="a 3D training run directory (fold*.pt, fold*_split.json)")
    ap.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.01, 0.03, 0.05], help="ε [a]")
    ap.add_argument("--axial-noise", type=float, nargs="+", default=[0.0, 0.1, 0.3], help="ε_z [a]")
    ap.add_argument("--folds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache-dir", default=str(ROOT / "data" / "cache"))
    ap.add_argument("--phi", type=float, nargs="+", help="score the test snapshots of each φ apart")
    ap.add_argument("--section", default="confocal_noise")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    run_dir = Path(args.run)
    if not all((run_dir / f"fold{k}.pt").is_file() for k in args.folds):
        sys.exit(f"confocal_noise: {run_dir} lacks a fold model of folds {args.folds} (fold*.pt)")
    levels = list(itertools.product(args.noise, args.axial_noise))
    results = [fold_rows(run_dir, k, levels, args.seed, Path(args.cache_dir)) for k in args.folds]
    command = command_line("confocal_noise", argv)
    for phi in args.phi or [None]:
        scores = pooled_scores(results, levels, phi)
        section = args.section if phi is None else f"{args.section}_phi{phi:g}"
        publish_scores(scores, levels, run_dir, args, command, section, phi)
    return 0


def publish_scores(scores, levels, run_dir: Path, args, command: str, section: str, phi) -> None:
    at = "" if phi is None else f" at φ = {phi:g}"
    out = Section(
        f"Held-out test trajectories{at} of `{run_dir.name}` ({len(args.folds)} folds), Gaussian noise of ε "
        "per coordinate across the optical axis and ε_z along it (units of a) on their positions, each "
        "fold's model on its own test trajectories; R² pooled over the folds' test snapshots "
        "(log10 for η_r and Π).",
        "",
    )
    rows = []
    for (eps, eps_axial), name in itertools.product(levels, PREDICTORS):
        values = scores[(name, (eps, eps_axial))]
        rows.append([f"{eps:g}", f"{eps_axial:g}", name, *(f"{values[key]:.3f}" for key, _ in METRICS)])
    out.table(["ε", "ε_z", "predictor", *(label for _, label in METRICS)], rows)
    out.add("", f"Command: `{command}`")
    record = {
        "noise": [list(level) for level in levels],
        "scores": {
            name: {
                label: [round(float(scores[(name, level)][key]), 4) for level in levels]
                for key, label in METRICS
            }
            for name in PREDICTORS
        },
    }
    publish(
        section, out, not args.no_write, page="validation/surrogate_3d.md", record=record, command=command
    )


if __name__ == "__main__":
    sys.exit(main())
