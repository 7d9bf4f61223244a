"""Physics-only rows beside a finished training run, on its own test folds, with nothing retrained: the
one-solve η_r (alone, and shifted by the per-(φ, σ) log offset of the fold's training snapshots), the
contact-spring pressure (2π σ / A) Σ r ā δ / δ_σ and the counted frictional contacts — against the graph
network's held-out R² from the run's metrics.json, and the share of the best physics-only row's residual
variance that the network removes, 1 − (1 − R²_net) / (1 − R²_physics).

    python -m bench.physics_rows docs/results/surrogate_per_phi/N400_phi0.76 [RUN ...]

Each fold's graphs are rebuilt from its split file (same files, same graph settings: the same order as
in training) and scored with the training code's metrics (rheograph.learn.module.fold_metrics).  The table
is kept as the record docs/results/bench/physics_rows.json (unless ``--no-write``), from which
``python -m bench.render`` draws its section of docs/validation/surrogate_accuracy.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from bench.publishing import Section, command_line, publish
from rheograph.learn.baselines import physics_fold_metrics  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ROWS = ("physics_solve", "physics_offset")
TARGETS = (("eta", "r2_log_eta"), ("pressure", "r2_log_pressure"), ("z_mu", "r2_z_mu"))


LABELS = {
    "physics_solve": "physics: one-solve η_r, spring Π, counted Z_μ",
    "physics_offset": "physics: one-solve η_r + (φ, σ) offset, spring Π, counted Z_μ",
}
HEADER = ("run", "predictor", "R² log η_r", "R² log Π", "R² Z_μ")
LEAD = (
    "### What the network adds beyond physics-only estimates",
    "",
    "Held-out test folds of each training run (mean over folds); the physics rows are computed from the "
    "same positions and the imposed stress, nothing learned but the per-(φ, σ) offset of the second "
    "row, fitted on the fold's training and validation snapshots.",
    "",
)


def network_scores(run_dir: Path) -> dict:
    """The graph network's held-out R² per target of a finished run: the mean over its test folds."""
    folds = json.loads((run_dir / "metrics.json").read_text())["folds"]
    return {key: float(np.mean([f[f"test/{key}"] for f in folds])) for _, key in TARGETS}


def physics_scores(run_dir: Path, cache_dir: Path) -> dict:
    """Each physics-only row's R² per target on the run's test folds (mean over folds)."""
    folds = [f["fold"] for f in json.loads((run_dir / "metrics.json").read_text())["folds"]]
    per_fold = [physics_fold_metrics(run_dir, k, cache_dir) for k in folds]
    return {
        name: {key: float(np.nanmean([f[name][key] for f in per_fold])) for _, key in TARGETS}
        for name in ROWS
    }


def run_rows(run: str, net: dict, phys: dict) -> list[list[str]]:
    """The published cells of one run (named ``run``): the network, the physics rows, and the share of the
    best physics row's residual variance the network removes."""
    rows = [[run, "graph network"] + [f"{net[key]:.5f}" for _, key in TARGETS]]
    rows += [["", LABELS[name]] + [f"{phys[name][key]:.5f}" for _, key in TARGETS] for name in ROWS]
    best = {key: max(phys[name][key] for name in ROWS) for _, key in TARGETS}
    removed = [
        (1.0 - (1.0 - net[key]) / (1.0 - best[key])) if best[key] < 1.0 else float("nan")
        for _, key in TARGETS
    ]
    share = "share of the best physics row's residual variance the network removes"
    return rows + [["", share] + [f"{100 * r:.0f} %" for r in removed]]


def section(rows: list[list[str]], command: str) -> Section:
    """The published section: what the rows are, the table of every run and the command."""
    out = Section(*LEAD)
    out.table(HEADER, rows)
    out.add("", f"Command: `{command}`")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--cache-dir", default=str(ROOT / "data" / "cache"))
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    rows = []
    for run in map(Path, args.runs):
        name = f"{run.parent.name}/{run.name}"
        rows += run_rows(name, network_scores(run), physics_scores(run, Path(args.cache_dir)))
    command = command_line("physics_rows.py", argv)
    publish("physics_rows", section(rows, command), not args.no_write, command=command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
