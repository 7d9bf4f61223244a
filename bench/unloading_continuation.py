"""Does elastic unloading change the steady rheology of a committed run?  Continue a trajectory of the 3D
flow-curve set from its last checkpoint with ``sim.elastic_unloading=true`` (or, ``--rule lfdem``, with the
run's own rule, for the step it takes there; the file is read, never written) and compare the continuation's
η_r and Z_μ with the run's own steady values (``rheograph.analysis.steady``, strain >= its
``steady_state_strain``).

    python -m bench.unloading_continuation \\
        data/flow_curves_3d/multirun/N500_phi0.58_s200_seed1_d0.002_implicit_3d/trajectory.h5 --strain 1

η_r of the continuation is σ Δt / Δγ over the whole window (the time average of the rate, as the runner's
steady value), with the standard error of five equal-strain blocks.  A packing at rest never reaches
``--strain``: ``--max-steps`` ends the continuation there and the output says so (``stopped_at_max_steps``);
its median dt and first shear rates show how it steps.  Prints one JSON object; CPU seconds and steps per
strain included; a line per block on stderr as it goes.

``--record SECTION`` keeps the result as one row of the published table ``SECTION`` (its record under
docs/results/bench/, page ``--page`` the first time): a study of one checkpoint at several rules and steps
is built one continuation at a time, each row with the command that made it, the run's own steady values
as the first row.  A row of the same run, rule, step and strain is replaced::

    python -m bench.unloading_continuation RUN --strain 0.5 --disp-max 1e-3 --rule lfdem \\
        --record unloading_convergence_3d --page jamming.md
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

from bench.publishing import Section, command_line, publish, record_path, records_folder
from rheograph.analysis.steady import steady_state_summary
from rheograph.errors import InputError
from rheograph.io.hdf5 import is_trajectory, read_checkpoint, read_timeseries
from rheograph.io.pages import read_record
from rheograph.sim.integrator3d import Simulation3D

BLOCKS = 5
FIRST_RATES = 6  # shear rates of the first steps, printed: a chattering packing alternates their sign


def last_block_viscosity(strain: np.ndarray, t: np.ndarray, span: float, stress: float) -> dict:
    """η_r = σ Δt/Δγ of a run over (at least) the last ``span`` of strain of its time series (``strain``,
    ``t``: its rows): the run's own value just before its checkpoint, to set against a continuation's first
    block (near jamming η_r wanders by several times between windows of 0.1 strain)."""
    # the last row at or before strain[-1] - span: at least ``span``, however sparse the rows
    first = max(int(np.searchsorted(strain, strain[-1] - span, side="right")) - 1, 0)
    return {
        "run_last_block_window": [float(strain[first]), float(strain[-1])],
        "run_last_block_eta_r": float(stress * (t[-1] - t[first]) / (strain[-1] - strain[first])),
    }


def continuation(
    path: Path, strain: float, disp_max: float | None, unloading: bool = True, max_steps: int = 10**6
) -> dict:
    if not is_trajectory(path):
        sys.exit(f"unloading_continuation: {path} is not a rheograph trajectory file")
    try:
        params, state = read_checkpoint(path)
    except InputError as err:
        sys.exit(f"unloading_continuation: {err}")
    if params.DIM != 3:
        sys.exit(f"unloading_continuation: {path} is a 2D run; this benchmark continues 3D runs")
    changed = {"elastic_unloading": unloading, "integrator": "implicit"}
    if disp_max is not None:
        changed["disp_max"] = disp_max
    sim = Simulation3D(dataclasses.replace(params, **changed), state)
    start, cpu0 = state.strain, time.process_time()
    time_total = strain_total = z_mu_weighted = 0.0
    blocks, block_time, block_strain, steps, dts, rates = [], 0.0, 0.0, 0, [], []
    while strain_total < strain and steps < max_steps:
        result = sim.step()
        steps += 1
        dts.append(result.dt)
        rates.append(result.shear_rate)
        d_strain = result.shear_rate * result.dt
        time_total += result.dt
        strain_total += d_strain
        z_mu_weighted += 2.0 * result.n_frictional / params.n_particles * d_strain
        block_time += result.dt
        block_strain += d_strain
        if strain_total >= strain * (len(blocks) + 1) / BLOCKS:
            blocks.append(params.stress * block_time / block_strain)
            block_time = block_strain = 0.0
            # progress on stderr: a continuation near jamming runs for an hour
            print(
                f"unloading_continuation: block {len(blocks)}/{BLOCKS}: strain +{strain_total:.3f}, "
                f"{steps} steps, {time.process_time() - cpu0:.0f} CPU s, eta_r {blocks[-1]:.4g}",
                file=sys.stderr,
                flush=True,
            )
    own = read_timeseries(path)
    steady = steady_state_summary(
        own["strain"], own["time"], own["pressure"], own["z_mu"], own["z"], params.stress,
        params.steady_state_strain,
    )  # fmt: skip
    moved = bool(strain_total > 0.0)
    return {
        "run": str(path),
        "elastic_unloading": unloading,
        "disp_max": sim.params.disp_max,
        "strain_window": [start, start + strain_total],
        "stopped_at_max_steps": bool(strain_total < strain),
        "steps": steps,
        "steps_per_strain": steps / strain_total if moved else float("inf"),
        "median_dt": float(np.median(dts)),
        "first_shear_rates": [float(r) for r in rates[:FIRST_RATES]],
        "cpu_seconds": time.process_time() - cpu0,
        "eta_r": params.stress * time_total / strain_total if moved else float("inf"),
        "eta_r_blocks": blocks,
        "eta_r_se": float(np.std(blocks, ddof=1) / np.sqrt(len(blocks))) if len(blocks) > 1 else float("nan"),
        "z_mu": z_mu_weighted / strain_total if moved else float("nan"),
        "run_eta_r": steady["viscosity"],
        "run_eta_r_se": steady["viscosity_se"],
        "run_z_mu": steady["z_mu"],
        "run_window": [params.steady_state_strain, float(own["strain"][-1])],
        **last_block_viscosity(own["strain"], own["time"], strain / BLOCKS, params.stress),
    }


RULES = {True: "elastic unloading", False: "LF_DEM's"}


def _row_key(result: dict) -> tuple:
    return (result["run"], result["elastic_unloading"], result["disp_max"], round(result["strain_window"][1]
            - result["strain_window"][0], 2))  # fmt: skip


def record_rows(section: str, result: dict, command: str, page: str | None) -> dict:
    """Add ``result`` (with the ``command`` that made it) to the continuations of the published table
    ``section`` (replacing one of the same run, rule, step and strain) and publish the table."""
    if result["stopped_at_max_steps"]:
        sys.exit(f"unloading_continuation: stopped at --max-steps; not recorded in {section}")
    path = record_path(section, records_folder())
    kept = read_record(path, f"record of {section}") if path.exists() else {"continuations": []}
    if "continuations" not in kept:
        sys.exit(f"unloading_continuation: {path} is another benchmark's record; choose another --record")
    kept = kept["continuations"]
    if kept and kept[0]["run"] != result["run"]:
        sys.exit(
            f"unloading_continuation: {section} holds continuations of {kept[0]['run']}; "
            f"record {result['run']} under another --record name"
        )
    rows = [r for r in kept if _row_key(r) != _row_key(result)] + [{**result, "command": command}]
    rows.sort(key=lambda r: (r["elastic_unloading"], -r["disp_max"]))
    first = rows[0]
    sec = Section(
        f"Continuations of `{first['run']}` from its last checkpoint "
        f"(strain {first['strain_window'][0]:.2f}), each with one stick–slip rule and step; "
        "η_r = σ Δt/Δγ over the continuation (± the standard error of five equal-strain blocks) and "
        "the mean of its last four blocks (the first holds the response to a change of rule), Z_μ its "
        "strain average; the first rows are the run's own steady value (`rheograph.analysis.steady`) "
        "and its η_r over the last block-length of strain before the checkpoint.  "
        "CPU: one core of a 2-core machine shared with other runs.",
        "",
    )
    a, b = first["run_last_block_window"]
    table = [[
        f"the run itself ({RULES[False]})", "", f"{first['run_window'][0]:g}–{first['run_window'][1]:.2f}",
        f"{first['run_eta_r']:.0f} ± {first['run_eta_r_se']:.0f}", "", f"{first['run_z_mu']:.2f}", "", "", "",
    ], [
        "the run itself, its last block", "", f"{a:.2f}–{b:.2f}", f"{first['run_last_block_eta_r']:.0f}",
        "", "", "", "", "",
    ]]  # fmt: skip
    for r in rows:
        a, b = r["strain_window"]
        later = np.asarray(r["eta_r_blocks"][1:])
        table.append([
            RULES[r["elastic_unloading"]], f"{r['disp_max']:g}", f"+{b - a:.2f}",
            f"{r['eta_r']:.0f} ± {r['eta_r_se']:.0f}",
            f"{later.mean():.0f} ± {later.std(ddof=1) / np.sqrt(later.size):.0f}" if later.size > 1 else "–",
            f"{r['z_mu']:.2f}", f"{r['steps_per_strain']:.3g}", f"{r['median_dt']:.2g}",
            f"{r['cpu_seconds'] / (b - a):.0f}",
        ])  # fmt: skip
    header = ["rule", "disp_max", "strain", "η_r", "η_r, blocks 2–5", "Z_μ", "steps/strain", "median dt"]
    sec.table([*header, "CPU s/strain"], table)
    sec.add("", "Commands (one per row):", "", *[f"    {r['command']}" for r in rows])
    return publish(section, sec, True, page=page, record={"continuations": rows}, command=None)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("trajectory", type=Path, help="a 3D trajectory file with a checkpoint")
    ap.add_argument("--strain", type=float, default=1.0, help="strain of the continuation")
    ap.add_argument("--disp-max", type=float, default=None, help="another step (default: the run's)")
    ap.add_argument(
        "--rule", choices=("unloading", "lfdem"), default="unloading",
        help="stick-slip rule of the continuation: elastic unloading, or LF_DEM's (the set's own)",
    )  # fmt: skip
    ap.add_argument("--max-steps", type=int, default=10**6, help="end here if --strain is not reached")
    ap.add_argument("--record", metavar="SECTION", help="keep the result as a row of this published table")
    ap.add_argument("--page", help="the docs page of --record's table (the first time)")
    args = ap.parse_args(argv)
    if not args.trajectory.is_file():
        sys.exit(f"unloading_continuation: no trajectory file {args.trajectory}")
    if not args.strain > 0.0:
        sys.exit(f"unloading_continuation: --strain {args.strain} must be > 0")
    if args.max_steps < 1:
        sys.exit(f"unloading_continuation: --max-steps {args.max_steps} must be >= 1")
    if args.page and not args.record:
        sys.exit("unloading_continuation: --page names the page of a --record table; give --record too")
    out = continuation(args.trajectory, args.strain, args.disp_max, args.rule == "unloading", args.max_steps)
    print(json.dumps(out, indent=1))
    if args.record:
        record_rows(args.record, out, command_line("unloading_continuation", argv), args.page)


if __name__ == "__main__":
    main()
