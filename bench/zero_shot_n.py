"""Surrogates across system sizes: shipped models trained at one N, scored zero-shot on the snapshots of
larger (or smaller) systems, which they never saw by construction.

    python -m bench.zero_shot_n data/large_n/multirun --models N400_phi0.76 N2000_phi0.76
    python -m bench.zero_shot_n data/paper/multirun/N2000_phi0.76_*/trajectory.h5 \\
        --models N400_phi0.76_imaging --noise 0 0.01 0.03 --every 4 \\
        --page validation/position_noise.md --section zero_shot_n_noise --title '...'
    python -m bench.zero_shot_n data/large_n_3d/multirun --models pooled_N500_3d \\
        --lookup-from data/flow_curves_3d/multirun --page validation/surrogate_3d.md --section zero_shot_3d

Every snapshot with strain >= 1 of every trajectory under the directories (grouped by N and φ), each
model whose area fractions cover the group: its ensemble prediction (the models flag N as outside their
domain: that is the point), against the simulator's own targets: R² of log η_r, log Π and Z_μ per (N, φ,
model), pooled over the stresses, with the within-state fluctuation correlation of η_r.  With ``--noise``
the positions carry Gaussian noise of each ε (declared to the model, as for an imaging model), beside the
lookup of the other seeds' mean at the same state point (or, with ``--lookup-from``, of other runs' mean at
the same (φ, σ): the smaller system's set).  Results replace the marked section
(``--section``) of docs/<``--page``> (default jamming.md) unless ``--no-write``; ``--per-snapshot`` also
prints every scored snapshot's prediction/target ratios.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import glob
import io
import sys
from pathlib import Path

import numpy as np

from bench.publishing import command_line, publish, table


def _noisy(snaps, keep, eps: float, rng):
    """The snapshots ``keep`` of ``snaps`` with Gaussian noise of ``eps`` [a] per coordinate added to the
    positions and declared (``position_noise``), as an experimenter who knows their precision would."""
    from rheograph.io.configurations import wrap_into_box

    positions = snaps.positions[keep]
    if eps > 0.0:
        positions = np.stack(
            [
                wrap_into_box(p + rng.normal(0.0, eps, p.shape), snaps.lx, snaps.ly, offset)
                for p, offset in zip(positions, snaps.le_offset[keep])
            ]
        )
    return dataclasses.replace(
        snaps,
        positions=positions,
        le_offset=snaps.le_offset[keep],
        strain=snaps.strain[keep],
        targets=snaps.targets[keep],
        jammed=snaps.jammed[keep],
        contacts=None,
        position_noise=eps if eps > 0.0 else snaps.position_noise,
    )


def lookup_mean(targets: list[np.ndarray]) -> np.ndarray:
    """(3,) lookup of target rows (K_i, 3) pooled: geometric means of η_r and Π (the scores are in log),
    the mean of Z_μ."""
    scored = np.concatenate([np.column_stack([np.log(t[:, 0]), np.log(t[:, 1]), t[:, 2]]) for t in targets])
    mean = scored.mean(axis=0)
    return np.array([np.exp(mean[0]), np.exp(mean[1]), mean[2]])


def _state_key(snaps):
    """The (φ, σ) state-point key of a trajectory's snapshots."""
    from rheograph.naming import state_point_key

    return state_point_key(np.array([snaps.phi]), np.array([snaps.stress]))[0]


def other_seeds_mean(members) -> list[np.ndarray | None]:
    """Per trajectory, the lookup a user of the same state point could have: over the *other*
    trajectories at its (N, φ, σ), the geometric means of η_r and Π (the scores are in log) and the mean
    of Z_μ, (K, 3) for its K snapshots (None where it is the only one)."""
    keys = [_state_key(s) for s, _ in members]
    targets = [s.targets[k] for s, k in members]
    out = []
    for i, (_, keep) in enumerate(members):
        others = [targets[j] for j in range(len(members)) if j != i and keys[j] == keys[i]]
        if not others:
            out.append(None)
            continue
        out.append(np.repeat(lookup_mean(others)[None], keep.size, axis=0))
    return out


