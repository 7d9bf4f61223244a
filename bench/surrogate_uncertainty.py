"""Fold-ensemble uncertainty on trajectories no model has seen, and the surrogate's speed-up over the
simulator, measured in one run on this machine.

    OMP_WAIT_POLICY=PASSIVE python -m bench.surrogate_uncertainty --phi 0.76 --train-seeds 1 2 --test-seed 3

Trains the default 5-fold surrogate (held-out trajectories) on the seeds ``--train-seeds`` of one area
fraction, then predicts every trajectory of ``--test-seed`` with the 5-model ensemble (``predict.py``'s
function, one batched pass per file) and reports: R² of the ensemble mean, and the coverage of two
error bars (a calibrated Gaussian bar covers 68 % within ±1 and 95 % within ±2): the ensemble's spread,
and the cross-validated error bar of the training run (rheograph.learn.error_model: the RMS of its
held-out-trajectory residuals per state point).  Speed: wall
seconds per predicted snapshot (graph building + 5 models) against the simulator's CPU seconds for one
decorrelated snapshot (the runs' recorded CPU seconds per strain × the measured decorrelation strain).
Keeps the ``surrogate_uncertainty`` section of docs/validation/surrogate_accuracy.md as its record
(``python -m bench.render`` draws it).
"""

from __future__ import annotations

import argparse
import glob
import os
import shutil
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402

