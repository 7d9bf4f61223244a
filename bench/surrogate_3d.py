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

``--pooled FOLDER`` draws the model trained over every φ of the set instead (a folder named
``pooled_N<N>``, from ``python train.py experiment=pooled_grouped data.files=data/flow_curves_3d/index.json
data.n_particles=<N> fold_workers=1 output_root=outputs/pooled_3d``): its held-out scores per φ, computed
from the folds' test predictions (``rheograph.learn.report.per_subset_scores``), beside the same
baselines on the same snapshots, into the section ``surrogate_3d_pooled``.
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
from rheograph.learn.report import per_subset_scores
from rheograph.learn.train import read_fold_predictions

ROOT = Path(__file__).resolve().parents[1]

# (metric key, column) of the three targets, and (key prefix of the folds' metrics, row name)
METRICS = (("r2_log_eta", "R² log η_r"), ("r2_log_pressure", "R² log Π"), ("r2_z_mu", "R² Z_μ"))
PREDICTORS = (
    ("test", "graph network"),
    ("baseline/physics_offset", "physics only: one-solve η_r + (φ, σ) offset, spring Π, counted Z_μ"),
    ("baseline/descriptors", "descriptor trees + σ"),
    ("baseline/stress_mean", "lookup: training mean at (φ, σ)"),
)
RUN_NAME = re.compile(r"^N(\d+)_phi(\d+(?:\.\d+)?)$")
POOLED_NAME = re.compile(r"^pooled_N(\d+)$")


def finished_run(folder: Path, name: re.Pattern, example: str) -> tuple[re.Match, list[dict]]:
    """The match of a result folder's name against ``name`` and its folds' metrics, or one line that says
    why the folder is not a finished training run's named as it must be (e.g. ``example``)."""
    match = name.match(folder.name)
    if match is None:
        sys.exit(f"surrogate_3d: {folder}: the folder must be named {example}")
    metrics = folder / "metrics.json"
    if not metrics.is_file():
        sys.exit(f"surrogate_3d: {folder} has no metrics.json: not a finished training run's result folder")
    return match, json.loads(metrics.read_text())["folds"]


def read_run(folder: Path) -> dict:
    """N, φ, the folds' metrics and the counts of test trajectories and snapshots of one result folder."""
    match, folds = finished_run(folder, RUN_NAME, "N<N>_phi<φ> (e.g. N500_phi0.56)")
    snapshots = 0
    for fold in folds:
        with np.load(folder / f"fold{fold['fold']}_predictions.npz") as predictions:
            snapshots += predictions["true"].shape[0]
    n, phi = int(match.group(1)), float(match.group(2))
    # the trajectories it was trained on: every run of the set at (N, phi) unless the split says otherwise
    split = json.loads((folder / f"fold{folds[0]['fold']}_split.json").read_text())
    pattern = f"data/flow_curves_3d/multirun/N{n}_phi{phi:g}_*/trajectory.h5"
    every_run = sorted(str(p.relative_to(ROOT)) for p in ROOT.glob(pattern))
    trained = sorted(split["files"])
    files = f"'data.files={pattern}'" if trained == every_run else files_override(trained)
    return {
        "n": n,
        "phi": phi,
        "files": files,
        "folds": folds,
        "trajectories": int(sum(fold["test/n_runs"] for fold in folds)),
        "snapshots": snapshots,
    }


def files_override(files: list[str]) -> str:
    """``data.files`` as an explicit list of run folders: a model trained on part of the runs at its φ."""
    runs = ",".join(f'"{Path(f).parent.as_posix()}/trajectory.h5"' for f in sorted(files))
    return f"'data.files=[{runs}]'"


