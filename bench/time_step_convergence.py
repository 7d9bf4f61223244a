"""Run time against error: eta_r, Pi, Z_mu and cost vs disp_max at phi = 0.76, N = 400 for three schemes:
explicit Euler with LF_DEM's lagged step control (``euler-lagged``, LF_DEM's discretisation), explicit
Euler with the current-speed step control (``euler``) and linearly implicit springs (``implicit``).

    python -m bench.time_step_convergence run  [--stress 10 200] [--disp 4e-3 2e-3 1e-3 5e-4]
                                               [--schemes euler-lagged euler implicit] [--seeds 1]
    python -m bench.time_step_convergence plot  # the table's record (with the figure's numbers), the figure

Runs are resumable (one trajectory file per point under data/time_step/).  The cost axis is steps per unit
strain: the cost of a step is the same for every scheme (docs/validation/speed.md), and, unlike wall
seconds, it does not depend on the solver backend or on the machine's load; the wall seconds per strain
recorded by this script are listed in the table with the backend that produced them.  ``plot`` keeps the
table and the numbers the figure draws in the section's record, docs/results/bench/time_step_convergence.json,
from which it draws the page's section and docs/figures/time_step_convergence.png (as ``python -m
bench.render`` does); ``--no-write`` prints the table and writes nothing.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_THREAD_LIMIT", "1")  # CHOLMOD's OpenMP (see simulate.py)

import numpy as np  # noqa: E402

from bench.figures import SCHEME_MARKERS  # noqa: E402
from bench.publishing import Section, command_line, publish  # noqa: E402
from rheograph.analysis.flow_curves import reference_points  # noqa: E402
from rheograph.io.hdf5 import read_run_info, read_timeseries  # noqa: E402
from rheograph.naming import run_name  # noqa: E402
from rheograph.runs.runner import run_state_point  # noqa: E402
from rheograph.sim.params import SimParams, scheme_name, scheme_settings  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "data" / "time_step"
SCHEMES = tuple(s for s in SCHEME_MARKERS if s != "LF_DEM")  # the schemes run here, by label
HEADER = (
    "σ/σ0",
    "scheme",
    "disp_max",
    "η_r (± s.e.)",
    "Π/σ",
    "Z_μ",
    "steps/strain",
    "wall s/strain",
    "solver",
)
# the published section's lead: the conditions of the table's runs (the wall seconds' shared machine and
# backends among them), which the runs' files do not record
LEAD = (
    "Command: `python -m bench.time_step_convergence run && python -m bench.time_step_convergence plot` "
    "(φ = 0.76,",
    "N = 400, one seed, 3 strain, averages over strain 0.5–3; LF_DEM's reference runs summarised with the "
    "same",
    "estimator over strain ≥ 0.5; `plot` keeps the figure's numbers with the table in "
    "`docs/results/bench/time_step_convergence.json`, from which",
    "`python -m bench.render` redraws it).  Figure: "
    "[figures/time_step_convergence.png](../figures/time_step_convergence.png)",
    "— η_r, Π/σ and Z_μ against cost for the three schemes and LF_DEM on one plot.  The cost axis is steps "
    "per unit",
    "strain: a step costs the same in every scheme ([speed](speed.md)), and steps, unlike wall seconds, do "
    "not depend on the",
    "solver backend or the machine's load.  The wall seconds below were measured while a second simulation "
    "shared",
    "the machine, with the backend listed (the euler and implicit rows ran with qdldl, the euler-lagged rows "
    "with",
    "CHOLMOD; [speed](speed.md) gives clean per-step costs).",
    "",
    "Schemes: `euler-lagged` = explicit Euler with LF_DEM's step control (`sim.lagged_step_control=true`: dt",
    "bounded by the previous step's pair speeds), `euler` = explicit Euler with the current step's speeds",
    "(default), `implicit` = linearly implicit contact springs (`sim.integrator=implicit`).",
    "",
)


def run(args) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    for seed in args.seeds:
        for stress in args.stress:
            for scheme in args.schemes:
                for disp in args.disp:
                    params = SimParams(
                        n_particles=args.n,
                        phi=args.phi,
                        stress=stress,
                        seed=seed,
                        strain=args.strain,
                        disp_max=disp,
                        **scheme_settings(scheme),
                        snapshot_interval=args.strain,
                        steady_state_strain=args.steady,
                    )
                    path = OUT / (run_name(params) + ".h5")
                    outcome = run_state_point(params, path, progress=False)
                    cost_file = path.with_suffix(".cost.json")
                    if outcome.steps and outcome.wall_seconds > 1.0:
                        prior = json.loads(cost_file.read_text()) if cost_file.exists() else {"wall": 0.0}
                        prior["wall"] += outcome.wall_seconds
                        prior["strain"] = outcome.strain
                        prior["steps"] = outcome.steps
                        cost_file.write_text(json.dumps(prior))
                    print(
                        path.name,
                        outcome.status,
                        {k: round(v, 4) for k, v in outcome.summary.items()},
                        flush=True,
                    )


def collect() -> list[dict]:
    rows = []
    for path in sorted(OUT.glob("*.h5")):
        info = read_run_info(path)
        p = info["params"]
        cost = json.loads(path.with_suffix(".cost.json").read_text())
        ts = read_timeseries(path)
        rows.append(
            dict(
                stress=p["stress"],
                disp_max=p["disp_max"],
                scheme=scheme_name(p["integrator"], p.get("lagged_step_control", False)),
                solver=info["solver"] or "qdldl",  # the only backend before it was recorded
                seed=p["seed"],
                s_per_strain=cost["wall"] / cost["strain"],
                steps_per_strain=cost["steps"] / cost["strain"],
                **{**info["summary"], "max_overlap": float(ts["max_overlap"].max())},
            )
        )
    return rows


def figure_data(rows: list[dict], phi: float, n: int) -> dict:
    """The numbers :func:`bench.figures.draw_time_step_convergence` plots: per run (``rows``, this
    script's and LF_DEM's) its σ/σ0, scheme, disp_max, steps per strain and the means ± standard errors
    of η_r, Π [σ0] and Z_μ."""
    keys = ("stress", "scheme", "disp_max", "steps_per_strain")
    values = [k for key in ("viscosity", "pressure", "z_mu") for k in (key, key + "_se")]
    return {"phi": phi, "n": n, "points": [{k: r[k] for k in (*keys, *values)} for r in rows]}


def plot(args) -> None:
    rows = collect()
    stresses = sorted({r["stress"] for r in rows})
    reference = lfdem_rows(args.reference, args.phi, args.n, stresses, args.steady)
    # the record keeps the figure's numbers too: publishing it draws docs/figures/time_step_convergence.png
    publish(
        "time_step_convergence",
        section(rows + reference),
        not args.no_write,
        record={"figure": figure_data(rows + reference, args.phi, args.n)},
        command=command_line("time_step_convergence"),
    )


def lfdem_rows(reference: str | None, phi: float, n: int, stresses, steady: float) -> list[dict]:
    """LF_DEM's own runs at (``phi``, ``n``) and the stresses compared, summarised with the same estimator
    and window as ours (none where the folder ``reference`` is absent)."""
    if not reference or not Path(reference).is_dir():
        return []
    return [
        {**r, "scheme": "LF_DEM", "solver": "LF_DEM", "s_per_strain": float("nan")}
        for r in reference_points(reference, strain_min=steady)
        if r["phi"] == phi and r["n_particles"] == n and r["stress"] in stresses
    ]


def table_rows(rows: list[dict]) -> list[list[str]]:
    """The published cells: per stress, each scheme (LF_DEM last) from the coarsest step to the finest."""
    order = list(SCHEME_MARKERS)
    out = []
    compared = [r for r in rows if r["scheme"] in order]
    for r in sorted(compared, key=lambda r: (r["stress"], order.index(r["scheme"]), -r["disp_max"])):
        stress = r["stress"]
        wall = f"{r['s_per_strain']:.1f}" if np.isfinite(r["s_per_strain"]) else "–"
        out.append(
            [
                f"{stress:g}",
                r["scheme"],
                f"{r['disp_max']:g}",
                f"{r['viscosity']:.1f} ± {r['viscosity_se']:.1f}",
                f"{r['pressure'] / stress:.3f}",
                f"{r['z_mu']:.2f}",
                f"{r['steps_per_strain']:.0f}",
                wall,
                r["solver"],
            ]
        )
    return out


def section(rows: list[dict]) -> Section:
    """The published section: how the runs were measured and the table of every run (ours and LF_DEM's)."""
    out = Section(*LEAD)
    out.table(HEADER, table_rows(rows))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=("run", "plot"))
    ap.add_argument("--stress", type=float, nargs="+", default=[10.0, 200.0])
    ap.add_argument("--disp", type=float, nargs="+", default=[4e-3, 2e-3, 1e-3, 5e-4])
    ap.add_argument("--schemes", nargs="+", choices=SCHEMES, default=list(SCHEMES))
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--phi", type=float, default=0.76)
    ap.add_argument("--n", type=int, default=400)
    ap.add_argument(
        "--reference",
        default=str(ROOT.parent / "shared" / "reference" / "lfdem_phi0.76"),
        help="directory of LF_DEM data_*.dat files to overlay (skipped if absent)",
    )
    ap.add_argument("--strain", type=float, default=3.0)
    ap.add_argument("--steady", type=float, default=0.5)
    ap.add_argument("--no-write", action="store_true", help="plot: print the table, write no record")
    args = ap.parse_args()
    run(args) if args.mode == "run" else plot(args)


if __name__ == "__main__":
    main()
