"""Run report: R^2 / MAE table per fold, parity plots (+-15 % bands, seed paper Fig. 4), predicted vs
simulated flow curves (Fig. 6) and absolute-error distributions (Fig. 5)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rheograph.learn.module import TARGET_NAMES

LABELS = {"eta": "η_r", "pressure": "Π / σ0", "z_mu": "Z_μ"}


def write_report(run_dir: Path, fold_results: list[dict], predictions: list[dict], split: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    run_dir = Path(run_dir)
    lines = [
        f"# Surrogate report ({len(fold_results)} fold(s), split: **{split}**)",
        "",
        "Test-fold metrics in physical units (η_r, Π in σ0, Z_μ).",
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

    def mean_std(key):
        v = np.array([r[key] for r in fold_results])
        return f"{v.mean():.4f} ± {v.std(ddof=1) if v.size > 1 else 0.0:.4f}"

    lines.append(
        "| mean ± std | "
        + " | ".join(f"{mean_std(f'test/r2_{t}')} | {mean_std(f'test/mae_{t}')}" for t in TARGET_NAMES)
        + " |"
    )
    n_test = sum(p["pred"].shape[0] for p in predictions)
    lines += [
        "",
        f"{n_test} test graphs in all.",
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
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(run_dir / "parity.png", dpi=110)
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
    fig.savefig(run_dir / "flow_curves.png", dpi=110)
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
    fig.savefig(run_dir / "mae_distribution.png", dpi=110)
    plt.close(fig)

    try:  # the parity plot as a TensorBoard figure, next to the scalars
        import matplotlib.image as mpimg
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(str(run_dir / "tensorboard" / "report"))
        for name in ("parity", "flow_curves", "mae_distribution"):
            img = mpimg.imread(run_dir / f"{name}.png")[..., :3]
            writer.add_image(f"report/{name}", img, dataformats="HWC")
        writer.close()
    except ImportError:  # tensorboard is a dependency; only a broken install lands here
        pass
    return run_dir / "report.md"
