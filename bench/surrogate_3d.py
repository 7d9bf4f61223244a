"""The shipped 3D surrogates' held-out accuracy, one row block per volume fraction: the graph network
against the physics-only row, the descriptor trees and the lookup of the training mean at (φ, σ), each
mean ± standard deviation over the five test folds (whole trajectories held out).

    python -m bench.surrogate_3d docs/results/surrogate_3d/N500_phi0.5 docs/results/surrogate_3d/N500_phi0.56

Each argument is the light result folder of one finished training run (its ``metrics.json`` and
``fold*_predictions.npz``), named ``N<N>_phi<φ>`` as its model is; the runs themselves are made with

    python train.py experiment=demo data.phi=<φ> data.n_particles=<N> fold_workers=1 \\
        output_root=outputs/surrogate_3d 'data.files=data/flow_curves_3d/multirun/N<N>_phi<φ>_*/trajectory.h5'

(the light files copied from the run directory; ``python -m rheograph.learn.registry ship RUN --name
N<N>_phi<φ>_3d`` ships its fold models).  Nothing is retrained here: the table is redrawn from the
folds' own metrics.  It replaces the marked section ``surrogate_3d`` of docs/validation/surrogate_3d.md
unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

from bench.publishing import Section, command_line, publish
from bench.surrogate_per_phi import stats

# (metric key, column) of the three targets, and (key prefix of the folds' metrics, row name)
METRICS = (("r2_log_eta", "R² log η_r"), ("r2_log_pressure", "R² log Π"), ("r2_z_mu", "R² Z_μ"))
PREDICTORS = (
    ("test", "graph network"),
    ("baseline/physics_offset", "physics only: one-solve η_r + (φ, σ) offset, spring Π, counted Z_μ"),
    ("baseline/descriptors", "descriptor trees + σ"),
    ("baseline/stress_mean", "lookup: training mean at (φ, σ)"),
)
RUN_NAME = re.compile(r"^N(\d+)_phi(\d+(?:\.\d+)?)$")


def read_run(folder: Path) -> dict:
    """N, φ, the folds' metrics and the counts of test trajectories and snapshots of one result folder."""
    match = RUN_NAME.match(folder.name)
    if match is None:
        sys.exit(f"surrogate_3d: {folder}: the folder must be named N<N>_phi<φ> (e.g. N500_phi0.56)")
    metrics = folder / "metrics.json"
    if not metrics.is_file():
        sys.exit(f"surrogate_3d: {folder} has no metrics.json: not a finished training run's result folder")
    folds = json.loads(metrics.read_text())["folds"]
    snapshots = 0
    for fold in folds:
        with np.load(folder / f"fold{fold['fold']}_predictions.npz") as predictions:
            snapshots += predictions["true"].shape[0]
    return {
        "n": int(match.group(1)),
        "phi": float(match.group(2)),
        "folds": folds,
        "trajectories": int(sum(fold["test/n_runs"] for fold in folds)),
        "snapshots": snapshots,
    }


def cell(folds: list[dict], key: str) -> str:
    """Mean ± standard deviation (ddof 1) of ``key`` over the folds."""
    mean, std = stats(folds, key)
    digits = 3 if "eta" in key else 4
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def section(runs: list[dict], command: str) -> Section:
    out = Section(
        "The shipped 3D models, one per volume fraction: N = 500 spheres, the runs of the 3D flow-curve "
        "set at that φ (σ/σ0 = 0.5–200, two seeds each, strain 3, `campaign=flow_curves_3d`, committed in "
        "`data/flow_curves_3d/`), the demo model and inputs (`graph=physics_solve`: one resistance solve "
        "of the 3D simulator on the snapshot, the contact-spring pressure, the counted frictional "
        "contacts), five folds holding out whole trajectories (mean ± standard deviation over the folds).  "
        "Each model was trained (about 6 minutes on one core) and shipped by",
        "",
    )
    for run in runs:
        n, phi = run["n"], run["phi"]
        out.add(
            f"    python train.py experiment=demo data.phi={phi:g} data.n_particles={n} fold_workers=1 \\",
            "        output_root=outputs/surrogate_3d \\",
            f"        'data.files=data/flow_curves_3d/multirun/N{n}_phi{phi:g}_*/trajectory.h5'",
            f"    python -m rheograph.learn.registry ship RUN --name N{n}_phi{phi:.2f}_3d",
            "",
        )
    rows = []
    for run in runs:
        label = f"{run['phi']:.2f} ({run['trajectories']} runs, {run['snapshots']} test snapshots)"
        for prefix, name in PREDICTORS:
            rows.append([label, name] + [cell(run["folds"], f"{prefix}/{key}") for key, _ in METRICS])
    out.table(["φ (model N500_phi<φ>_3d)", "predictor"] + [label for _, label in METRICS], rows)
    out.add("", f"Command: `{command}`")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path, help="result folders N<N>_phi<φ> of finished runs")
    ap.add_argument("--section", default="surrogate_3d")
    ap.add_argument("--page", default="validation/surrogate_3d.md")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    runs = sorted((read_run(folder) for folder in args.runs), key=lambda run: (run["n"], run["phi"]))
    record = {
        "runs": [
            {
                "n": run["n"],
                "phi": run["phi"],
                "trajectories": run["trajectories"],
                "snapshots": run["snapshots"],
                "mean": {
                    f"{prefix}/{key}": float(np.mean([fold[f"{prefix}/{key}"] for fold in run["folds"]]))
                    for prefix, _ in PREDICTORS
                    for key, _ in METRICS
                },
            }
            for run in runs
        ]
    }
    command = command_line("surrogate_3d", argv)
    publish(
        args.section,
        section(runs, command),
        not args.no_write,
        page=args.page,
        record=record,
        command=command,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