def cell(folds: list[dict], key: str) -> str:
    """Mean ± standard deviation (ddof 1) of ``key`` over the folds."""
    mean, std = stats(folds, key)
    digits = 3 if "eta" in key else 4
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def section(runs: list[dict], command: str) -> Section:
    out = Section(
        "The shipped 3D models, one per volume fraction: N = 500 spheres, the runs of the 3D flow-curve "
        "set at that φ (eight stresses σ/σ0 = 0.5–200, every seed there: the run counts below; strain 3, "
        "`campaign=flow_curves_3d`, committed in "
        "`data/flow_curves_3d/`), the demo model and inputs (`graph=physics_solve`: one resistance solve "
        "of the 3D simulator on the snapshot, the contact-spring pressure, the counted frictional "
        "contacts), five folds holding out whole trajectories (mean ± standard deviation over the folds).  "
        "Each model was trained (6–9 minutes on one core) and shipped by",
        "",
    )
    for run in runs:
        n, phi = run["n"], run["phi"]
        out.add(
            f"    python train.py experiment=demo data.phi={phi:g} data.n_particles={n} fold_workers=1 \\",
            "        output_root=outputs/surrogate_3d \\",
            f"        {run['files']}",
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


def read_pooled(folder: Path) -> dict:
    """N, the folds' metrics and, per φ, each predictor's fold scores of a pooled run's result folder."""
    match, folds = finished_run(folder, POOLED_NAME, "pooled_N<N> (e.g. pooled_N500)")
    predictions = [read_fold_predictions(folder, fold["fold"]) for fold in folds]
    n = int(match.group(1))
    per_phi: dict[float, dict] = {}
    for prefix, _ in PREDICTORS:
        model = None if prefix == "test" else prefix.split("/", 1)[1]
        for (phi, size), scores in per_subset_scores(predictions, model).items():
            if size != n:
                sys.exit(f"surrogate_3d: --pooled {folder} holds test snapshots of N = {size}, not {n}")
            per_phi.setdefault(phi, {})[prefix] = {key: scores[key].tolist() for key, _ in METRICS}
    for phi, entry in per_phi.items():
        held = [p["run_id"][np.round(p["phi"], 6) == phi] for p in predictions]
        entry["trajectories"] = int(sum(np.unique(ids).size for ids in held))
        entry["snapshots"] = int(sum(ids.size for ids in held))
    return {"n": n, "folds": folds, "per_phi": dict(sorted(per_phi.items()))}


def pooled_cell(values: list[float], key: str) -> str:
    """Mean ± standard deviation over the folds that hold test snapshots of the φ (one fold: no spread)."""
    finite = np.asarray(values, dtype=np.float64)
    finite = finite[np.isfinite(finite)]
    digits = 3 if "eta" in key else 4
    if finite.size == 1:
        return f"{finite[0]:.{digits}f} (one fold)"
    return f"{finite.mean():.{digits}f} ± {finite.std(ddof=1):.{digits}f}"


def pooled_section(pooled: dict, command: str) -> Section:
    n = pooled["n"]
    out = Section(
        f"One model over every volume fraction of the 3D set (N = {n}; φ and log σ as graph-level inputs "
        "besides the physics inputs; `experiment=pooled_grouped`: 40 epochs, five folds holding out whole "
        "trajectories of every state point), trained (23 minutes on one core) and shipped by",
        "",
        "    python train.py experiment=pooled_grouped data.files=data/flow_curves_3d/index.json \\",
        f"        data.n_particles={n} fold_workers=1 output_root=outputs/pooled_3d",
        f"    python -m rheograph.learn.registry ship RUN --name pooled_N{n}_3d",
        "",
        "Its held-out scores per φ (each fold's test snapshots at that φ; mean ± standard deviation over the "
        "folds that hold some), the baselines on the same snapshots, and over all test snapshots:",
        "",
    )
    rows = []
    for phi, entry in pooled["per_phi"].items():
        runs = "1 run" if entry["trajectories"] == 1 else f"{entry['trajectories']} runs"
        label = f"{phi:.2f} ({runs}, {entry['snapshots']} test snapshots)"
        for prefix, name in PREDICTORS:
            rows.append([label, name] + [pooled_cell(entry[prefix][key], key) for key, _ in METRICS])
    for prefix, name in PREDICTORS:
        rows.append(["all", name] + [cell(pooled["folds"], f"{prefix}/{key}") for key, _ in METRICS])
    out.table(["φ (model pooled_N<N>_3d)", "predictor"] + [label for _, label in METRICS], rows)
    out.add("", f"Command: `{command}`")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="*", type=Path, help="result folders N<N>_phi<φ> of finished runs")
    ap.add_argument("--pooled", type=Path, help="the result folder pooled_N<N> of a pooled run instead")
    ap.add_argument("--section", help="default surrogate_3d (surrogate_3d_pooled with --pooled)")
    ap.add_argument("--page", default="validation/surrogate_3d.md")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    command = command_line("surrogate_3d", argv)
    if args.pooled is not None:
        if args.runs:
            sys.exit("surrogate_3d: give either per-φ result folders or --pooled, not both")
        pooled = read_pooled(args.pooled)
        publish(
            args.section or "surrogate_3d_pooled",
            pooled_section(pooled, command),
            not args.no_write,
            page=args.page,
            record={"n": pooled["n"], "per_phi": {f"{phi:g}": e for phi, e in pooled["per_phi"].items()}},
            command=command,
        )
        return 0
    if not args.runs:
        sys.exit("surrogate_3d: no result folders (N<N>_phi<φ> ..., or --pooled pooled_N<N>)")
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
    publish(
        args.section or "surrogate_3d",
        section(runs, command),
        not args.no_write,
        page=args.page,
        record=record,
        command=command,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
