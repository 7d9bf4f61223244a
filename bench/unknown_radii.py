"""Surrogates trained on exactly bidisperse discs, on polydisperse suspensions whose radii are not known.

    python -m bench.unknown_radii 'data/polydisperse/multirun/*/trajectory.h5' \
        --lookup 'data/paper/multirun/N400_phi0.76_*/trajectory.h5'
    python -m bench.unknown_radii 'data/polydisperse_3d/multirun/*/trajectory.h5' \
        --models N500_phi0.56_3d N500_phi0.56_3d_confocal --section unknown_radii_3d \
        --lookup 'data/flow_curves_3d/multirun/N500_phi0.56_s2_seed[12]_*/trajectory.h5' \
        'data/flow_curves_3d/multirun/N500_phi0.56_s20_seed[12]_*/trajectory.h5'

Real particles spread in size by several per cent and a microscope does not measure each radius; the
shipped models were trained on two exact radii (1 and 1.4).  The runs scored here were simulated with
each species' radii spread Gaussian (``sim.radii=polydisperse sim.polydispersity=p``), and their
snapshots are given to the models with what an experiment knows instead of the true radii:

* ``species known``: each particle's species (a dye, or the sample's recipe) and the nominal radii 1 and
  1.4 — the species as the simulation drew them;
* ``species by size``: the species of a particle from its own (measured) radius against the geometric
  mean of the two nominal radii, then the nominal radius — misassigns the tails of a wide spread;
* ``radii estimated``: the species known, and each snapshot's radii estimated from its configuration
  (``rheograph.graphs.radii_estimate``: near pairs' distances by least squares, scaled to the stated φ);
* ``radii estimated, mean``: the same, the radii the mean of the estimates over the run's kept snapshots.

The exact models read the gaps the nominal radii make (overlaps of order p a between touching
particles); the imaging models (those told a position precision: 2D imaging, 3D confocal) given nominal
radii are told a precision ``--declared-noise`` [a] (in 3D along the optical axis too) and, where they
relax, relax the configuration before reading it.  Given estimated radii, every model is told the
precision ``predict_with_estimated_radii`` declares: the positions are the simulator's, exact, so it is
the radii's uncertainty alone (the estimates' scatter over the run's kept snapshots), shown in the table.
With the true radii (or estimated ones) the models read each particle's species from its size and
everything else from the radii themselves, and flag the snapshot (trained on two exact radii). Scores:
R² of log10 η_r, log10 Π and Z_μ over the snapshots at strain >= ``--min-strain`` of all runs of one
spread; the lookup row is the mean of the bidisperse training runs at each σ (``--lookup``), which reads
no positions.  Runs not finished (still going or interrupted) are left out and counted.  The table
replaces the marked section ``unknown_radii`` of docs/imaging.md unless ``--no-write``; its numbers are
kept in docs/results/bench/unknown_radii.json.
"""

from __future__ import annotations

import argparse
import glob
import sys

import numpy as np

from bench.lfdem_snapshots import scores, state_means
from bench.publishing import command_line, publish, table
from rheograph.errors import InputError
from rheograph.io.index import USABLE

NOMINAL = (1.0, 1.4)
# what the models are given
MODES = ("true radii", "species known", "species by size", "radii estimated", "radii estimated, mean")
ESTIMATED = ("radii estimated", "radii estimated, mean")


def nominal_radii(radii: np.ndarray, n_small: int, how: str) -> np.ndarray:
    """The radii (N,) an experiment would use: the nominal radius of each particle's species, the
    species known (the first ``n_small`` particles are the small ones, as the simulator orders them) or
    told from each particle's own radius against the geometric mean of the nominal radii."""
    if how == "species known":
        small = np.arange(radii.size) < n_small
    else:
        small = radii < np.sqrt(NOMINAL[0] * NOMINAL[1])
    return np.where(small, NOMINAL[0], NOMINAL[1])