def reference_mean(members, references) -> tuple[list[np.ndarray | None], str]:
    """Per trajectory of ``members``, the lookup from other runs (``references``: (snapshots, kept
    indices) pairs, e.g. a smaller system's set): the geometric means of η_r and Π and the mean of Z_μ
    over the references' snapshots at its (φ, σ), (K, 3) for its K snapshots (None where no reference
    run has its state point); with the row's label."""
    pooled: dict = {}
    for s, k in references:
        pooled.setdefault(_state_key(s), []).append(s.targets[k])
    sizes = sorted({s.n_particles for s, _ in references})
    out = [
        np.repeat(lookup_mean(pooled[_state_key(s)])[None], keep.size, axis=0)
        if _state_key(s) in pooled
        else None
        for s, keep in members
    ]
    return out, f"lookup: mean of the N = {', '.join(map(str, sizes))} runs at (φ, σ)"


def _flowing(paths, min_strain: float, every: int = 1) -> list:
    """(snapshots, indices) per trajectory of ``paths``: every ``every``-th flowing snapshot with strain
    >= ``min_strain`` (trajectories without one are left out)."""
    from rheograph.io.snapshots import read_snapshots

    out = []
    for path in paths:
        snaps = read_snapshots(path)
        keep = np.flatnonzero((np.nan_to_num(snaps.strain, nan=-1) >= min_strain) & ~snaps.jammed)[::every]
        if keep.size:
            out.append((snaps, keep))
    return out


