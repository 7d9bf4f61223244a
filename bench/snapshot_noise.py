"""How the surrogates degrade when the positions are not exact: Gaussian noise of ε per coordinate (units
of the small radius a) added to the held-out test trajectories of finished training runs, each fold's
model on its own test trajectories (strain >= its min_strain), against the lookup of the training mean at
(φ, σ) (which reads no positions), the physics-only rows (one-solve η_r, contact-spring Π, counted Z_μ)
and gradient-boosted trees on the eight descriptors computed from the noisy positions (fitted on the
exact training snapshots).  Per target: R² (log10 for η_r and Π), the within-state fluctuation
correlation and the share within ±15 %.

    python -m bench.snapshot_noise docs/results/pressure_on_spring/N400_phi0.76 \\
        docs/results/surrogate_study/physics_grouped --noise 0 0.001 0.003 0.01 0.03 0.05

With ``--relax-strain Δγ`` a run whose model reads exact positions is also scored on the noisy
positions after a shear of Δγ under the simulator's own dynamics at the imposed stress
(``rheograph.graphs.features.relax_positions``: the false overlaps pushed apart, the load-bearing ones
closed again), on every ``--relax-every``-th test snapshot (about 0.4 s each at N = 400).

One noise draw per (ε, snapshot), seeded (``--seed``).  Results replace the marked section
(``--section``) of docs/validation/position_noise.md unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from bench.publishing import Section, command_line, publish, write_result_record

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "docs" / "results" / "bench" / "snapshot_noise"  # per run, read by bench/noise_figure.py
METRICS = (("r2_log_eta", "R² log η_r"), ("r2_log_pressure", "R² log Π"), ("r2_z_mu", "R² Z_μ"))


def _one_thread() -> None:
    import torch

    torch.set_num_threads(1)


def relaxed(snaps, eps: float, strain: float, every: int, rng):
    """Every ``every``-th snapshot of ``snaps`` with noise ``eps`` added and then relaxed by ``strain``."""
    import dataclasses

    from rheograph.graphs.features import relax_positions
    from rheograph.io.configurations import noisy_positions

    keep = np.arange(0, len(snaps), every)
    params = {**snaps.graph_params(), **snaps.numerics}
    positions, offsets = [], []
    for idx in keep:
        noisy = noisy_positions(snaps, idx, eps, rng)
        pos, offset, *_ = relax_positions(
            noisy, snaps.radii, snaps.lx, snaps.ly, snaps.le_offset[idx], params, strain
        )
        positions.append(pos)
        offsets.append(offset)
    return dataclasses.replace(
        snaps,
        positions=np.stack(positions),
        le_offset=np.array(offsets),
        strain=snaps.strain[keep],
        targets=snaps.targets[keep],
        jammed=snaps.jammed[keep],
        contacts=None,
        position_noise=eps,
    )


def noisy_snapshots(snaps, level, optical_axis: str, rng):
    """``snaps`` with Gaussian noise on every position, drawn from ``rng``: ``level`` is eps [a] per
    coordinate, or for a 3D run a pair (eps, eps_axial), eps_axial along ``optical_axis`` (confocal)."""
    import dataclasses

    from rheograph.graphs.dataset import noise_scales
    from rheograph.io.configurations import wrap_into_box, wrap_into_box3d

    eps, eps_axial = level if isinstance(level, tuple) else (level, None)
    noisy = snaps.positions + rng.normal(
        0.0, noise_scales(eps, eps_axial, snaps.dim, optical_axis), snaps.positions.shape
    )
    if snaps.lz is None:
        wrapped = [wrap_into_box(p, snaps.lx, snaps.ly, o) for p, o in zip(noisy, snaps.le_offset)]
    else:
        wrapped = [
            wrap_into_box3d(p, snaps.lx, snaps.ly, snaps.lz, o) for p, o in zip(noisy, snaps.le_offset)
        ]
    return dataclasses.replace(
        snaps, positions=np.stack(wrapped), contacts=None, position_noise=eps, axial_noise=eps_axial
    )


def fold_rows(
    run_dir: Path, k: int, noises, seed: int, cache_dir: Path, relax_strain: float = 0.0, relax_every: int = 4
) -> dict:
    """{(predictor, ε): (pred (G, 3), true (G, 3), groups (G,), jammed (G,), stress (G,))} for fold
    ``k``; each ε of ``noises`` is eps [a] or, for 3D runs, a pair (eps, eps_axial) (``noisy_snapshots``)."""
    import torch

    from rheograph.graphs.dataset import SnapshotGraphDataset, snapshot_graphs
    from rheograph.io.snapshots import read_snapshots
    from rheograph.learn.baselines import dataset_arrays, descriptor_trees, physics_rows
    from rheograph.learn.bundle import load_bundle, predict_dataset
    from rheograph.learn.datamodule import split_files
    from rheograph.learn.module import physical_targets
    from rheograph.naming import state_point_key

    split = json.loads((run_dir / f"fold{k}_split.json").read_text())
    saved = np.load(run_dir / f"fold{k}_predictions.npz")
    module, settings, _ = load_bundle(run_dir / f"fold{k}.pt")
    files = split_files(split, ROOT)
    dataset = SnapshotGraphDataset(files, settings, cache_dir)
    fitted = dataset_arrays(dataset, np.r_[split["train"], split["val"]])
    # the lookup (physical predictions; reads no positions) per state point: a run trained on noisy
    # copies (graph.noise_copies) saved several rows per snapshot
    saved_keys = state_point_key(saved["phi"], saved["stress"])
    lookup_at = {key: row for key, row in zip(saved_keys, saved["baseline_stress_mean"])}
    rng = np.random.default_rng(seed + 1000 * k)
    out = {}
    runs = np.unique(saved["run_id"])
    for eps in noises:
        graphs = []
        for run in runs:
            snaps = read_snapshots(files[int(run)])
            if np.any(eps):
                snaps = noisy_snapshots(snaps, eps, settings.optical_axis, rng)
            graphs += snapshot_graphs(snaps, settings, int(run))
        pred, true, meta = predict_dataset(module, graphs)
        groups = state_point_key(meta["phi"], meta["stress"])
        jammed = meta["jammed"]
        stress = meta["stress"]
        out[("graph network", eps)] = (pred, true, groups, jammed, stress)
        test = {
            "descriptors": np.concatenate([g.descriptors.numpy() for g in graphs]),
            "stress": meta["stress"],
            "phi": meta["phi"],
            "physics": np.concatenate([g.physics.numpy() for g in graphs]),
        }
        trees = descriptor_trees(fitted, test)
        out[("trees on descriptors + σ", eps)] = (
            physical_targets(trees, settings.targets),
            true,
            groups,
            jammed,
            stress,
        )
        rows = physics_rows(fitted, test, settings.targets.viscosity_scale)
        out[("physics: one-solve η_r + offset, spring Π, counted Z_μ", eps)] = (
            rows["physics_offset"],
            true,
            groups,
            jammed,
            stress,
        )
        copies = max(1, settings.noise_copies)
        assert true.shape[0] * copies == saved["true"].shape[0], "not the test snapshots of the training run"
        lookup = np.stack([lookup_at[key] for key in groups])
        out[("lookup: mean at (φ, σ)", eps)] = (lookup, true, groups, jammed, stress)
        if not settings.stress_known:
            # what a positions-only model must beat: the training folds' mean at phi alone (log eta_r,
            # log Pi / sigma, Z_mu), sigma unknown
            train = np.r_[split["train"], split["val"]]
            y = dataset.y_raw[torch.as_tensor(train)].numpy()
            train_stress = dataset.stress[torch.as_tensor(train)].numpy()
            flowing = ~dataset.jammed[torch.as_tensor(train)].numpy()
            per_phi = np.stack(
                [
                    np.full(len(stress), np.exp(np.mean(np.log(y[flowing, 0])))),
                    stress * np.exp(np.mean(np.log(y[:, 1] / train_stress))),
                    np.full(len(stress), y[:, 2].mean()),
                ],
                axis=1,
            )
            out[("lookup: mean at φ (σ unknown)", eps)] = (per_phi, true, groups, jammed, stress)
        if relax_strain and not settings.noise_range:
            graphs = []
            for run in runs:
                snaps = relaxed(read_snapshots(files[int(run)]), eps, relax_strain, relax_every, rng)
                graphs += snapshot_graphs(snaps, settings, int(run))
            pred, true, meta = predict_dataset(module, graphs)
            name = f"graph network on positions relaxed by Δγ = {relax_strain:g} (every {relax_every}th)"
            key = state_point_key(meta["phi"], meta["stress"])
            out[(name, eps)] = (pred, true, key, meta["jammed"], meta["stress"])
    return out


def main(argv=None) -> int:
    from rheograph.learn.module import fold_metrics, r2_score

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="training run directories (fold*.pt, fold*_split.json)")
    ap.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.001, 0.003, 0.01, 0.03, 0.05])
    ap.add_argument("--folds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache-dir", default=str(ROOT / "data" / "cache"))
    ap.add_argument("--relax-strain", type=float, default=0.0, help="also score relaxed positions (0: no)")
    ap.add_argument("--relax-every", type=int, default=4, help="relax every n-th test snapshot")
    ap.add_argument("--workers", type=int, default=1, help="folds scored in parallel processes")
    ap.add_argument(
        "--section", default="snapshot_noise", help="the marked section of docs/validation/position_noise.md"
    )
    ap.add_argument("--title", default="Position noise: how far the surrogates read imprecise snapshots")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    out = Section(
        f"### {args.title}",
        "",
        "Held-out test trajectories of each run, Gaussian noise ε per coordinate (units of a) on their "
        "positions, each fold's model on its own test trajectories; metrics pooled over the folds' test "
        "snapshots (fluct.: correlation of predicted and true deviations from the state-point mean; ±15 %: "
        "share of η_r within ±15 %).",
        "",
    )
    records: dict = {}  # {run: {predictor: {metric: [value per ε]}}}
    for run in args.runs:
        run_dir = Path(run)
        pooled = {}
        score = [run_dir, args.noise, args.seed, Path(args.cache_dir), args.relax_strain, args.relax_every]
        if args.workers > 1:
            with ProcessPoolExecutor(max_workers=args.workers, initializer=_one_thread) as pool:
                jobs = [pool.submit(fold_rows, score[0], k, *score[1:]) for k in args.folds]
                results = [job.result() for job in jobs]
        else:
            results = [fold_rows(score[0], k, *score[1:]) for k in args.folds]
        for rows in results:
            for key, value in rows.items():
                pooled.setdefault(key, []).append(value)
        predictors = list(dict.fromkeys(name for name, _ in pooled))
        out.add(f"**{run_dir.name}**", "")
        body = []
        for name in predictors:
            scores = {}
            for eps in args.noise:
                parts = pooled[(name, eps)]
                pred, true = np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
                groups = np.concatenate([p[2] for p in parts])
                jammed = np.concatenate([p[3] for p in parts])
                stress = np.concatenate([p[4] for p in parts])
                scores[eps] = fold_metrics(pred, true, groups, jammed)
                # the bulk friction mu_eff = sigma / Pi: what a positions-only model predicts of Pi
                # (on the snapshots whose true and predicted Pi are positive: mu_eff is undefined else)
                ok = (pred[:, 1] > 0) & (true[:, 1] > 0)
                scores[eps]["r2_log_mu_eff"] = r2_score(
                    np.log(stress[ok] / pred[ok, 1]), np.log(stress[ok] / true[ok, 1])
                )
            rows_of = (*METRICS, ("r2_log_mu_eff", "R² log μ_eff"), ("fluct_eta", "fluct. η_r"))
            for key, label in (*rows_of, ("within15_eta", "±15 % η_r")):
                values = [round(float(scores[eps][key]), 3) for eps in args.noise]
                records.setdefault(run_dir.name, {}).setdefault(name, {})[label] = values
                body.append([name, label, *(f"{value:.3f}" for value in values)])
        out.table(["predictor", "metric", *(f"ε = {eps:g}" for eps in args.noise)], body)
        out.add("")
    command = command_line("snapshot_noise", argv)
    out.add(f"Command: `{command}`")
    publish(args.section, out, not args.no_write, command=command)
    if not args.no_write:  # each run's numbers, as its table prints them, for bench/noise_figure.py
        for run, predictors in records.items():
            record = dict(command=f"`{command}`", noise=list(args.noise), predictors=predictors)
            write_result_record(run, record, RECORDS)
    return 0


if __name__ == "__main__":
    sys.exit(main())
