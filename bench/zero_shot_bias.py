"""Where a shipped model is off on another system size: its mean log(predicted / true) η_r per run
(state point and seed), on the flowing snapshots with strain >= 1, with declared position noise.

    python -m bench.zero_shot_bias N400_phi0.80_imaging 'data/paper/multirun/N2000_phi0.8_*/trajectory.h5' \\
        --noise 0.01 --every 5

Same snapshots and noise draws as ``bench/zero_shot_n.py`` with the same --every, --noise and --seed
when the trajectories are passed in the same order (sorted).  Prints a markdown table.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
from pathlib import Path

import numpy as np

from bench.zero_shot_n import _noisy, trajectory_paths  # noqa: E402


def main(argv=None) -> int:
    from rheograph.io.snapshots import read_snapshots
    from rheograph.learn.predict import load_model

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model", help="a shipped model's name or a model directory")
    ap.add_argument("sources", nargs="+", help="trajectory files, globs, or directories searched for them")
    ap.add_argument("--noise", type=float, default=0.0, help="position noise ε [a], declared")
    ap.add_argument("--every", type=int, default=1, help="every n-th snapshot")
    ap.add_argument("--min-strain", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=0, help="of the noise draws")
    args = ap.parse_args(argv)
    paths = trajectory_paths(args.sources, ap)
    model = load_model(args.model)
    rng = np.random.default_rng([args.seed, int(round(args.noise * 1e6))])
    rows = []
    for path in paths:
        snaps = read_snapshots(path)
        keep = np.flatnonzero((np.nan_to_num(snaps.strain, nan=-1) >= args.min_strain) & ~snaps.jammed)
        keep = keep[:: args.every]
        if not keep.size:
            continue
        subset = _noisy(snaps, keep, args.noise, rng)
        with contextlib.redirect_stderr(io.StringIO()):  # the out-of-domain N warning, expected
            table = model.predict_snapshots(subset)
        ratio = np.log(table["eta_pred"]) - np.log(snaps.targets[keep, 0])
        rows.append(
            (
                snaps.stress,
                path,
                keep.size,
                ratio.mean(),
                ratio.std(),
                np.exp(np.log(snaps.targets[keep, 0]).mean()),
            )
        )
    print(f"{args.model} on {len(rows)} runs, ε = {args.noise:g} a\n")
    print("| σ/σ0 | run | snapshots | mean log(pred/true) η_r | sd | true η_r (geometric mean) |")
    print("|---|---|---|---|---|---|")
    for stress, path, count, mean, sd, eta in sorted(rows):
        print(f"| {stress:g} | {Path(path).parent.name} | {count} | {mean:+.3f} | {sd:.3f} | {eta:.0f} |")
    return 0


if __name__ == "__main__":
    from rheograph.errors import one_line_errors

    with one_line_errors("bench/zero_shot_bias.py"):
        sys.exit(main())
