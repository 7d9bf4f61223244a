"""Physics-only rows beside a finished training run, on its own test folds, with nothing retrained: the
one-solve η_r (alone, and shifted by the per-(φ, σ) log offset of the fold's training snapshots), the
contact-spring pressure (2π σ / A) Σ r ā δ / δ_σ and the counted frictional contacts — against the graph
network's held-out R² from the run's metrics.json, and the share of the best physics-only row's residual
variance that the network removes, 1 − (1 − R²_net) / (1 − R²_physics).

    python -m bench.physics_rows docs/results/surrogate_per_phi/N400_phi0.76 [RUN ...]

Each fold's graphs are rebuilt from its split file (same files, same graph settings: the same order as
in training) and scored with the training code's metrics (rheograph.learn.module.fold_metrics).  Results
replace the marked section of docs/validation/surrogate_accuracy.md unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from bench.publishing import command_line, publish
from rheograph.learn.baselines import physics_fold_metrics  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ROWS = ("physics_solve", "physics_offset")
TARGETS = (("eta", "r2_log_eta"), ("pressure", "r2_log_pressure"), ("z_mu", "r2_z_mu"))


def run_table(run_dir: Path, cache_dir: Path) -> list[str]:
    metrics = json.loads((run_dir / "metrics.json").read_text())
    folds = [f["fold"] for f in metrics["folds"]]
    per_fold = [physics_fold_metrics(run_dir, k, cache_dir) for k in folds]
    net = {key: np.mean([f[f"test/{key}"] for f in metrics["folds"]]) for _, key in TARGETS}
    phys = {
        name: {key: float(np.nanmean([f[name][key] for f in per_fold])) for _, key in TARGETS}
        for name in ROWS
    }
    lines = [
        f"| {run_dir.parent.name}/{run_dir.name} | graph network | "
        + " | ".join(f"{net[key]:.5f}" for _, key in TARGETS)
        + " |"
    ]
    labels = {
        "physics_solve": "physics: one-solve η_r",
        "physics_offset": "physics: one-solve η_r + (φ, σ) offset",
    }
    for name in ROWS:
        lines.append(
            f"| | {labels[name]}, spring Π, counted Z_μ | "
            + " | ".join(f"{phys[name][key]:.5f}" for _, key in TARGETS)
            + " |"
        )
    best = {key: max(phys[name][key] for name in ROWS) for _, key in TARGETS}
    removed = [
        (1.0 - (1.0 - net[key]) / (1.0 - best[key])) if best[key] < 1.0 else float("nan")
        for _, key in TARGETS
    ]
    lines.append(
        "| | share of the best physics row's residual variance the network removes | "
        + " | ".join(f"{100 * r:.0f} %" for r in removed)
        + " |"
    )
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--cache-dir", default=str(ROOT / "data" / "cache"))
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    lines = [
        "### What the network adds beyond physics-only estimates",
        "",
        "Held-out test folds of each training run (mean over folds); the physics rows are computed from the "
        "same positions and the imposed stress, nothing learned but the per-(φ, σ) offset of the second "
        "row, fitted on the fold's training and validation snapshots.",
        "",
        "| run | predictor | R² log η_r | R² log Π | R² Z_μ |",
        "|---|---|---|---|---|",
    ]
    for run in args.runs:
        lines += run_table(Path(run), Path(args.cache_dir))
    command = command_line("physics_rows.py", argv)
    lines += ["", f"Command: `{command}`"]
    publish("physics_rows", "\n".join(lines), not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
