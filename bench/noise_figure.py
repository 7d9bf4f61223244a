"""The position-noise figure: unexplained variance 1 − R² of each target against the noise ε per
coordinate, at φ = 0.70, 0.76 and 0.80 (N = 400, held-out trajectories), for the exact model, the exact
model on positions relaxed by a short shear, the imaging model, trees on descriptors of the noisy
positions, gap-shell inputs (φ = 0.76) and the lookup of the training mean at (φ, σ).

    python -m bench.noise_figure

It draws the numbers that ``bench/snapshot_noise.py`` records for each run it scores
(docs/results/bench/snapshot_noise/<run>.json, each with the command that made it; the same numbers as
its tables in docs/validation/position_noise.md), so it costs no prediction: rerun those commands to
refresh them, then this.  Writes docs/figures/imaging_noise.png (``--out``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from bench.publishing import read_result_record
from rheograph.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "docs" / "results" / "bench" / "snapshot_noise"  # bench/snapshot_noise.py's, per run
TARGETS = (("R² log η_r", "log η_r"), ("R² log Π", "log Π"), ("R² Z_μ", "Z_μ"))
RELAXED = "graph network on positions relaxed by Δγ = 0.01 (every 4th)"  # the exact model, relaxed input
# (φ, the exact model's run, the imaging model's run, further (run, row, label))
PANELS = (
    (0.70, "N400_phi0.70", "N400_phi0.70_relaxed_measured", ()),
    (
        0.76,
        "N400_phi0.76",
        "N400_phi0.76_relaxed_measured",
        (("N400_phi0.76_shells", "graph network", "gap shells, ε known"),),
    ),
    (0.80, "N400_phi0.80", "N400_phi0.80_relaxed", ()),
)


def curves(exact: str, imaging: str, extra=()) -> list[tuple[str, str, str]]:
    """(run heading, predictor row, legend label) of every curve of a panel; the trees and the lookup are
    those of the imaging run (descriptors from the noisy positions, the same training folds)."""
    return [
        (exact, "graph network", "exact model"),
        (exact, RELAXED, "exact model, relaxed positions"),
        (imaging, "trees on descriptors + σ", "trees on descriptors + σ"),
        *extra,
        (imaging, "graph network", "imaging model"),
        (imaging, "lookup: mean at (φ, σ)", "lookup: mean at (φ, σ)"),
    ]


STYLE = {
    "exact model": dict(color="tab:red", marker="x"),
    "exact model, relaxed positions": dict(color="tab:orange", marker="v"),
    "trees on descriptors + σ": dict(color="tab:green", marker="s"),
    "gap shells, ε known": dict(color="tab:purple", marker="D"),
    "imaging model": dict(color="tab:blue", marker="o", linewidth=2.2),
    "lookup: mean at (φ, σ)": dict(color="black", linestyle="--", marker=""),
}


def run_records(records: Path, runs) -> tuple[list[float], dict]:
    """The noise levels shared by the recorded ``runs`` and their rows {(run, predictor, metric): [value
    per ε]}, from ``records``/<run>.json."""
    rows, eps = {}, None
    for run in runs:
        try:
            record = read_result_record(run, records)
        except InputError as exc:
            sys.exit(f"noise_figure: {exc}")
        if eps is not None and record["noise"] != eps:
            sys.exit(f"noise_figure: {run} was scored at noise levels {record['noise']}, another at {eps}")
        eps = record["noise"]
        for predictor, metrics in record["predictors"].items():
            for metric, values in metrics.items():
                rows[(run, predictor, metric)] = values
    return eps, rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--records", default=str(RECORDS), help="folder of snapshot_noise.py's records (<run>.json)"
    )
    ap.add_argument("--out", default=str(ROOT / "docs" / "figures" / "imaging_noise.png"))
    args = ap.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(PANELS), len(TARGETS), figsize=(12, 10), sharex=True, squeeze=False)
    floor = 5e-4  # half the last digit the tables print: an R² shown as 1.000 is drawn here
    for row, (phi, exact, imaging, extra) in enumerate(PANELS):
        runs = dict.fromkeys(run for run, _, _ in curves(exact, imaging, extra))
        eps, rows = run_records(Path(args.records), runs)
        # ε = 0 drawn a decade below the smallest ε > 0, on the log axis
        x = np.array([e if e > 0 else min(v for v in eps if v > 0) / 10 for e in eps])
        for col, (metric, title) in enumerate(TARGETS):
            ax = axes[row, col]
            for run, predictor, label in curves(exact, imaging, extra):
                if (run, predictor, metric) not in rows:
                    sys.exit(f"noise_figure: the record of {run} has no row '{predictor}' / {metric}")
                unexplained = np.maximum(1.0 - np.asarray(rows[(run, predictor, metric)]), floor)
                ax.plot(x, unexplained, label=label, **STYLE[label])
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_ylim(floor / 1.5, 5e3)
            ax.set_title(f"φ = {phi:.2f}: {title}", fontsize=10)
            ax.grid(True, which="major", alpha=0.3)
            ax.set_xticks(x, ["0" if e == 0 else f"{e:g}" for e in eps], rotation=45, fontsize=8)
            ax.minorticks_off()
            if col == 0:
                ax.set_ylabel("1 − R² (held out)")
            if row == len(PANELS) - 1:
                ax.set_xlabel("position noise ε per coordinate [a]")
    handles = {}
    for ax in axes.flat:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    fig.legend(handles.values(), handles.keys(), loc="lower center", ncol=3, frameon=False)
    fig.suptitle("Imprecise positions, N = 400: unexplained variance against the noise (lower is better)")
    fig.tight_layout(rect=(0, 0.06, 1, 0.97))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
