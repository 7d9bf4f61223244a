"""Campaign cost: CPU seconds per unit strain of every committed run, per (N, φ, σ), and the CPU hours a
full grid costs, so that the size of the dataset can be planned.

    python -m bench.campaign_cost [--index data/paper/index.json] \\
        [--extra 'data/scheme_phi080/*/trajectory.h5']

CPU seconds are what each run recorded (``summary/cpu_seconds``: process CPU time over all invocations,
single-threaded), divided by the strain it reached.  Runs were made one per core on this 2-core machine,
sometimes next to training, so they carry the machine's noise (≈ 1.5×).  ``--extra`` adds runs outside
the dataset (the φ = 0.80 scheme study) in a second table, by scheme and disp_max.  Results replace the
``campaign_cost`` section of docs/validation/speed.md unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import glob
from collections import defaultdict
from pathlib import Path

import numpy as np

from bench.publishing import publish, table
from rheograph.analysis.dataset_card import run_cpu_seconds
from rheograph.io.hdf5 import read_run_info
from rheograph.io.index import read_index
from rheograph.sim.params import scheme_name

ROOT = Path(__file__).resolve().parents[1]
SEEDS_PLANNED = {400: 3, 2000: 2}  # the paper-scale grid


def run_row(path: Path, params: dict, status: str, strain: float) -> dict:
    """The state point, outcome and CPU seconds per strain of one run."""
    cpu = run_cpu_seconds(path)  # read once: the file's recorded process CPU time
    return dict(
        n=params["n_particles"],
        phi=round(params["phi"], 4),
        stress=params["stress"],
        seed=params["seed"],
        scheme=scheme_name(params["integrator"], params.get("lagged_step_control", False)),
        disp=params["disp_max"],
        status=status,
        strain=strain,
        planned_strain=params["strain"],  # the experiment's sim.strain
        cpu=cpu,
        cost=cpu / strain if strain > 0 else float("nan"),
    )


def dataset_rows(index_path: Path) -> list[dict]:
    rows = []
    for e in read_index(index_path)["runs"]:
        if e["status"] == "running":
            continue
        try:
            rows.append(run_row(Path(e["path"]), e["params"], e["status"], e["strain"]))
        except OSError:  # locked by a simulation resuming it now: its cost is read once it stops
            print(f"{e['path']}: being written, left out")
    return rows


def extra_rows(pattern: str) -> list[dict]:
    rows = []
    for name in sorted(glob.glob(pattern)):
        try:
            info = read_run_info(name)
        except OSError:  # being written by a running simulation
            continue
        rows.append(run_row(Path(name), info["params"], info["status"], info["strain"]))
    return rows


def render(rows: list[dict], extra: list[dict], command: str) -> list:
    """The section's blocks: the dataset's table, the extra runs' table, the command."""
    by_point = defaultdict(list)
    recorded, planned_strain = defaultdict(float), defaultdict(float)
    for r in rows:
        by_point[(r["n"], r["phi"], r["stress"])].append(r["cost"])
        recorded[(r["n"], r["phi"])] += r["cpu"]
        planned_strain[(r["n"], r["phi"])] = max(planned_strain[(r["n"], r["phi"])], r["planned_strain"])
    sizes = sorted({(n, phi) for n, phi, _ in by_point})
    stresses = sorted({s for _, _, s in by_point})
    # the grid planned at an area fraction: every stress the dataset has there at any N
    planned = {phi: {s for _, p, s in by_point if p == phi} for _, phi in sizes}
    blocks = [
        "CPU seconds per unit strain (median over seeds) of the committed dataset runs (implicit, disp_max "
        "2e-3; 1e-3 at φ = 0.80), per σ/σ0 (–: not simulated at that (N, φ)).  *Recorded*: the CPU hours "
        "the runs at that (N, φ) spent (unfinished ones so far).  *Grid, extrapolated*: the medians × the "
        f"planned seeds (N = 400: {SEEDS_PLANNED[400]}, N = 2000: {SEEDS_PLANNED[2000]}) × the strain "
        "per run (the experiment's `sim.strain`), summed over the stresses the dataset has at that φ — "
        "an upper estimate where runs shear-jam (they stop early), a lower bound (≥) where a planned stress "
        "has no run yet.\n",
    ]
    header = ["N", "φ", *(f"{s:g}" for s in stresses), "strain per run", "recorded CPU h"]
    header.append("grid CPU h, extrapolated")
    body = []
    for n, phi in sizes:
        medians = {
            s: np.nanmedian(by_point[(n, phi, s)]) if (n, phi, s) in by_point else np.nan for s in stresses
        }
        grid = sum(medians[s] for s in planned[phi] if np.isfinite(medians[s]))
        grid *= SEEDS_PLANNED.get(n, 1) * planned_strain[(n, phi)] / 3600
        partial = "≥ " if any(np.isnan(medians[s]) for s in planned[phi]) else ""
        cells = ["–" if np.isnan(medians[s]) else f"{medians[s]:.0f}" for s in stresses]
        body.append(
            [
                f"{n}",
                f"{phi:.2f}",
                *cells,
                f"{planned_strain[(n, phi)]:g}",
                f"{recorded[(n, phi)] / 3600:.2f}",
            ]
            + [f"{partial}{grid:.2f}"]
        )
    blocks.append(table(header, body))
    if extra:
        blocks.append("\nRuns outside the dataset (`--extra`), CPU seconds per unit strain reached:\n")
        header = ["N", "φ", "σ/σ0", "seed", "scheme", "disp_max", "status", "strain", "CPU s/strain"]
        body = []
        for r in sorted(
            extra, key=lambda r: (r["n"], r["phi"], -r["stress"], r["seed"], r["scheme"], -r["disp"])
        ):
            body.append(
                [
                    f"{r['n']}",
                    f"{r['phi']:.2f}",
                    f"{r['stress']:g}",
                    f"{r['seed']}",
                    r["scheme"],
                    f"{r['disp']:g}",
                ]
                + [r["status"], f"{r['strain']:.2f}", f"{r['cost']:.0f}"]
            )
        blocks.append(table(header, body))
    blocks.append(f"\nCommand: `{command}`")
    return blocks


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--index", default="data/paper/index.json")
    ap.add_argument("--extra", default=None, help="glob of further trajectory files (e.g. a scheme study)")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    rows = dataset_rows(ROOT / args.index)
    extra = extra_rows(str(ROOT / args.extra)) if args.extra else []
    command = (
        "python -m bench.campaign_cost --index "
        + args.index
        + (f" --extra '{args.extra}'" if args.extra else "")
    )
    publish("campaign_cost", render(rows, extra, command), write=not args.no_write, command=command)


if __name__ == "__main__":
    main()
