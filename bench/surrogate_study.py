"""Surrogate accuracy study: input variants x split protocols on one area fraction, with the baselines
scored on the same folds, written as one table into docs/validation/surrogate_accuracy.md (section
``surrogate_study``) and per-run reports under docs/results/surrogate_study/<variant>_<split>/.

    OMP_WAIT_POLICY=PASSIVE python -m bench.surrogate_study --phi 0.76 --epochs 60 \\
        --runs paper:grouped physics_positions:grouped physics:grouped physics_mean_pool:grouped \\
               paper:random physics:random

Variants (config groups of conf/): ``paper`` = graph=paper model=resgcn (the seed paper: geometric edge
features, softmax aggregation, mean pooling, positions only); ``physics_positions`` = physics-aware edge
features, positions only; ``physics`` = physics-aware features + imposed stress (graph input and CLM
load); ``physics_solve`` = ``physics`` + the one-solve viscosity and the counted Z_μ, both targets learned
as corrections to them (graph=physics_solve, the default); ``physics_solve_uncorrected`` = the same inputs
read through the head (an earlier default);
``physics_mean_pool`` = ``physics`` with mean pooling and softmax aggregation (ablation of the
stress-like readout); ``physics_layer_norm`` = ``physics`` with layer instead of batch normalisation;
``physics_pi_sigma0`` = ``physics`` learning Pi in sigma0 (graph.targets.pi.per_stress=false) with the
weights that suited it (2/5/2): ablation of learning Pi in units of the imposed stress;
``<inputs>_tuned`` = the best trial of that input variant's Optuna study
(``conf/experiment/<inputs>_phi076_best.yaml``, its own batch size).  Every run trains the K folds with
the same epochs and seed.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
from hydra import compose, initialize_config_dir  # noqa: E402

from rheograph.learn.train import train_folds  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = {
    "paper": ["graph=paper", "model=resgcn"],
    "physics_positions": ["graph=physics_positions", "model=resgcn_physics"],
    "physics": ["graph=physics", "model=resgcn_physics"],
    "physics_solve": ["graph=physics_solve", "model=resgcn_physics"],
    # the default inputs as they were before the corrections became default
    "physics_solve_uncorrected": [
        "graph=physics_solve",
        "model=resgcn_physics",
        "graph.targets.eta_r.relative_to=null",
        "graph.targets.z_mu.relative_to=null",
    ],
    "physics_mean_pool": [
        "graph=physics",
        "model=resgcn_physics",
        "model.net.pool=mean",
        "model.net.aggr=softmax",
    ],
    "physics_layer_norm": ["graph=physics", "model=resgcn_physics", "model.net.norm=layer"],
    "physics_pi_sigma0": [
        "graph=physics",
        "model=resgcn_physics",
        "graph.targets.pi.per_stress=false",
        "model.loss_weights=[2.0,5.0,2.0]",
    ],
    # the best trial of each input variant's Optuna study (bench/tune_report.py), with its batch size
    **{
        f"{v}_tuned": [f"experiment={v}_phi076_best"]
        for v in ("physics", "paper", "physics_positions", "physics_solve")
        if (ROOT / "conf" / "experiment" / f"{v}_phi076_best.yaml").exists()  # once its study has run
    },
}
COLUMNS = [
    ("r2_log_eta", "R² log η_r"),
    ("r2_log_pressure", "R² log Π"),
    ("r2_z_mu", "R² Z_μ"),
    ("r2_eta", "R² η_r"),
    ("r2_pressure", "R² Π"),
]


def train_or_resume(cfg, run_dir: Path) -> None:
    """Train the folds into ``run_dir``, keeping folds an interrupted earlier invocation of the same
    configuration finished on the same data; a directory of another configuration or other data is
    replaced."""
    from rheograph.errors import OtherRunError

    try:
        train_folds(cfg, run_dir)
    except OtherRunError:
        shutil.rmtree(run_dir)
        train_folds(cfg, run_dir)


def benchmark_config(files, phi, n, split, epochs, fold_workers, batch_size=None, extra=()):
    """The training configuration every surrogate benchmark composes: one (phi, N), a fixed epoch budget
    (cosine schedule, best validation epoch kept), no logger.  Batch size (default): 32 graphs at
    N < 2000, 8 at N >= 2000 — the fastest per epoch (docs/validation/surrogate_cost.md: batches of 32
    N = 2000 graphs leave the cache and train 1.4x slower)."""
    if batch_size is None:
        batch_size = 8 if n >= 2000 else 32
    overrides = [
        f"data.files={files}",
        f"data.phi={phi}",
        f"data.n_particles={n}",
        f"data.split={split}",
        f"data.batch_size={batch_size}",
        f"trainer.max_epochs={epochs}",
        "trainer.enable_progress_bar=false",
        "callbacks.early_stopping.patience=1000",
        "~logger",
        f"fold_workers={fold_workers}",
        *extra,
    ]
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        return compose(config_name="train", overrides=overrides)


def run_variant(name: str, split: str, args, out: Path) -> tuple[dict, float]:
    extra = [*VARIANTS[name], f"seed={args.seed}"]
    if name == "paper":  # the paper's constant learning rate over the same epoch budget
        extra.append("model.scheduler=null")
    batch_size = args.batch_size
    if name.endswith("_tuned"):  # the tuned batch size, not the study's common one
        with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
            batch_size = int(compose(config_name="train", overrides=VARIANTS[name]).data.batch_size)
    cfg = benchmark_config(
        args.files, args.phi, 400, split, args.epochs, args.fold_workers, batch_size, extra
    )
    run_dir = out / f"{name}_{split}"
    if args.reuse and (run_dir / "metrics.json").exists():  # a finished run of an earlier invocation
        minutes = run_dir / "train_minutes.txt"
        return (
            json.loads((run_dir / "metrics.json").read_text()),
            float(minutes.read_text()) if minutes.exists() else float("nan"),
        )
    t0 = time.perf_counter()
    train_or_resume(cfg, run_dir)
    minutes = (time.perf_counter() - t0) / 60
    (run_dir / "train_minutes.txt").write_text(f"{minutes:.2f}\n")
    for big in run_dir.glob("fold*/"):  # lightning checkpoints: the bundles fold*.pt are kept
        shutil.rmtree(big, ignore_errors=True)
    shutil.rmtree(run_dir / "tensorboard", ignore_errors=True)
    return json.loads((run_dir / "metrics.json").read_text()), minutes


def cell(folds: list[dict], key: str) -> str:
    v = np.array([f.get(key, np.nan) for f in folds], dtype=np.float64)
    return f"{np.nanmean(v):.3f} ± {np.nanstd(v, ddof=1):.3f}" if np.isfinite(v).sum() > 1 else "–"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--phi", type=float, default=0.76)
    ap.add_argument("--files", default="data/paper/index.json")
    ap.add_argument(
        "--runs",
        nargs="+",
        default=[f"{v}:grouped" for v in VARIANTS] + ["paper:random", "physics:random"],
        help="variant:split pairs (variants: " + ", ".join(VARIANTS) + "; splits: grouped, random)",
    )
    ap.add_argument("--epochs", type=int, default=60)
    ap.add_argument("--batch-size", type=int, default=32)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--fold-workers", type=int, default=1, help="parallel fold processes (one per core)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "results" / "surrogate_study"))
    ap.add_argument(
        "--no-write", action="store_true", help="do not touch docs/validation/surrogate_accuracy.md"
    )
    ap.add_argument(
        "--reuse", action="store_true", help="take runs whose metrics.json exists instead of retraining them"
    )
    args = ap.parse_args(argv)
    out = Path(args.out)
    rows, baselines = [], {}
    for run in args.runs:
        name, _, split = run.partition(":")
        if name not in VARIANTS or split not in ("grouped", "random"):
            raise SystemExit(f"--runs {run}: expected variant:split with variant in {list(VARIANTS)}")
        metrics, minutes = run_variant(name, split, args, out)
        folds = metrics["folds"]
        rows.append(
            f"| {name} | {split} | "
            + " | ".join(cell(folds, f"test/{key}") for key, _ in COLUMNS)
            + f" | {cell(folds, 'test/fluct_eta')} | {minutes:.1f} |"
        )
        for b in ("stress_mean", "descriptors", "descriptors_ridge", "descriptors_solve"):
            if f"baseline/{b}/r2_log_eta" in folds[0]:  # descriptors_solve: with the one-solve input
                baselines.setdefault((b, split), folds)
        print(rows[-1], flush=True)

    for (b, split), folds in baselines.items():
        rows.append(
            f"| baseline {b} | {split} | "
            + " | ".join(cell(folds, f"baseline/{b}/{key}") for key, _ in COLUMNS)
            + f" | {cell(folds, f'baseline/{b}/fluct_eta')} | – |"
        )
    lines = [
        f"φ = {args.phi}, N = 400, {args.epochs} epochs, batch {args.batch_size} (tuned: their own), 5 "
        "folds, mean ± std over folds of the test fold.  grouped: whole trajectories held out "
        "(honest); random: snapshots "
        "(seed paper).  fluct. η_r: correlation of predicted and true deviations of log η_r from the "
        "state-point mean (0 for a model that knows only σ).  Baselines (rheograph.learn.baselines) on the "
        "same folds: stress_mean = training mean at the same (φ, σ); descriptors = gradient-boosted trees "
        "on eight physics descriptors + log σ; descriptors_ridge = ridge on the descriptors alone; "
        "descriptors_solve = the trees given the one-solve η_r and the counted Z_μ too "
        "(graph=physics_solve).",
        "",
        "| inputs | split | " + " | ".join(label for _, label in COLUMNS) + " | fluct. η_r | train min |",
        "|---|---|" + "---|" * (len(COLUMNS) + 2),
        *rows,
        "",
        "Command: `python -m bench.surrogate_study "
        + ("--reuse " if args.reuse else "")
        + f"--phi {args.phi} --epochs {args.epochs} --batch-size {args.batch_size} --runs "
        + " ".join(args.runs)
        + "`; reports: docs/results/surrogate_study/.",
    ]
    from bench.publishing import publish

    publish("surrogate_study", "\n".join(lines), write=not args.no_write)


if __name__ == "__main__":
    main()
