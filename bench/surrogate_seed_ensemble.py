"""Seed ensembles on held-out trajectories: train the same configuration with several initialisation
seeds on the same folds, and score each fold's test trajectories with one model and with the mean of
the M models (log η_r and log Π averaged in log space, Z_μ linearly).  The deployed surrogate
(``predict.py``) already averages the K fold models; this measures what averaging buys on trajectories
no member has seen, which a single model's held-out score does not show.

    OMP_WAIT_POLICY=PASSIVE python -m bench.surrogate_seed_ensemble --phi 0.70 --seeds 0 1 2

Each seed's run is kept under docs/results/seed_ensemble/N<N>_phi<φ>_seed<s>/ (finished folds are
reused); the table replaces the ``seed_ensemble`` section of docs/validation/surrogate_accuracy.md.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402

from bench.publishing import Section, publish
from bench.training import benchmark_config, train_or_resume  # noqa: E402
from rheograph.learn.module import fold_metrics  # noqa: E402
from rheograph.naming import state_point_key  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCORES = (("r2_log_eta", "R² log η_r"), ("r2_log_pressure", "R² log Π"), ("r2_z_mu", "R² Z_μ"))


def model_label(overrides: list[str]) -> str:
    """The graph and model config groups the runs used (the training defaults with ``overrides``), and
    the overrides themselves, for the table's caption."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        choices = compose(config_name="train", overrides=overrides, return_hydra_config=True).hydra.runtime
    label = f"graph={choices.choices.graph}, model={choices.choices.model}"
    return label + (", " + " ".join(overrides) if overrides else "")


def ensemble_mean(preds: list[np.ndarray]) -> np.ndarray:
    """Mean of M predictions (G, 3) in physical units: geometric for η_r and Π (the scores are on log
    scale and both are positive), arithmetic for Z_μ."""
    stack = np.stack(preds)
    out = stack.mean(axis=0)
    for col in (0, 1):
        positive = (stack[:, :, col] > 0).all(axis=0)
        out[positive, col] = np.exp(np.log(stack[:, positive, col]).mean(axis=0))
    return out


def fold_scores(run_dirs: list[Path], k: int) -> tuple[list[dict], dict]:
    """Per-member and ensemble ``fold_metrics`` of fold k (the members must share its test graphs)."""
    loaded = [np.load(d / f"fold{k}_predictions.npz") for d in run_dirs]
    first = loaded[0]
    for other in loaded[1:]:
        if not (
            np.array_equal(other["true"], first["true"]) and np.array_equal(other["run_id"], first["run_id"])
        ):
            raise SystemExit(f"fold {k}: the runs were tested on different graphs (not the same folds)")
    groups = state_point_key(first["phi"], first["stress"])
    members = [fold_metrics(p["pred"], p["true"], groups, p["jammed"]) for p in loaded]
    mean = fold_metrics(ensemble_mean([p["pred"] for p in loaded]), first["true"], groups, first["jammed"])
    return members, mean


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--phi", type=float, default=0.70)
    ap.add_argument("--n", type=int, default=400)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--epochs", type=int, default=60)
    ap.add_argument("--split", default="grouped", choices=["grouped", "random"])
    ap.add_argument("--index", default="data/paper/index.json")
    ap.add_argument("--out", default=str(ROOT / "docs" / "results" / "seed_ensemble"))
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("overrides", nargs="*", help="extra train.py overrides (after --)")
    args = ap.parse_args(argv)
    if len(args.seeds) < 2:
        raise SystemExit(f"--seeds {args.seeds}: an ensemble needs at least 2 seeds")
    run_dirs = []
    for seed in args.seeds:
        cfg = benchmark_config(
            args.index, args.phi, args.n, args.split, args.epochs, 1, extra=[*args.overrides, f"seed={seed}"]
        )
        run_dir = Path(args.out) / f"N{args.n}_phi{args.phi:g}_seed{seed}"
        train_or_resume(cfg, run_dir)
        for big in list(run_dir.glob("fold*/")) + [run_dir / "tensorboard"]:
            shutil.rmtree(big, ignore_errors=True)
        run_dirs.append(run_dir)
    folds = sorted(
        int(p.stem.removeprefix("fold").split("_")[0]) for p in run_dirs[0].glob("fold*_predictions.npz")
    )
    per_fold = [fold_scores(run_dirs, k) for k in folds]

    def cell(values):
        v = np.asarray(values, dtype=np.float64)
        return f"{np.nanmean(v):.4f} ± {np.nanstd(v, ddof=1):.4f}"

    held_out = "whole trajectories held out" if args.split == "grouped" else "snapshots held out"
    out = Section(
        f"N = {args.n}, φ = {args.phi:.2f}, {args.split} split ({held_out}), "
        f"{len(folds)} folds, {args.epochs} epochs, model: {model_label(args.overrides)}; seeds "
        f"{args.seeds}.  Mean ± std over the test folds; the ensemble averages the "
        f"{len(args.seeds)} models of each fold (log η_r, log Π in log space).",
        "",
    )
    body = []
    for m, seed in enumerate(args.seeds):
        rows = [members[m] for members, _ in per_fold]
        body.append(
            [
                f"seed {seed}",
                *(cell([r[key] for r in rows]) for key, _ in SCORES),
                cell([r["fluct_eta"] for r in rows]),
            ]
        )
    mean_single = {
        key: [np.mean([r[key] for r in members]) for members, _ in per_fold]
        for key, _ in SCORES + (("fluct_eta", ""),)
    }
    body.append(
        ["one model (mean over seeds)", *(cell(mean_single[key]) for key, _ in SCORES)]
        + [cell(mean_single["fluct_eta"])]
    )
    ens = [mean for _, mean in per_fold]
    body.append(
        [f"**ensemble of {len(args.seeds)}**", *(f"**{cell([r[key] for r in ens])}**" for key, _ in SCORES)]
        + [cell([r["fluct_eta"] for r in ens])]
    )
    out.table(["model", *(label for _, label in SCORES), "fluct. η_r"], body)
    gain = [e["r2_log_eta"] - s for e, s in zip(ens, mean_single["r2_log_eta"])]
    command = (
        "python -m bench.surrogate_seed_ensemble --phi "
        f"{args.phi:g} --n {args.n} --seeds {' '.join(map(str, args.seeds))} --epochs {args.epochs}"
        + (" -- " + " ".join(args.overrides) if args.overrides else "")
    )
    out.add(
        "",
        f"Ensemble − one model, log η_r, per fold: {', '.join(f'{g:+.4f}' for g in gain)}.",
        "",
        f"Command: `{command}`",
    )
    (Path(args.out) / f"N{args.n}_phi{args.phi:g}.json").write_text(
        json.dumps(
            {"seeds": args.seeds, "folds": folds, "ensemble": ens, "one_model": mean_single}, default=float
        )
    )
    publish("seed_ensemble", out, not args.no_write, command=command)


if __name__ == "__main__":
    main()
