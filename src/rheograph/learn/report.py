"""Run report: R^2 / MAE table per fold, parity plots (+-15 % bands, seed paper Fig. 4), predicted vs
simulated flow curves (Fig. 6) and absolute-error distributions (Fig. 5)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rheograph.io.figures import save_png
from rheograph.learn.module import TARGET_NAMES, fold_metrics

LABELS = {"eta": "η_r", "pressure": "Π / σ0", "z_mu": "Z_μ"}
BASELINE_LABELS = {
    "stress_mean": "baseline: mean at (φ, σ)",
    "descriptors": "baseline: descriptors + σ (trees)",
    "descriptors_ridge": "baseline: descriptors, positions only (ridge)",
    "descriptors_solve": "baseline: descriptors + σ + one-solve η_r (trees)",
    "physics_solve": "physics only: one-solve η_r, contact-spring Π, counted Z_μ",
    "physics_offset": "physics only: one-solve η_r + (φ, σ) offset, contact-spring Π, counted Z_μ",
}


def subsets(prediction: dict) -> np.ndarray:
    """(G, 2) array of each test graph's (phi, N); N = 0 where the fold did not record it."""
    size = prediction.get("n_particles", np.zeros(len(prediction["phi"])))
    return np.stack([np.round(prediction["phi"], 6), np.asarray(size, dtype=np.float64)], axis=1)


def per_subset_scores(
    predictions: list[dict], model: str | None = None
) -> dict[tuple[float, int], dict[str, np.ndarray]]:
    """Test scores of a model trained over several area fractions or system sizes, broken down per
    (phi, N).

    ``predictions``: the per-fold test predictions (``pred``, ``true`` (G, 3) physical units, ``phi``,
    ``stress``, ``jammed`` (G,), optionally ``n_particles`` (G,)); ``model``: None for the graph network,
    else a baseline name.  Returns {(phi, N): {metric: (n_folds,) values}}, the ``fold_metrics`` of each
    fold's test graphs of that (phi, N) (NaN where a fold has fewer than 2 graphs there), so that a pooled
    model is compared with one model per (phi, N) on the same footing.
    """
    keys = np.unique(np.concatenate([subsets(p) for p in predictions]), axis=0)
    out: dict[tuple[float, int], dict[str, list]] = {(float(f), int(n)): {} for f, n in keys}
    for p in predictions:
        pred = p["pred"] if model is None else p["baselines"][model]
        members = subsets(p)
        for key in out:
            sel = np.all(members == np.array(key, dtype=np.float64), axis=1)
            rows = (
                fold_metrics(pred[sel], p["true"][sel], p["stress"][sel], p["jammed"][sel])
                if sel.sum() > 1
                else {}
            )
            for name in set(rows) | set(out[key]):
                out[key].setdefault(name, []).append(rows.get(name, np.nan))
    return {key: {k: np.asarray(v, dtype=np.float64) for k, v in m.items()} for key, m in out.items()}


