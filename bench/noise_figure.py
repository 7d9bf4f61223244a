"""The position-noise figure: unexplained variance 1 − R² of each target against the noise ε per
coordinate, at φ = 0.70, 0.76 and 0.80 (N = 400, held-out trajectories), for the exact model, the exact
model on positions relaxed by a short shear, the imaging model, trees on descriptors of the noisy
positions, gap-shell inputs (φ = 0.76) and the lookup of the training mean at (φ, σ).

    python -m bench.noise_figure

It draws the numbers that ``bench/snapshot_noise.py`` records for each run it scores
(docs/results/bench/snapshot_noise/<run>.json, each with the command that made it; the same numbers as
its tables in docs/validation/position_noise.md), so it costs no prediction: rerun those commands to
refresh them, then this.  Keeps the plotted numbers in docs/results/bench/figures/imaging_noise.json, from
which it draws docs/figures/imaging_noise.png (as ``python -m bench.render`` does).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from bench.figures import NOISE_TARGETS as TARGETS
from bench.figures import publish_figure
from bench.publishing import command_line, read_result_record
from rheograph.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "docs" / "results" / "bench" / "snapshot_noise"  # bench/snapshot_noise.py's, per run
FIGURE = "figures/imaging_noise.png"
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


def figure_data(records: Path = RECORDS) -> dict:
    """The numbers :func:`bench.figures.draw_imaging_noise` plots: per panel its φ, the noise levels ε
    and per curve its legend label and R² per ε of each target, from the run records in ``records``."""
    panels = []
    for phi, exact, imaging, extra in PANELS:
        runs = dict.fromkeys(run for run, _, _ in curves(exact, imaging, extra))
        eps, rows = run_records(Path(records), runs)
        lines = []
        for run, predictor, label in curves(exact, imaging, extra):
            missing = [m for m, _ in TARGETS if (run, predictor, m) not in rows]
            if missing:
                sys.exit(f"noise_figure: the record of {run} has no row '{predictor}' / {missing[0]}")
            lines.append({"label": label, "r2": {m: rows[(run, predictor, m)] for m, _ in TARGETS}})
        panels.append({"phi": phi, "noise": eps, "curves": lines})
    return {"panels": panels}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--records", default=str(RECORDS), help="folder of snapshot_noise.py's records (<run>.json)"
    )
    args = ap.parse_args(argv)
    path = publish_figure(FIGURE, figure_data(Path(args.records)), command_line("noise_figure", argv))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
