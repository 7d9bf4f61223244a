"""Surrogates across system sizes: shipped models trained at one N, scored zero-shot on the snapshots of
larger (or smaller) systems, which they never saw by construction.

    python bench/zero_shot_n.py data/large_n/multirun --models N400_phi0.76 N2000_phi0.76

Every snapshot with strain >= 1 of every trajectory under the directories (grouped by N and φ), each
model's ensemble prediction (the models flag N as outside their domain: that is the point), against the
simulator's own targets: R² of log η_r, log Π and Z_μ per (N, φ, model), pooled over the stresses, with
the within-state fluctuation correlation of η_r.  Results replace the marked section of docs/jamming.md
unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from simulate_speed import command_line, publish  # noqa: E402


def score(models, paths, min_strain: float) -> list[dict]:
    from rheograph.io.snapshots import read_snapshots
    from rheograph.learn.module import fold_metrics
    from rheograph.learn.predict import load_model
    from rheograph.naming import state_point_key

    groups: dict = {}
    for path in paths:
        snaps = read_snapshots(path)
        keep = np.flatnonzero((np.nan_to_num(snaps.strain, nan=-1) >= min_strain) & ~snaps.jammed)
        if keep.size:
            groups.setdefault((snaps.n_particles, round(snaps.phi, 6)), []).append((snaps, keep))
    rows = []
    for (n, phi), members in sorted(groups.items()):
        for name in models:
            model = load_model(name)
            preds, trues, keys = [], [], []
            for snaps, keep in members:
                subset = dataclasses.replace(
                    snaps,
                    positions=snaps.positions[keep],
                    le_offset=snaps.le_offset[keep],
                    strain=snaps.strain[keep],
                    targets=snaps.targets[keep],
                    jammed=snaps.jammed[keep],
                    contacts=None,
                )
                with contextlib.redirect_stderr(io.StringIO()):  # the out-of-domain N warning, expected
                    table = model.predict_snapshots(subset)
                preds.append(np.stack([table["eta_pred"], table["pressure_pred"], table["z_mu_pred"]], 1))
                trues.append(subset.targets)
                keys.append(state_point_key(np.full(keep.size, snaps.phi), np.full(keep.size, snaps.stress)))
            pred, true, key = np.concatenate(preds), np.concatenate(trues), np.concatenate(keys)
            metrics = fold_metrics(pred, true, key)
            rows.append(
                {
                    "n": n,
                    "phi": phi,
                    "model": name,
                    # a model scored on its own N has seen these trajectories (or their neighbours)
                    "zero_shot": n not in model.domain["n_particles"],
                    "snapshots": int(true.shape[0]),
                    "stresses": int(np.unique(key).size),
                    **metrics,
                }
            )
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sources", nargs="+", help="trajectory files, or directories searched for them")
    ap.add_argument("--models", nargs="+", default=["N400_phi0.76", "N2000_phi0.76"])
    ap.add_argument("--min-strain", type=float, default=1.0)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    paths = sorted(
        q for s in map(Path, args.sources) for q in (s.rglob("trajectory.h5") if s.is_dir() else [s])
    )
    rows = score(args.models, paths, args.min_strain)
    lines = [
        "Each shipped model on every flowing snapshot (strain ≥ 1) of the runs at each (N, φ), pooled over "
        "the stresses; zero-shot where the model was trained at another N (a model at its own N has "
        "seen most of these trajectories: a reference, not a test).",
        "",
        "| N | φ | model | zero-shot | snapshots | stresses | R² log η_r | R² log Π | R² Z_μ | fluct. η_r |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        seen = "yes" if r["zero_shot"] else "no: its training N"
        lines.append(
            f"| {r['n']} | {r['phi']:g} | {r['model']} | {seen} | "
            f"{r['snapshots']} | {r['stresses']} | "
            f"{r['r2_log_eta']:.4f} | {r['r2_log_pressure']:.5f} | {r['r2_z_mu']:.5f} | "
            f"{r['fluct_eta']:.3f} |"
        )
    command = command_line("zero_shot_n.py", argv)
    lines += ["", f"Command: `{command}`"]
    publish("zero_shot_n", "\n".join(lines), not args.no_write, page="jamming.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