def _per_subset_table(predictions: list[dict]) -> list[str]:
    """Markdown rows: per (area fraction, system size), the network's R² (mean ± std over folds) beside
    the trees'."""
    net = per_subset_scores(predictions)
    trees = (
        per_subset_scores(predictions, "descriptors")
        if "descriptors" in predictions[0].get("baselines", {})
        else {}
    )
    lines = [
        "## Per area fraction and system size",
        "",
        "Test graphs of each (φ, N), scored per fold (mean ± std over folds); trees: the descriptor "
        "baseline on the same graphs.",
        "",
        "| φ | N | test graphs | R² log η_r | R² log Π | R² Z_μ | fluct. η_r "
        "| trees: log η_r / log Π / Z_μ |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def ms(values):
        finite = values[np.isfinite(values)]
        if finite.size == 0:
            return "n/a"
        return f"{finite.mean():.4f} ± {finite.std(ddof=1) if finite.size > 1 else 0.0:.4f}"

    for (phi, n), m in net.items():
        count = sum(int(np.all(subsets(p) == np.array([phi, n]), axis=1).sum()) for p in predictions)
        tree = (
            " / ".join(
                f"{np.nanmean(trees[(phi, n)][f'r2_{k}']):.4f}" for k in ("log_eta", "log_pressure", "z_mu")
            )
            if trees
            else "–"
        )
        lines.append(
            f"| {phi:.2f} | {n or '?'} | {count} | {ms(m['r2_log_eta'])} | {ms(m['r2_log_pressure'])} "
            f"| {ms(m['r2_z_mu'])} | {np.nanmean(m['fluct_eta']):.2f} | {tree} |"
        )
    return lines


def write_report(run_dir: Path, fold_results: list[dict], predictions: list[dict], split: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    run_dir = Path(run_dir)
    lines = [f"# Surrogate report ({len(fold_results)} fold(s), split: **{split}**)", ""]
    if split == "grouped":
        lines.append(
            "Test folds hold **whole trajectories** the model has never seen (the runs of each state point "
            "spread over folds): the honest estimate."
        )
    elif split == "phi":
        lines.append(
            "Each test fold is **one whole area fraction** the model has never seen (leave-one-φ-out: "
            "interior φ test interpolation, the smallest and largest extrapolation)."
        )
    else:
        lines.append(
            "Test folds are **random snapshots**: snapshots of one trajectory are correlated, so this "
            "measures recognition of trajectories seen in training as much as physics (optimistic)."
        )
    n_test = sum(p["pred"].shape[0] for p in predictions)
    n_runs = len({(p_["fold"], r) for p_ in predictions for r in np.unique(p_["run_id"])})
    lines += [
        "",
        f"{n_test} test graphs from {n_runs} (fold, trajectory) pairs.  Mean ± std over folds; R² log: "
        "log10 scale (seed paper), R²: physical units, ±15 %: share of snapshots predicted within ±15 % "
        "(Z_μ: or 0.05), fluct.: correlation of predicted and true deviations from the state-point mean "
        "(0 for a model that only knows σ).",
        "",
        "| model | R² log η_r | R² log Π | R² Z_μ | R² η_r | R² Π | ±15 % η_r / Π / Z_μ "
        "| fluct. η_r / Π / Z_μ |",
        "|---|---|---|---|---|---|---|---|",
    ]
    models = [("graph network", "test/")] + [
        (BASELINE_LABELS.get(name, name), f"baseline/{name}/") for name in predictions[0].get("baselines", {})
    ]

    def mean_std(key, digits=3):
        v = np.array([r.get(key, np.nan) for r in fold_results], dtype=np.float64)
        std = np.nanstd(v, ddof=1) if np.isfinite(v).sum() > 1 else 0.0
        return f"{np.nanmean(v):.{digits}f} ± {std:.{digits}f}"

    def means(prefix, name):
        values = [
            np.array([r.get(f"{prefix}{name}_{t}", np.nan) for r in fold_results]) for t in TARGET_NAMES
        ]
        return " / ".join(f"{np.nanmean(v):.2f}" if np.isfinite(v).any() else "n/a" for v in values)

    for label, prefix in models:
        lines.append(
            # log Pi and Z_mu to 4 digits: their R2 differ from 1 in the fourth (network against the
            # physics-only rows)
            f"| {label} | {mean_std(prefix + 'r2_log_eta')} | {mean_std(prefix + 'r2_log_pressure', 4)} "
            f"| {mean_std(prefix + 'r2_z_mu', 4)} | {mean_std(prefix + 'r2_eta')} "
            f"| {mean_std(prefix + 'r2_pressure')} | {means(prefix, 'within15')} | {means(prefix, 'fluct')} |"
        )
    excluded = sum(int(r.get("test/n_nonpositive_pressure", 0)) for r in fold_results)
    if excluded:
        lines += [
            "",
            f"{excluded} test graph(s) with a non-positive Π (true or predicted) left out of R² log Π.",
        ]
    scored = [r for r in fold_results if "test/jam_accuracy" in r]
    if scored:
        runs = sum(int(r["test/n_runs"]) for r in scored)
        jammed = sum(int(r["test/n_jammed_runs"]) for r in scored)
        right = sum(r["test/jam_accuracy"] * r["test/n_runs"] for r in scored if r["test/n_runs"])
        lines += [
            "",
            f"Shear jamming (rheograph.learn.jamming: jammed where ≥ half the training trajectories at the "
            f"nearest state point jammed): right on {right:.0f} of {runs} test trajectories ({jammed} of "
            "them jammed); η_r is not scored on jammed snapshots.",
        ]
    if split != "phi" and np.unique(np.concatenate([subsets(p) for p in predictions]), axis=0).shape[0] > 1:
        lines += [""] + _per_subset_table(predictions)
    lines += [
        "",
        "## Graph network per fold",
        "",
        "| fold | " + " | ".join(f"R² {LABELS[t]} | MAE {LABELS[t]}" for t in TARGET_NAMES) + " |",
        "|---|" + "---|---|" * len(TARGET_NAMES),
    ]
    for r in fold_results:
        lines.append(
            f"| {r['fold']} | "
            + " | ".join(f"{r[f'test/r2_{t}']:.4f} | {r[f'test/mae_{t}']:.4g}" for t in TARGET_NAMES)
            + " |"
        )
    lines.append(
        "| mean ± std | "
        + " | ".join(f"{mean_std(f'test/r2_{t}', 4)} | {mean_std(f'test/mae_{t}', 4)}" for t in TARGET_NAMES)
        + " |"
    )
    lines += [
        "",
        "![parity](parity.png)",
        "",
        "![flow curves](flow_curves.png)",
        "",
        "![errors](mae_distribution.png)",
    ]
    (run_dir / "report.md").write_text("\n".join(lines) + "\n")

    pred = np.concatenate([p["pred"] for p in predictions])
    true = np.concatenate([p["true"] for p in predictions])
    stress = np.concatenate([p["stress"] for p in predictions])
    phi = np.concatenate([p["phi"] for p in predictions])

    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))
    for k, (ax, t) in enumerate(zip(axes, TARGET_NAMES)):
        lo, hi = (
            float(min(true[:, k].min(), pred[:, k].min())),
            float(max(true[:, k].max(), pred[:, k].max())),
        )
        grid = np.linspace(lo, hi, 50)
        ax.plot(grid, grid, "k-", lw=1)
        ax.plot(grid, 1.15 * grid, "b--", lw=0.8)
        ax.plot(grid, 0.85 * grid, "b--", lw=0.8, label="±15 %")
        ax.scatter(true[:, k], pred[:, k], s=10, c="tab:red", alpha=0.7, label="test folds")
        ax.set_xlabel(f"simulated {LABELS[t]}")
        ax.set_ylabel(f"predicted {LABELS[t]}")
        if t != "z_mu" and lo > 0:
            ax.set_xscale("log")
            ax.set_yscale("log")
            # labels at 1, 2, 5 x 10^n in plain numbers, none on the minor ticks: matplotlib labels
            # the minor ticks of a log axis spanning less than about a decade and a half, and they
            # run into each other
            for axis in (ax.xaxis, ax.yaxis):
                axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
                axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
                axis.set_minor_formatter(NullFormatter())
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    save_png(fig, run_dir / "parity.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))
    for value in np.unique(phi):
        sel = phi == value
        sig = np.unique(stress[sel])
        for k, (ax, t) in enumerate(zip(axes, TARGET_NAMES)):
            sim_mean = [true[sel & (stress == s), k].mean() for s in sig]
            pred_mean = [pred[sel & (stress == s), k].mean() for s in sig]
            ax.plot(sig, sim_mean, "-", label=f"simulated φ={value:.2f}")
            ax.plot(sig, pred_mean, "o", mfc="none", label=f"predicted φ={value:.2f}")
            ax.set_xscale("log")
            ax.set_xlabel("σ / σ0")
            ax.set_ylabel(LABELS[t])
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    save_png(fig, run_dir / "flow_curves.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for k, (ax, t) in enumerate(zip(axes, TARGET_NAMES)):
        err = np.abs(pred[:, k] - true[:, k])
        ax.hist(err, bins=30, density=True, alpha=0.6)
        if err.size > 2 and err.std() > 0:
            from scipy.stats import gaussian_kde

            grid = np.linspace(0, err.max(), 200)
            ax.plot(grid, gaussian_kde(err)(grid), "k-")
        ax.set_xlabel(f"absolute error {LABELS[t]}")
        ax.set_ylabel("density")
    fig.tight_layout()
    save_png(fig, run_dir / "mae_distribution.png", dpi=110)
    plt.close(fig)

    # the figures in TensorBoard too, next to the scalars
    import matplotlib.image as mpimg
    from torch.utils.tensorboard import SummaryWriter

    writer = SummaryWriter(str(run_dir / "tensorboard" / "report"))
    for name in ("parity", "flow_curves", "mae_distribution"):
        img = mpimg.imread(run_dir / f"{name}.png")[..., :3]
        writer.add_image(f"report/{name}", img, dataformats="HWC")
    writer.close()
    return run_dir / "report.md"