from bench.publishing import Section, publish
from bench.training import benchmark_config, train_or_resume  # noqa: E402
from rheograph.analysis.dataset_card import cpu_seconds_per_decorrelated_snapshot  # noqa: E402
from rheograph.io.snapshots import read_snapshots  # noqa: E402
from rheograph.learn.error_model import error_scale  # noqa: E402
from rheograph.learn.module import TARGET_NAMES, r2_score  # noqa: E402
from rheograph.learn.predict import Surrogate  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
LABELS = {"eta": "η_r", "pressure": "Π", "z_mu": "Z_μ"}
HEADER = (
    "target",
    "R² (ensemble mean)",
    "R² log",
    "ensemble spread: coverage ±1σ / ±2σ",
    "median σ_ens / |error|",
    "cross-validated error bar: coverage ±1 / ±2",
    "median bar / |error|",
)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--phi", type=float, default=0.76)
    ap.add_argument("--n", type=int, default=400)
    ap.add_argument("--train-seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--test-seed", type=int, default=3)
    ap.add_argument("--epochs", type=int, default=60)
    ap.add_argument("--fold-workers", type=int, default=1, help="parallel fold processes (one per core)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "results" / "surrogate_uncertainty"))
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    pattern = f"data/paper/multirun/N{args.n}_phi{args.phi:g}_*_seed{{}}_*/trajectory.h5"
    train_files = sorted(f for s in args.train_seeds for f in glob.glob(str(ROOT / pattern.format(s))))
    test_files = sorted(glob.glob(str(ROOT / pattern.format(args.test_seed))))
    if not train_files or not test_files:
        raise SystemExit(f"no files for N = {args.n}, φ = {args.phi} and the seeds asked for")
    files = f"[{','.join(train_files)}]"
    cfg = benchmark_config(files, args.phi, args.n, "grouped", args.epochs, args.fold_workers)
    run_dir = Path(args.out)
    train_or_resume(cfg, run_dir)
    for big in list(run_dir.glob("fold*/")) + [run_dir / "tensorboard"]:
        shutil.rmtree(big, ignore_errors=True)
    bundles = sorted(run_dir.glob("fold*.pt"))
    preds, stds, errs, trues, seconds, n_snapshots, sim_cost = [], [], [], [], 0.0, 0, []
    for path in test_files:
        t0 = time.perf_counter()
        result = Surrogate(bundles, str(run_dir)).predict_snapshots(read_snapshots(path))
        seconds += time.perf_counter() - t0
        n_snapshots += result["strain"].size
        steady = result["strain"] >= 1.0  # scored like the training data: after the start-up transient
        preds.append(np.stack([result[f"{t}_pred"][steady] for t in TARGET_NAMES], axis=1))
        stds.append(np.stack([result[f"{t}_pred_std"][steady] for t in TARGET_NAMES], axis=1))
        errs.append(np.stack([result[f"{t}_pred_err"][steady] for t in TARGET_NAMES], axis=1))
        trues.append(np.stack([result[f"{t}_sim"][steady] for t in TARGET_NAMES], axis=1))
        sim_cost.append(cpu_seconds_per_decorrelated_snapshot(path))
    pred, std, true = np.concatenate(preds), np.concatenate(stds), np.concatenate(trues)
    err_bar = np.concatenate(errs)
    rows = [
        target_cells(name, pred[:, k], std[:, k], err_bar[:, k], true[:, k])
        for k, name in enumerate(TARGET_NAMES)
    ]
    command = (
        f"python -m bench.surrogate_uncertainty --phi {args.phi} --n {args.n} --train-seeds "
        + " ".join(map(str, args.train_seeds))
        + f" --test-seed {args.test_seed} --epochs {args.epochs}"
    )
    lead = (
        f"N = {args.n}, φ = {args.phi}: 5-fold ensemble trained on seeds {args.train_seeds} "
        f"({len(train_files)} trajectories, held-out-trajectory folds), tested on the {len(test_files)} "
        f"trajectories of seed {args.test_seed} ({len(pred)} snapshots at strain ≥ 1) that no model "
        "has seen."
    )
    finite = [c for c in sim_cost if np.isfinite(c)]
    out = section(lead, rows, seconds / n_snapshots, float(np.median(finite)), command)
    publish("surrogate_uncertainty", out, write=not args.no_write, command=command)


def target_cells(name: str, pred, std, err_bar, true) -> list[str]:
    """One target's published cells from the ensemble's predictions ``pred``, its spread ``std``, the
    cross-validated error bar ``err_bar`` and the simulated values ``true`` (one per test snapshot)."""
    err = np.abs(pred - true)
    positive = (pred > 0) & (true > 0)
    r2_log = r2_score(np.log10(pred[positive]), np.log10(true[positive])) if name != "z_mu" else float("nan")
    ratio = np.median(std / np.maximum(err, 1e-12))
    # the error bar lives in the scale the errors were modelled on (log10 for eta_r and Pi)
    scaled_err = np.abs(error_scale(pred, name) - error_scale(true, name))
    usable = np.isfinite(scaled_err)
    bar, scaled_err = err_bar[usable], scaled_err[usable]
    return [
        LABELS[name],
        f"{r2_score(pred, true):.3f}",
        f"{r2_log:.3f}" if np.isfinite(r2_log) else "–",
        f"{np.mean(err <= std):.2f} / {np.mean(err <= 2 * std):.2f}",
        f"{ratio:.2f}",
        f"{np.mean(scaled_err <= bar):.2f} / {np.mean(scaled_err <= 2 * bar):.2f}",
        f"{np.median(bar / np.maximum(scaled_err, 1e-12)):.2f}",
    ]


def section(
    lead: str, rows: list[list[str]], per_snapshot: float, sim_seconds: float, command: str
) -> Section:
    """The published section: what was tested (``lead``), the coverage table, the speed-up of one
    prediction (``per_snapshot`` wall s) over simulating a decorrelated snapshot (``sim_seconds`` CPU s)
    and the command."""
    out = Section(lead, "")
    out.table(HEADER, rows)
    out.add(
        "",
        f"Speed: {1e3 * per_snapshot:.1f} ms per snapshot (graph building + 5 models, one batched pass per "
        f"file, this machine); the simulator spends {sim_seconds:.1f} CPU s per decorrelated snapshot "
        "(median over the test runs of recorded CPU s/strain × the 1/e decorrelation strain of log η_r): "
        f"**{sim_seconds / per_snapshot:.0f}×**.",
        "",
        f"Command: `{command}`",
    )
    return out


if __name__ == "__main__":
    main()