def predict(model, snaps, keep, how: str) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(predictions (S, 3), the simulator's values (S, 3), share in domain, position precision told
    [a], NaN where none is added) at the kept snapshots; ``how`` one of MODES: for the estimated ones the
    radii are estimated from the kept snapshots' configurations first (each its own, or their mean)."""
    told = np.nan
    if how in ESTIMATED:
        table = model.predict_with_estimated_radii(snaps.select(keep), mean=how == "radii estimated, mean")
        keep = np.ones(int(np.sum(keep)), dtype=bool)
        told = float(table["position_noise"][0])
    else:
        table = model.predict_snapshots(snaps)
    pred = np.stack([table[f"{t}_pred"] for t in ("eta", "pressure", "z_mu")], axis=1)[keep]
    sim = np.stack([table[f"{t}_sim"] for t in ("eta", "pressure", "z_mu")], axis=1)[keep]
    return pred, sim, float(np.mean(table["in_domain"][keep])), told


def main(argv=None) -> int:
    from rheograph.io.hdf5 import read_run_info
    from rheograph.io.snapshots import read_snapshots
    from rheograph.learn.predict import load_model

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="trajectories of polydisperse runs (globs)")
    ap.add_argument("--models", nargs="+", default=["N400_phi0.76", "N400_phi0.76_imaging"])
    ap.add_argument(
        "--declared-noise",
        type=float,
        default=0.05,
        help="told to the imaging models given nominal radii [a] (estimated radii: their own uncertainty)",
    )
    ap.add_argument("--lookup", nargs="+", default=[], help="bidisperse trajectories at the same φ and N")
    ap.add_argument("--min-strain", type=float, default=1.0)
    ap.add_argument(
        "--radii", nargs="+", choices=MODES, default=list(MODES), help="what the models are given"
    )
    ap.add_argument("--section", default="unknown_radii", help="the marked section of docs/imaging.md")
    ap.add_argument("--page", default="imaging.md", help="the section's page under docs/")
    ap.add_argument("--title", default="Surrogates on polydisperse suspensions whose radii are unknown")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    files = sorted({f for pattern in args.runs for f in glob.glob(pattern)})
    if not files:
        sys.exit(f"unknown_radii: {args.runs} match no trajectory")
    lookup = state_means(args.lookup, args.min_strain) if args.lookup else {}
    models = {name: load_model(name) for name in args.models}

    by_spread: dict = {}
    systems = set()
    unfinished = []
    for path in files:
        info = read_run_info(path)
        params = info["params"]
        # a run still going (or interrupted) is left out: it would score differently once resumed
        if info["status"] not in USABLE:
            unfinished.append(path)
            continue
        if params.get("radii") != "polydisperse":
            sys.exit(f"unknown_radii: {path} is not a run of sim.radii=polydisperse")
        dim = int(params.get("dim", 2))
        systems.add((dim, params["n_particles"], params["phi"]))
        # the simulator's species: the first n_small particles are the small ones, equal areas (volumes)
        n_large = round(params["n_particles"] / (1.0 + params["size_ratio"] ** dim))
        runs = by_spread.setdefault(float(params["polydispersity"]), [])
        runs.append((read_snapshots(path), params["n_particles"] - n_large))

    if not systems:
        sys.exit(f"unknown_radii: {args.runs} match no finished run")
    if len(systems) > 1:
        sys.exit(f"unknown_radii: the runs are of several systems (dimension, N, φ): {sorted(systems)}")
    ((dim, n_particles, phi),) = systems
    record: dict = {"command": command_line("unknown_radii", argv), "spreads": {}}
    lines = [
        f"### {args.title}",
        "",
        f"{'3D, ' if dim == 3 else ''}N = {n_particles}, φ = {phi:g}; snapshots at strain ≥ "
        f"{args.min_strain:g} of runs with each species' radii spread Gaussian (relative spread p, truncated "
        f"at 2p); R² log η_r / log Π / Z_μ over all runs of one spread; imaging models given nominal radii "
        f"told ε = {args.declared_noise:g} a, every model "
        "given estimated radii told their uncertainty (their scatter over the run's snapshots; the positions "
        "are exact); in domain: the share of snapshots the model does not flag.\n",
    ]
    counts = "; ".join(
        f"p = {spread:g}: {len(runs)} runs at {len({float(snaps.stress) for snaps, _ in runs})} stresses"
        for spread, runs in sorted(by_spread.items())
    )
    left_out = f"; unfinished, left out: {len(unfinished)}" if unfinished else ""
    lines.append(f"Runs scored: {counts}{left_out}.\n")
    record["unfinished_left_out"] = unfinished
    body = []
    for spread, runs in sorted(by_spread.items()):
        rows = {}
        truth, looked_up = [], []  # the simulator's values and the lookup's, snapshot by snapshot
        for how in args.radii:
            for name, model in models.items():
                preds, sims, shares, told = [], [], [], []
                refused = None
                for snaps, n_small in runs:
                    keep = snaps.strain >= args.min_strain
                    given = snaps
                    if how != "true radii":
                        species = "species known" if how in ESTIMATED else how
                        given = _with_radii(snaps, nominal_radii(snaps.radii, n_small, species))
                        # the simulator's positions are exact; estimated radii add their own uncertainty
                        if how in ESTIMATED:
                            given.position_noise = 0.0
                        elif "position_noise" in model.settings.graph_inputs:
                            given.position_noise = args.declared_noise
                    try:
                        pred, sim, share, eps = predict(model, given, keep, how)
                    except InputError as exc:
                        refused = str(exc).split(":", 1)[-1].split("(found")[0].strip()
                        break
                    preds.append(pred)
                    sims.append(sim)
                    shares.append(share * keep.sum())
                    told.append(eps)
                key = f"{how} / {name}"
                if refused:
                    rows[key] = {"refused": refused}
                    body.append([f"{spread:g}", how, f"`{name}`", f"refused: {refused}", "", "", ""])
                    continue
                pred, sim = np.concatenate(preds), np.concatenate(sims)
                r2 = scores(pred, sim)
                share = float(np.sum(shares) / len(sim))
                rows[key] = {"r2": list(r2), "in_domain": share, "snapshots": len(sim)}
                label = how
                if how in ESTIMATED:
                    rows[key]["precision_told"] = told
                    label += f" (ε told {min(told):.3f}–{max(told):.3f} a)"
                body.append(
                    [f"{spread:g}", label, f"`{name}`", f"{r2[0]:.3f}", f"{r2[1]:.4f}", f"{r2[2]:.4f}"]
                    + [f"{share:.2f}"]
                )
        if lookup:
            for snaps, _ in runs:
                keep = snaps.strain >= args.min_strain
                stress = round(float(snaps.stress), 9)
                if stress not in lookup:
                    sys.exit(f"unknown_radii: --lookup has no trajectory at σ/σ0 = {snaps.stress:g}")
                looked_up.append(np.repeat(lookup[stress][2][None], int(keep.sum()), axis=0))
                truth.append(snaps.targets[keep])
            if truth:
                r2 = scores(np.concatenate(looked_up), np.concatenate(truth))
                rows["lookup"] = {"r2": list(r2)}
                body.append(
                    [
                        f"{spread:g}",
                        "none",
                        "lookup: bidisperse mean at (φ, σ)",
                        f"{r2[0]:.3f}",
                        f"{r2[1]:.4f}",
                    ]
                    + [f"{r2[2]:.4f}", "—"]
                )
        record["spreads"][str(spread)] = rows
    header = ["p", "radii given", "model", "R² log η_r", "R² log Π", "R² Z_μ", "in domain"]
    lines += [table(header, body), f"\nCommand: `{record['command']}`"]
    publish(args.section, lines, not args.no_write, page=args.page, record=record)
    return 0


def _with_radii(snaps, radii: np.ndarray):
    """A copy of ``snaps`` with other radii (the positions, box and stated φ unchanged: what an
    experiment knows of its sample)."""
    import dataclasses

    return dataclasses.replace(snaps, radii=np.asarray(radii, dtype=np.float64), contacts=None)


if __name__ == "__main__":
    sys.exit(main())
