"""Cost against accuracy in 3D, side by side with LF_DEM: CPU per unit strain and the steady means of each
run from LF_DEM's start (N = 500, φ = 0.56) at one stress, LF_DEM at its step(s) and ours at LF_DEM's
scheme and at the default implicit scheme (with or without elastic unloading), so that the cost at
LF_DEM's discretisation and at equal accuracy can be read off one table.

    python -m bench.lfdem_3d_cost --stress 200 --lfdem s200_disp1e-3 s200_disp5e-4 \\
        --ours data/lfdem_reference_3d/phi0.56_n500/rheograph/s200_*.json

LF_DEM's runs are read from the reference folder (``data_<run>.dat``; its README says how they were made)
with their CPU time from ``lfdem_cpu.json`` there: user + system CPU seconds of the LF_DEM process
sampled every 30 s against the strain it had written (``--log`` adds a run from such a log, the monitor
script's ``unix-time cpu-seconds strain`` lines, over ``--window``).  Ours are the ``--json`` reports of
``python -m bench.vs_lfdem_3d`` (their series, scheme, step and CPU time).  Steady means over strain >=
``--steady`` with 5 block standard errors, the estimator of ``bench.vs_lfdem_3d`` on both sides.  The
table replaces the marked section ``lfdem_3d_cost_<σ>`` of docs/validation/lfdem_3d.md unless
``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from bench.publishing import Section, command_line, publish
from bench.vs_lfdem_3d import (
    CONF,
    REFERENCE,
    SCHEME_LABELS,
    earlier_series,
    lfdem_series,
    read_configuration,
    read_table,
    steady,
)

CPU_FILE = "lfdem_cpu.json"
QUANTITIES = (("viscosity", "η_r"), ("pressure_over_sigma", "Π/σ"), ("z_mu", "Z_μ"))


def cpu_from_log(path: Path, window: tuple[float, float]) -> dict:
    """CPU seconds per strain over ``window`` from a monitor log (``unix-time cpu-seconds strain`` lines,
    lines without a strain skipped), interpolated at the window's ends."""
    rows = []
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if len(parts) == 3:
            rows.append([float(x) for x in parts])
    if len(rows) < 2:
        raise SystemExit(f"--log {path}: fewer than two 'unix-time cpu-seconds strain' lines")
    log = np.array(rows)
    strain, cpu = log[:, 2], log[:, 1]
    lo, hi = window
    if not strain[0] <= lo < hi <= strain[-1]:
        raise SystemExit(
            f"--log {path}: covers strain {strain[0]:g}-{strain[-1]:g}, not --window {lo:g}-{hi:g}"
        )
    spent = np.interp(hi, strain, cpu) - np.interp(lo, strain, cpu)
    return {"cpu_per_strain": float(spent / (hi - lo)), "window": [lo, hi], "source": Path(path).name}


def lfdem_steps_per_strain(data_path: Path, window: tuple[float, float]) -> float:
    """LF_DEM's steps per unit strain over ``window``: the time between its rows divided by the step dt it
    wrote with each (column ``dt``), summed, per strain."""
    names, d = read_table(data_path)
    t, s, dt = d[:, names["time"]], d[:, names["cumulated shear strain"]], d[:, names["dt"]]
    keep = (s >= window[0]) & (s <= window[1])
    t, s, dt = t[keep], s[keep], dt[keep]
    return float(np.sum(np.diff(t) / dt[1:]) / (s[-1] - s[0]))


def lfdem_row(reference: Path, run: str, stress: float, steady_from: float, cpu: dict) -> dict:
    data_path = reference / f"data_{run}.dat"
    if not data_path.is_file():
        raise SystemExit(f"--lfdem {run}: {data_path} not found (gunzip a .gz first)")
    st_path = data_path.with_name(f"st_{run}.dat")
    if not st_path.is_file():
        raise SystemExit(f"--lfdem {run}: {st_path} not found (LF_DEM's st_ file of the run, gunzipped)")
    series = lfdem_series(data_path, st_path, stress, "stress")
    end = float(series["strain"][-1])
    disp = run.split("_disp", 1)[1] if "_disp" in run else "?"
    entry = cpu.get(run)
    return {
        "code": "LF_DEM",
        "scheme": f"{SCHEME_LABELS['euler-lagged']}, {disp}",
        "window": (steady_from, end),
        "steps_per_strain": lfdem_steps_per_strain(data_path, (steady_from, end)),
        "cpu_per_strain": entry["cpu_per_strain"] if entry else None,
        "cpu_window": entry["window"] if entry else None,
        "steady": steady(series, stress, "stress", 0.0, steady_from),
    }