def score(
    models,
    paths,
    min_strain: float,
    noises=(0.0,),
    every: int = 1,
    seed: int = 0,
    per_snapshot=None,
    lookup_paths=None,
) -> list[dict]:
    """Rows of metrics per (N, φ, model or lookup, ε): every ``every``-th flowing snapshot with strain >=
    ``min_strain``, noise ``ε`` [a] drawn once per (ε, trajectory) from ``seed``.  The lookup is the
    other seeds' mean at the same (N, φ, σ), or with ``lookup_paths`` the mean of those trajectories'
    flowing snapshots at the same (φ, σ).  A list given as ``per_snapshot`` receives one dict per
    (model, ε, snapshot the row scores): its run, stress, strain and η_r, and the prediction's ratios
    (η_r, Π) and difference (Z_μ) — what an R² over a few snapshots of one state point hides."""
    from rheograph.learn.module import fold_metrics
    from rheograph.learn.predict import load_model
    from rheograph.naming import state_point_key

    groups: dict = {}
    for snaps, keep in _flowing(paths, min_strain, every):
        groups.setdefault((snaps.n_particles, round(snaps.phi, 6)), []).append((snaps, keep))
    references = _flowing(lookup_paths, min_strain) if lookup_paths else None
    rows = []
    for (n, phi), members in sorted(groups.items()):
        true = np.concatenate([s.targets[k] for s, k in members])
        key = np.concatenate(
            [state_point_key(np.full(k.size, s.phi), np.full(k.size, s.stress)) for s, k in members]
        )
        key_stress = np.concatenate([np.full(k.size, s.stress) for s, k in members])
        if references is None:
            lookups, lookup_label = other_seeds_mean(members), "lookup: other seeds' mean at (φ, σ)"
        else:
            lookups, lookup_label = reference_mean(members, references)
        # where a lookup exists, every row is scored on the snapshots it covers (state points with
        # another seed): R² over different snapshots would not compare
        have = np.concatenate([np.full(k.size, x is not None) for (_, k), x in zip(members, lookups)])
        if not have.any():
            have[:] = True
        common = {
            "n": n,
            "phi": phi,
            "snapshots": int(have.sum()),
            "stresses": int(np.unique(key[have]).size),
        }
        if any(x is not None for x in lookups):
            pred = np.concatenate([x for x in lookups if x is not None])
            rows.append(
                {
                    **common,
                    "model": lookup_label,
                    "zero_shot": None,
                    "eps": None,
                    **fold_metrics(pred, true[have], key[have]),
                }
            )
        for eps in noises:
            rng = np.random.default_rng([seed, int(round(eps * 1e6))])
            subsets = [_noisy(s, k, eps, rng) for s, k in members]
            for name in models:
                model = load_model(name)
                low, high = model.domain["phi"]
                if not low - 1e-3 <= phi <= high + 1e-3:
                    continue  # another area fraction's model: not what this bench measures
                preds = []
                for subset in subsets:
                    with contextlib.redirect_stderr(io.StringIO()):  # the out-of-domain N warning, expected
                        table = model.predict_snapshots(subset)
                    preds.append(np.stack([table["eta_pred"], table["pressure_pred"], table["z_mu_pred"]], 1))
                if per_snapshot is not None:
                    # the snapshots this row scores (``have``), in its order
                    scored = np.concatenate(preds)[have]
                    names = [np.full(len(s), Path(s.source).parent.name) for s in subsets]
                    runs = np.concatenate(names)[have]
                    strain = np.concatenate([s.strain for s in subsets])[have]
                    tgt, stress_scored = true[have], key_stress[have]
                    per_snapshot.extend(
                        {
                            "n": n,
                            "phi": phi,
                            "model": name,
                            "eps": eps,
                            "run": str(runs[j]),
                            "stress": float(stress_scored[j]),
                            "strain": float(strain[j]),
                            "eta": float(tgt[j, 0]),
                            "eta_ratio": float(scored[j, 0] / tgt[j, 0]),
                            "pressure_ratio": float(scored[j, 1] / tgt[j, 1]),
                            "z_mu_diff": float(scored[j, 2] - tgt[j, 2]),
                        }
                        for j in range(len(tgt))
                    )
                rows.append(
                    {
                        **common,
                        "model": name,
                        # a model scored on its own N has seen these trajectories (or their neighbours)
                        "zero_shot": n not in model.domain["n_particles"],
                        "eps": eps,
                        **fold_metrics(np.concatenate(preds)[have], true[have], key[have]),
                    }
                )
    return rows


