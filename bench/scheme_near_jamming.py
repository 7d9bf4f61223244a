"""Near jamming the time-stepping scheme decides the physics: phi = 0.80, N = 400, eta_r(strain) from one
and the same initial configuration for explicit Euler and linearly implicit springs at decreasing disp_max.

    python -m bench.scheme_near_jamming run  [--stress 50 10] [--seeds 1 2] [--strain 1]
                                             [--schemes euler:1e-3 euler:5e-4 euler:2.5e-4 implicit:2e-3 ...]
                                             [--max-wall 1800]
    python -m bench.scheme_near_jamming plot  # the table's record (with the figure's curves), the figure

Every (seed, stress, scheme, disp_max) is one resumable trajectory under data/scheme_phi080/<run name>/
(the layout simulate.py writes, so runs made with ``python simulate.py ... output_root=data/scheme_phi080``
are picked up).  ``--max-wall`` bounds one invocation of one run (wall seconds); rerunning the command
resumes the unfinished ones.  A run ends early when the flow stops (status ``jammed``: apparent viscosity
above ``jam_viscosity`` for ``jam_intervals`` output intervals).  The verdict per (seed, stress) is read
off the finest discretisation of each scheme.  ``plot`` keeps the table and the curves the figure draws in
the section's record, docs/results/bench/scheme_near_jamming.json, from which it draws the page's section
and docs/figures/scheme_near_jamming.png (as ``python -m bench.render`` does); ``--no-write`` prints the
table and writes nothing.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_THREAD_LIMIT", "1")  # CHOLMOD's OpenMP (see simulate.py)

import numpy as np  # noqa: E402

from bench.publishing import Section, command_line, publish  # noqa: E402
from rheograph.io.figures import significant  # noqa: E402
from rheograph.io.hdf5 import read_run_info, read_timeseries  # noqa: E402
from rheograph.naming import run_name  # noqa: E402
from rheograph.runs.runner import run_state_point  # noqa: E402
from rheograph.sim.params import SimParams, scheme_name, scheme_settings  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "data" / "scheme_phi080"
HEADER = (
    "σ/σ0",
    "seed",
    "scheme",
    "disp_max",
    "status",
    "strain reached",
    "η_r = σ Δt/Δγ before jamming",
    "η_r, 0.1-strain blocks from 0.2 (± s.e.)",
    "steps/strain",
    "CPU s",
)
# the invocations that made the committed runs (the published section quotes them to reproduce its table)
RUNS = (
    "python -m bench.scheme_near_jamming run --stress 50 --seeds 1",
    "python -m bench.scheme_near_jamming run --stress 50 --seeds 2 --schemes implicit:2e-3 implicit:1e-3 "
    "implicit:5e-4",
    "python -m bench.scheme_near_jamming run --stress 10 --seeds 1 --schemes euler:5e-4 euler:2.5e-4 "
    "implicit:2e-3 implicit:1e-3 implicit:5e-4",
)
DEFAULT_SCHEMES = [
    "euler:1e-3",
    "euler:5e-4",
    "euler:2.5e-4",
    "implicit:2e-3",
    "implicit:1e-3",
    "implicit:5e-4",
]


def parse_scheme(text: str) -> tuple[str, float]:
    """``"euler:5e-4"`` -> ("euler", 5e-4)."""
    name, _, disp = text.partition(":")
    if not disp:
        raise SystemExit(f"--schemes: expected scheme:disp_max (e.g. euler:5e-4), got {text!r}")
    return name, float(disp)


def trajectory_path(params: SimParams) -> Path:
    return OUT / run_name(params) / "trajectory.h5"


def run(args) -> None:
    for seed in args.seeds:
        for stress in args.stress:
            for text in args.schemes:
                scheme, disp = parse_scheme(text)
                params = SimParams(
                    n_particles=400,
                    phi=args.phi,
                    stress=stress,
                    seed=seed,
                    strain=args.strain,
                    disp_max=disp,
                    **scheme_settings(scheme),
                    snapshot_interval=0.1,
                    max_wall_seconds=args.max_wall,
                )
                path = trajectory_path(params)
                path.parent.mkdir(parents=True, exist_ok=True)
                if path.exists():
                    info = read_run_info(path)
                    finished = info["status"] == "completed" and info["strain"] >= args.strain - 1e-9
                    if finished or info["status"] in ("jammed", "diverged"):
                        print(path.parent.name, info["status"], "(done)", flush=True)
                        continue
                outcome = run_state_point(params, path, progress=False)
                print(path.parent.name, outcome.status, f"strain {outcome.strain:.3f}", flush=True)


def collect(phi: float) -> list[dict]:
    rows = []
    for path in sorted(OUT.glob("*/trajectory.h5")):
        try:
            info = read_run_info(path)
        except OSError:  # being written by a running simulation
            print(f"skipped {path.parent.name}: in use by a running simulation")
            continue
        p = info["params"]
        if abs(p["phi"] - phi) > 1e-9:
            continue
        ts = read_timeseries(path)
        strain, time = ts["strain"], ts["time"]
        flowing = ~ts["jammed"][1:].astype(bool) & (np.diff(strain) > 0)
        # apparent viscosity of each output interval, sigma dt / d(strain): the instantaneous column is
        # sigma / (shear rate at one step), which changes sign when the packing rattles at a standstill
        interval_viscosity = p["stress"] * np.diff(time) / np.maximum(np.diff(strain), 1e-12)
        d_time, d_strain = np.diff(time)[flowing].sum(), np.diff(strain)[flowing].sum()
        # the same over 0.1-strain blocks after the first 0.2 strain, for a mean with a standard error
        blocks = []
        for low in np.arange(0.2, strain[-1] - 0.1 + 1e-9, 0.1) if len(strain) else []:
            rows_in = np.flatnonzero((strain >= low) & (strain < low + 0.1))
            if rows_in.size > 2 and strain[rows_in[-1]] > strain[rows_in[0]]:
                span = strain[rows_in[-1]] - strain[rows_in[0]]
                blocks.append(p["stress"] * (time[rows_in[-1]] - time[rows_in[0]]) / span)
        rows.append(
            dict(
                seed=p["seed"],
                stress=p["stress"],
                scheme=scheme_name(p["integrator"], p.get("lagged_step_control", False)),
                disp_max=p["disp_max"],
                status=info["status"],
                strain_reached=float(strain[-1]) if len(strain) else 0.0,
                strain=strain[1:][flowing],
                viscosity=interval_viscosity[flowing],
                mean_viscosity=float(p["stress"] * d_time / d_strain) if d_strain > 0 else float("nan"),
                block_viscosity=(
                    (float(np.mean(blocks)), float(np.std(blocks, ddof=1) / np.sqrt(len(blocks))))
                    if len(blocks) > 2
                    else (float("nan"), float("nan"))
                ),
                steps_per_strain=float(ts["steps"][-1] / strain[-1]) if len(strain) else float("nan"),
                cpu_seconds=float(info["summary"].get("cpu_seconds", float("nan"))),
            )
        )
    return rows


def figure_data(rows: list[dict], phi: float) -> dict:
    """The numbers :func:`bench.figures.draw_scheme_near_jamming` plots: per run its (seed, σ/σ0, scheme,
    disp_max, status) and the strain and apparent viscosity of its flowing output intervals (6 digits)."""
    keys = ("seed", "stress", "scheme", "disp_max", "status")
    runs = [
        {
            **{k: r[k] for k in keys},
            "strain": significant(r["strain"], 6),
            "viscosity": significant(r["viscosity"], 6),
        }
        for r in rows
    ]
    return {"phi": phi, "runs": runs}


def plot(args) -> None:
    rows = collect(args.phi)
    if not rows:
        raise SystemExit(f"no runs at phi = {args.phi} under {OUT}")
    # the record keeps the figure's curves too: publishing it draws docs/figures/scheme_near_jamming.png
    publish(
        "scheme_near_jamming",
        section(rows),
        not args.no_write,
        record={"figure": figure_data(rows, args.phi)},
        command=command_line("scheme_near_jamming"),
    )


def table_rows(rows: list[dict]) -> list[list[str]]:
    """The published cells, one row per run: stress descending, then seed, scheme and step descending."""
    out = []
    for r in sorted(rows, key=lambda r: (-r["stress"], r["seed"], r["scheme"], -r["disp_max"])):
        mean, se = r["block_viscosity"]
        out.append(
            [
                f"{r['stress']:g}",
                f"{r['seed']}",
                r["scheme"],
                f"{r['disp_max']:g}",
                r["status"],
                f"{r['strain_reached']:.2f}",
                f"{r['mean_viscosity']:.0f}",
                f"{mean:.0f} ± {se:.0f}" if np.isfinite(mean) else "–",
                f"{r['steps_per_strain']:.3g}",
                f"{r['cpu_seconds']:.0f}",
            ]
        )
    return out


def section(rows: list[dict]) -> Section:
    """The published section: the commands that made the committed runs, and the table of every run."""
    out = Section(
        "```bash",
        f"# the {len(rows)} committed runs under data/scheme_phi080/ (resumable; --max-wall per run)",
        *RUNS,
        "python -m bench.scheme_near_jamming plot   # figure (and its record) + table, from the committed "
        "runs alone",
        "```",
        "",
    )
    out.table(HEADER, table_rows(rows))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p_run = sub.add_parser("run")
    p_run.add_argument("--phi", type=float, default=0.80)
    p_run.add_argument("--stress", type=float, nargs="+", default=[50.0, 10.0])
    p_run.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    p_run.add_argument("--schemes", nargs="+", default=DEFAULT_SCHEMES)
    p_run.add_argument("--strain", type=float, default=1.0)
    p_run.add_argument("--max-wall", type=float, default=1800.0)
    p_plot = sub.add_parser("plot")
    p_plot.add_argument("--phi", type=float, default=0.80)
    p_plot.add_argument("--no-write", action="store_true", help="print the table, write no record")
    args = parser.parse_args()
    run(args) if args.command == "run" else plot(args)


if __name__ == "__main__":
    main()
