"""An imaging model's held-out scores by noise level, for the cost of reading files: a run trained on
noisy copies (graph.noise_copies) saved each fold's predictions on its test trajectories, one row per
noisy copy of every test snapshot, ε log-uniform over the trained range.  This script reads the ε of
each row from the run's cached graphs (the graph input position_noise) and scores every predictor the
run saved — the graph network, the lookup of the training mean at (φ, σ), the trees on descriptors and
the physics-only row — within bins of ε.  Nothing is relaxed or predicted again, so a model whose
snapshots cost a relaxation each (graph.relax_strain) gets its by-ε table without that cost; every
predictor in a bin is scored on the same rows.

    python -m bench.noise_bins docs/results/imaging/N2000_phi0.80_relaxed

The cache is the one training built (data/cache); where it is absent it is rebuilt first, at the cost
of that build.  Results replace the marked section (``--section``) of ``--page`` unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from bench.publishing import Section, command_line, publish, table

ROOT = Path(__file__).resolve().parents[1]
# saved prediction arrays and the names the result tables give them
PREDICTORS = (
    ("pred", "graph network"),
    ("baseline_stress_mean", "lookup: mean at (φ, σ)"),
    ("baseline_descriptors", "trees on descriptors + σ"),
    ("baseline_descriptors_solve", "trees on descriptors + σ + one-solve η_r"),
    ("baseline_physics_offset", "physics: one-solve η_r + offset, spring Π, counted Z_μ"),
)
METRICS = (
    ("r2_log_eta", "R² log η_r"),
    ("r2_log_pressure", "R² log Π"),
    ("r2_z_mu", "R² Z_μ"),
    ("fluct_eta", "fluct. η_r"),
    ("within15_eta", "±15 % η_r"),
)


def fold_rows(run_dir: Path, k: int, cache_dir: Path) -> dict:
    """Saved predictions of fold ``k`` and the position noise ε [a] of each row."""
    import torch

    from rheograph.graphs.dataset import SnapshotGraphDataset
    from rheograph.learn.bundle import load_bundle
    from rheograph.learn.datamodule import split_files
    from rheograph.learn.predict import short_relaxation

    split = json.loads((run_dir / f"fold{k}_split.json").read_text())
    _, settings, _ = load_bundle(run_dir / f"fold{k}.pt")
    if not settings.noise_copies or "position_noise" not in settings.graph_inputs:
        raise SystemExit(
            f"noise_bins: {run_dir} was not trained on noisy copies that state their noise "
            "(graph.noise_copies and the graph input position_noise): score it with bench/snapshot_noise.py"
        )
    dataset = SnapshotGraphDataset(split_files(split, ROOT), settings, cache_dir)
    test = torch.as_tensor(split["test"])
    column = list(settings.graph_inputs).index("position_noise")
    eps = dataset.u[test, column].double().numpy()
    saved = dict(np.load(run_dir / f"fold{k}_predictions.npz"))
    if saved["true"].shape[0] != eps.size or not np.allclose(
        saved["true"], dataset.y_raw[test].numpy(), rtol=1e-5, equal_nan=True
    ):
        raise SystemExit(
            f"noise_bins: {run_dir}/fold{k}_predictions.npz does not hold the test rows of the cached "
            "graphs (another cache, or files changed since training)"
        )
    flagged = short_relaxation([dataset[int(i)] for i in test], settings)
    return {"eps": eps, "flagged": flagged, **saved}


def bin_table(rows: dict, edges: np.ndarray, labels: list[str]) -> dict:
    """A table block: every saved predictor's metrics within each ε bin of ``rows``, on the rows
    the model does not flag (a relaxation short of its strain: an arrested packing)."""
    from rheograph.learn.module import fold_metrics
    from rheograph.naming import state_point_key

    where = np.digitize(rows["eps"], edges) - 1
    # the top edge belongs to the last bin (the trained eps_max, stored in float32, may round past it)
    where[np.isclose(rows["eps"], edges[-1], rtol=1e-6)] = len(labels) - 1
    flagged = [int(np.sum((where == b) & rows["flagged"])) for b in range(len(labels))]
    # a flagged row's prediction comes with its reason (predict.py): score only what a user is served silently
    where[rows["flagged"]] = -1
    groups = state_point_key(rows["phi"], rows["stress"])
    counts = [int(np.sum(where == b)) for b in range(len(labels))]
    header = ["predictor", "metric"]
    header += [
        f"ε {label} (n {n}" + (f", {f} flagged" if f else "") + ")"
        for label, n, f in zip(labels, counts, flagged)
    ]
    body = []
    for key, name in PREDICTORS:
        if key not in rows:
            continue
        scores = []
        for b in range(len(labels)):
            inside = where == b
            scores.append(
                fold_metrics(rows[key][inside], rows["true"][inside], groups[inside], rows["jammed"][inside])
                if inside.sum() > 2
                else None
            )
        for metric, label in METRICS:
            digits = 4 if metric.startswith("r2") else 3  # R² near 1: the fourth decimal decides
            body.append([name, label, *("–" if s is None else f"{s[metric]:.{digits}f}" for s in scores)])
    return table(header, body)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="training run directories (fold*.pt, fold*_predictions.npz)")
    ap.add_argument(
        "--bins",
        type=float,
        nargs="+",
        default=[1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 5e-2],
        help="edges of the ε bins [a], increasing",
    )
    ap.add_argument("--folds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument(
        "--skip-stress",
        type=float,
        nargs="+",
        default=[],
        help="leave out the rows at these σ/σ0 (e.g. a state point whose lookup is an arrested run's mean)",
    )
    ap.add_argument("--cache-dir", default=str(ROOT / "data" / "cache"))
    ap.add_argument("--page", default=None, help="docs page with the marked section (default: its record's)")
    ap.add_argument("--section", default="noise_bins")
    ap.add_argument("--title", default="Imaging models by noise level, from their own held-out predictions")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    edges = np.asarray(args.bins, dtype=np.float64)
    if edges.size < 2 or np.any(np.diff(edges) <= 0) or edges[0] <= 0:
        sys.exit(f"noise_bins: --bins {args.bins}: give at least two increasing positive edges")
    for run in args.runs:
        missing = [k for k in args.folds if not (Path(run) / f"fold{k}_predictions.npz").is_file()]
        if missing:
            sys.exit(f"noise_bins: {run} has no finished fold(s) {missing} (fold*_predictions.npz)")
    labels = [f"{lo:g}–{hi:g}" for lo, hi in zip(edges[:-1], edges[1:])]
    out = Section(
        f"### {args.title}",
        "",
        "Each fold's model on the noisy copies of its own test trajectories, as training scored them (ε "
        "log-uniform over the trained range, one row per copy, positions relaxed as the model reads "
        "them), split by the ε of each copy (bins in units of a; n: rows in the bin).  Every predictor is "
        "scored on the same rows; fluct.: correlation of predicted and true deviations from the "
        "state-point mean; ±15 %: share of η_r within ±15 %.  Rows whose relaxation stopped short of its "
        "strain (an arrested or creeping packing) are predicted with that reason as out of the model's "
        "domain; they are counted (flagged) and not scored.",
        "",
    )
    for run in args.runs:
        run_dir = Path(run)
        folds = [fold_rows(run_dir, k, Path(args.cache_dir)) for k in args.folds]
        rows = {key: np.concatenate([f[key] for f in folds]) for key in folds[0] if np.ndim(folds[0][key])}
        kept = ~np.isin(np.round(rows["stress"], 9), np.round(args.skip_stress, 9))
        if not kept.any():
            sys.exit(f"noise_bins: --skip-stress {args.skip_stress} leaves no rows of {run}")
        rows = {key: value[kept] for key, value in rows.items()}
        phis = np.unique(np.round(rows["phi"], 6))
        # a model pooled over area fractions: one table per phi (pooled R² would mostly score phi)
        for phi in phis:
            at = np.isclose(rows["phi"], phi)
            title = f"**{run_dir.name}**" + (f", φ = {phi:g}" if len(phis) > 1 else "")
            if args.skip_stress:
                title += f" (without σ/σ0 = {', '.join(f'{x:g}' for x in args.skip_stress)})"
            out.add(title, "")
            out.table(**bin_table({k: v[at] for k, v in rows.items()}, edges, labels)["table"])
            out.add("")
    command = command_line("noise_bins", argv)
    out.add(f"Command: `{command}`")
    publish(args.section, out, not args.no_write, page=args.page, command=command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