def trajectory_paths(sources: list[str], ap: argparse.ArgumentParser) -> list[Path]:
    """The trajectory files of ``sources`` (files, directories searched for them, or quoted globs,
    expanded here so that the commands quoted in the docs stay short), sorted; a glob that matches
    nothing, or no file at all, ends the command with one line naming it."""
    unmatched = [s for s in sources if glob.has_magic(s) and not glob.glob(s)]
    if unmatched:
        ap.error(f"no file matches {', '.join(unmatched)} (run directories name φ as 0.7, not 0.70)")
    expanded = [Path(q) for s in sources for q in (sorted(glob.glob(s)) if glob.has_magic(s) else [s])]
    paths = sorted(q for s in expanded for q in (s.rglob("trajectory.h5") if s.is_dir() else [s]))
    if not paths:
        ap.error(f"no trajectory files in {sources}")
    return paths


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sources", nargs="+", help="trajectory files, globs, or directories searched for them")
    ap.add_argument("--models", nargs="+", default=["N400_phi0.76", "N2000_phi0.76"])
    ap.add_argument("--min-strain", type=float, default=1.0)
    ap.add_argument("--noise", type=float, nargs="+", default=[0.0], help="position noise ε [a], declared")
    ap.add_argument("--every", type=int, default=1, help="score every n-th snapshot")
    ap.add_argument(
        "--lookup-from",
        nargs="+",
        default=None,
        help="trajectories (files, globs, directories) whose mean at each (φ, σ) is the lookup row, "
        "e.g. the smaller system's set (default: the other seeds at the same N)",
    )
    ap.add_argument("--seed", type=int, default=0, help="of the noise draws")
    ap.add_argument("--page", default=None, help="the docs page holding the section (default: its record's)")
    ap.add_argument("--section", default="zero_shot_n")
    ap.add_argument("--title", default=None, help="a heading inside the section (none: the page has one)")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument(
        "--per-snapshot", action="store_true", help="also print each snapshot's prediction/target ratios"
    )
    args = ap.parse_args(argv)
    if args.every < 1 or any(not 0.0 <= eps < 1.0 for eps in args.noise):
        ap.error("--every must be >= 1 and each --noise in [0, 1) (units of a)")
    paths = trajectory_paths(args.sources, ap)
    snapshots = [] if args.per_snapshot else None
    lookup_paths = trajectory_paths(args.lookup_from, ap) if args.lookup_from else None
    rows = score(
        args.models, paths, args.min_strain, args.noise, args.every, args.seed, snapshots, lookup_paths
    )
    thinned = f" (every {args.every}th)" if args.every > 1 else ""
    lines = [
        f"Each shipped model on the flowing snapshots{thinned} with strain ≥ {args.min_strain:g} of the "
        "runs at each (N, φ), pooled over the stresses; zero-shot where the model was trained at another "
        "N (a model at its own N has seen most of these trajectories: a reference, not a test).  ε: "
        "Gaussian noise per coordinate added to the positions and declared to the model (units of a).  "
        + (
            "The lookup is the mean of the other seeds' runs at the same (N, φ, σ): what a user who had "
            "simulated that state point would predict without reading a snapshot (absent where a state "
            "point has one run; "
            if lookup_paths is None
            else "The lookup is the mean of the smaller system's runs at the same (φ, σ) (strain ≥ "
            f"{args.min_strain:g}): what a user who had simulated that state point at the size the models "
            "were trained on would predict without reading a snapshot (absent where those runs lack the "
            "state point; "
        )
        + "where it exists, every row of that (N, φ) is scored on the snapshots it covers).\n",
    ]
    header = ["N", "φ", "model", "zero-shot", "ε [a]", "snapshots", "stresses", "R² log η_r", "R² log Π"]
    header += ["R² Z_μ", "fluct. η_r"]
    body = []
    for r in rows:
        seen = "—" if r["zero_shot"] is None else "yes" if r["zero_shot"] else "no: its training N"
        eps = "any" if r["eps"] is None else f"{r['eps']:g}"
        body.append(
            [f"{r['n']}", f"{r['phi']:g}", r["model"], seen, eps, f"{r['snapshots']}", f"{r['stresses']}"]
            + [f"{r['r2_log_eta']:.4f}", f"{r['r2_log_pressure']:.5f}", f"{r['r2_z_mu']:.5f}"]
            + [f"{r['fluct_eta']:.3f}"]
        )
    command = command_line("zero_shot_n", argv)
    lines += [table(header, body), f"\nCommand: `{command}`"]
    if args.title:
        lines = [f"### {args.title}\n", *lines]
    publish(args.section, lines, not args.no_write, page=args.page, command=command)
    if snapshots:
        print(
            "\n| N | φ | model | ε [a] | run | σ/σ0 | strain | η_r | η_r pred/true | Π pred/true "
            "| Z_μ pred − true |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for s in snapshots:
            print(
                f"| {s['n']} | {s['phi']:g} | {s['model']} | {s['eps']:g} | {s['run']} | {s['stress']:g} | "
                f"{s['strain']:.2f} | "
                f"{s['eta']:.4g} | {s['eta_ratio']:.3f} | {s['pressure_ratio']:.4f} | {s['z_mu_diff']:+.4f} |"
            )
    return 0


if __name__ == "__main__":
    from rheograph.errors import one_line_errors

    with one_line_errors("bench/zero_shot_n.py"):
        sys.exit(main())