def our_row(path: Path, stress: float, steady_from: float) -> dict:
    report = json.loads(Path(path).read_text())
    kept = report.get("settings", {})
    if kept.get("stress") != stress or kept.get("control") != "stress":
        raise SystemExit(f"--ours {path}: a run at {kept}, not stress control at σ/σ0 = {stress:g}")
    args = argparse.Namespace(**{"solver": "auto", **kept})  # reports before --solver ran by auto
    series, cost = earlier_series(path, args)
    scheme = SCHEME_LABELS[kept["scheme"]]
    # the solver that ran: reports name it; earlier ones ran by auto, which was the direct solver at
    # every N they ran (N <= 2000 before auto took the multigrid solver from N = 2000)
    solver = cost.get("solver") or (kept.get("solver") if kept.get("solver", "auto") != "auto" else "cholmod")
    return {
        "code": "rheograph",
        "scheme": f"{scheme}, {kept['disp_max']:g}, {solver}",
        "window": (steady_from, float(series["strain"][-1])),
        "steps_per_strain": cost.get("steps_per_strain"),
        "cpu_per_strain": cost.get("cpu_per_strain"),
        "cpu_window": cost.get("window"),
        "steady": steady(series, stress, "stress", 0.0, steady_from),
    }


def section(stress: float, start: dict, steady_from: float, rows: list[dict], command: str) -> Section:
    n = start["radii"].shape[0]
    means = "steady means" if steady_from >= 1.0 else f"means over strain ≥ {steady_from:g} (not yet steady)"
    out = Section(
        f"**Cost and accuracy at σ/σ0 = {stress:g}**, every run from LF_DEM's start (N = {n}, "
        f"φ = {start['vf']:g}), one run each, {means} with 5 block standard errors; CPU seconds per strain "
        "on one core "
        "(LF_DEM: its process's user + system time against the strain it wrote; ours: the process's CPU "
        "time over the steps after strain 0.05):",
        "",
    )
    header = ["code", "scheme, disp_max, solver", "steady window", "steps per strain", "CPU s per strain"]
    header += [label for _, label in QUANTITIES]
    cells = []
    for row in rows:
        s = row["steady"]
        cells.append(
            [
                row["code"],
                row["scheme"],
                f"{row['window'][0]:g}–{row['window'][1]:.2f}",
                f"{row['steps_per_strain']:,.0f}" if row["steps_per_strain"] else "–",
                f"{row['cpu_per_strain']:.0f}" if row["cpu_per_strain"] else "not measured",
            ]
            + [f"{s[key]:.4g} ± {s[key + '_se']:.2g}" for key, _ in QUANTITIES]
        )
    out.table(header, cells)
    out.add("", f"Command: `{command}`")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reference", type=Path, default=REFERENCE)
    ap.add_argument("--configuration", default=CONF, help="LF_DEM's start in --reference")
    ap.add_argument("--stress", type=float, help="σ/σ0 of the runs (required unless --log)")
    ap.add_argument("--lfdem", nargs="*", default=[], help="LF_DEM runs <tag> (data_<tag>.dat)")
    ap.add_argument("--ours", nargs="*", type=Path, default=[], help="bench.vs_lfdem_3d --json reports")
    ap.add_argument("--steady", type=float, default=1.0, help="steady window starts at this strain")
    ap.add_argument("--log", type=Path, help="add an LF_DEM run's CPU from this monitor log, then stop")
    ap.add_argument("--tag", help="with --log: the run's tag")
    ap.add_argument("--window", type=float, nargs=2, help="with --log: strain window of the CPU figure")
    ap.add_argument("--section", help="default lfdem_3d_cost_<σ>")
    ap.add_argument("--page", default="validation/lfdem_3d.md")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    cpu_path = args.reference / CPU_FILE
    cpu = json.loads(cpu_path.read_text()) if cpu_path.is_file() else {}
    if args.log is not None:
        if not args.tag or not args.window:
            sys.exit("--log needs --tag (the run) and --window (two strains)")
        cpu[args.tag] = cpu_from_log(args.log, tuple(args.window))
        cpu_path.write_text(json.dumps(cpu, indent=1, sort_keys=True) + "\n")
        print(f"{cpu_path}: {args.tag} {cpu[args.tag]}")
        return 0
    if args.stress is None:
        sys.exit("lfdem_3d_cost: --stress is required (the σ/σ0 of the runs)")
    start_path = args.reference / args.configuration
    if not start_path.is_file():
        sys.exit(f"--configuration {start_path}: not found (LF_DEM's generator output in --reference)")
    start = read_configuration(start_path)
    rows = [lfdem_row(args.reference, run, args.stress, args.steady, cpu) for run in args.lfdem]
    rows += [our_row(path, args.stress, args.steady) for path in args.ours]
    if not rows:
        sys.exit("lfdem_3d_cost: no runs (--lfdem and/or --ours)")
    section_name = args.section or f"lfdem_3d_cost_{args.stress:g}".replace(".", "")
    command = command_line("lfdem_3d_cost", argv)
    publish(
        section_name,
        section(args.stress, start, args.steady, rows, command),
        not args.no_write,
        page=args.page,
        record={"rows": rows},
        command=command,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
