"""Flow curves (eta_r, Pi, Z_mu vs sigma) from a directory of trajectory files, optionally against
LF_DEM reference data.

    python -m rheograph.analysis.flow_curves data/flow_curves --out docs \
        --reference data/lfdem_reference/lfdem_phi0.76

writes ``flow_curves.png`` and ``flow_curves.md`` into --out, and with ``--record FILE`` the numbers the
figure plots (:func:`figure_data`) as JSON, from which :func:`draw` redraws it alone.  Seeds of one state
point are pooled: the value is their mean and the error the larger of (spread of seeds / sqrt(n_seeds))
and the propagated block standard errors.  Runs stopped early (wall-clock limit) are included and flagged
by their status and reached strain; shear-jammed runs are listed as such: their viscosity is never
averaged, their pressure and coordination (finite: the loaded static packing) are, where no seed of the
state point flows.
2D and 3D runs are never pooled: a 3D state point is its own row, its N shown as e.g. ``500 (3D)`` (and
the imposed rate of a rate-controlled run, ``500 (3D, rate 0.1)``, whose σ/σ0 in the table is the
measured steady stress η_r γ̇); Π_2D/σ, the 2D convention's pressure, is left empty for a 3D run.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from rheograph.analysis.steady import steady_extras, steady_state_summary
from rheograph.errors import InputError, one_line_errors
from rheograph.io.configurations import DAMAGED_FILE_ERRORS
from rheograph.io.figures import save_png
from rheograph.io.hdf5 import is_trajectory, read_run_info, read_timeseries
from rheograph.io.lfdem import read_lfdem_data
from rheograph.io.pages import write_record
from rheograph.sim.params import scheme_name

KEYS = ("viscosity", "pressure", "z_mu", "z")
# runs whose steady-state window is averaged: finished ones, and runs stopped early (wall-clock limit or
# interruption), which the table flags through their status and reached strain
PARTIAL_OR_DONE = ("completed", "wall_limit", "interrupted")


def state_points(directories) -> list[dict]:
    """One entry per state point (n, phi, stress, mu, disp_max, integrator[-lagged]), seeds pooled.

    A seed counts once: where several files hold the same start (a longer rerun of it, in another
    sweep), the one with the most strain stands for it, since the others repeat its trajectory."""
    groups = defaultdict(dict)
    for directory in directories:
        for path in sorted(Path(directory).rglob("*.h5")):
            if not is_trajectory(path):
                continue
            try:
                info = read_run_info(path)
                p = info["params"]
                # recompute from the time series (the estimator may be newer than the file's summary)
                ts = read_timeseries(path)
                info["summary"] = steady_state_summary(
                    ts["strain"],
                    ts["time"],
                    ts["pressure"],
                    ts["z_mu"],
                    ts["z"],
                    p["stress"],
                    p["steady_state_strain"],
                    **steady_extras(p, ts),
                )
                # the slowest flow recorded in the steady window (one row every output interval): how close a
                # flowing run came to arresting
                rate = ts.get("shear_rate")
                window = ts["strain"] >= p["steady_state_strain"]
                info["slowest_rate"] = (
                    float(rate[window].min()) if rate is not None and window.any() else float("nan")
                )
                # LF_DEM's lagged step control is another discretisation: never pooled with the default;
                # nor are 3D runs with 2D ones, or rate-controlled runs with stress-controlled ones
                scheme = scheme_name(p["integrator"], p.get("lagged_step_control", False))
                rate = p["shear_rate"] if p.get("control", "stress") == "rate" else 0.0
                key = (
                    p["n_particles"], p["phi"], p["stress"], p["mu"], p["disp_max"], scheme,
                    p.get("dim", 2), rate, radii_label(p),
                )  # fmt: skip
                seed = p["seed"]
            except DAMAGED_FILE_ERRORS as exc:  # the file, its parameters or its time series damaged
                raise InputError(
                    f"{path}: cannot be read as a rheograph trajectory ({type(exc).__name__}: {exc}); if "
                    "it is damaged, move it aside and rerun that state point"
                ) from exc
            same_start = groups[key].get(seed)
            if same_start is None or info["strain"] > same_start["strain"]:
                groups[key][seed] = info
    points = []
    for (n, phi, stress, mu, disp, integrator, dim, rate, radii), by_seed in sorted(groups.items()):
        infos = list(by_seed.values())
        point = dict(
            n_particles=n,
            phi=phi,
            stress=stress,
            disp_max=disp,
            mu=mu,
            integrator=integrator,
            dim=dim,
            imposed_rate=rate,  # 0: stress control
            radii=radii,  # "" for the bidisperse default
            statuses=sorted({i["status"] for i in infos}),
            strain=float(np.mean([i["strain"] for i in infos])),
        )
        flowing = [
            i
            for i in infos
            if i["status"] in PARTIAL_OR_DONE and np.isfinite(i["summary"].get("viscosity", np.nan))
        ]
        jammed = [i for i in infos if i["status"] == "jammed"]
        point["jammed"] = bool(jammed)
        point["n_runs"], point["n_jammed"] = len(infos), len(jammed)
        point["n_finished"] = sum(i["status"] in ("completed", "jammed") for i in infos)
        # a state point with no flowing seed is described by its jammed runs: their pressure and
        # coordination are finite (the static packing under load), their viscosity is not reported
        source = flowing or jammed
        point["n_seeds"] = len(source)  # seeds that enter the averages (unfinished runs are listed)
        # [σ0/η0]; over the flowing runs only (an arrested run's rate falls to zero by definition)
        rates = [i["slowest_rate"] for i in flowing if np.isfinite(i["slowest_rate"])]
        point["slowest_rate"] = min(rates, default=float("nan"))
        for k in KEYS:
            vals = np.array([i["summary"][k] for i in source])
            ses = np.array([i["summary"][k + "_se"] for i in source])
            # a run that jammed before the steady window has no steady values: it counts as jammed only
            keep = np.isfinite(vals)
            vals, ses = vals[keep], ses[keep]
            if vals.size == 0 or (k == "viscosity" and not flowing):
                point[k] = point[k + "_se"] = float("nan")
                continue
            spread = vals.std(ddof=1) / np.sqrt(vals.size) if vals.size > 1 else 0.0
            point[k] = float(vals.mean())
            point[k + "_se"] = float(max(spread, np.sqrt((ses**2).sum()) / vals.size))
        points.append(point)
    return points


def reference_points(directory, strain_min: float = 1.0) -> list[dict]:
    """LF_DEM data_N*_phi*_s*_disp*.dat files summarised with the same estimator as rheograph runs."""
    pattern = r"data_N(\d+)_phi([\d.]+)_s([\d.]+)_disp([\d.e-]+)\.dat"
    found = sorted(Path(directory).glob("data_*.dat"))
    files = [(p, m) for p, m in ((p, re.match(pattern, p.name)) for p in found) if m]
    if not files:
        naming = "data_N<N>_phi<phi>_s<stress>_disp<disp_max>.dat"
        raise InputError(
            f"--reference {directory}: "
            + (
                "no such directory"
                if not Path(directory).is_dir()
                else f"its data_*.dat files are not named {naming}, the naming the state point is read "
                "from: rename them"
                if found
                else f"no LF_DEM data files ({naming}) there"
            )
        )
    out = []
    for path, m in files:
        d = read_lfdem_data(path)
        stress = float(m.group(3))
        s = steady_state_summary(d["strain"], d["time"], d["pressure"], d["z_mu"], d["z"], stress, strain_min)
        # column 23 is the mean dt of the output interval ending at that row: steps = interval / mean dt
        sel = d["strain"] >= strain_min
        t, dt = d["time"][sel], d["dt"][sel]
        span = d["strain"][sel][-1] - d["strain"][sel][0] if sel.sum() > 1 else 0.0
        s["steps_per_strain"] = float(np.sum(np.diff(t) / dt[1:]) / span) if span > 0 else float("nan")
        out.append(
            dict(
                n_particles=int(m.group(1)),
                phi=float(m.group(2)),
                stress=stress,
                disp_max=float(m.group(4)),
                strain=float(d["strain"][-1]),
                **s,
            )
        )
    return out


def radii_label(params: dict) -> str:
    """How a run's radii were made, where not the bidisperse default (""): ``polydisperse 0.05`` or
    ``radii of <file name>``; runs of other radii are never pooled."""
    radii = params.get("radii", "bidisperse")
    if radii == "polydisperse":
        return f"polydisperse {params['polydispersity']:g}"
    if radii == "file":
        return f"radii of {Path(str(params['radii_file'])).name}"
    return ""


def system_label(point: dict) -> str:
    """N of a flow-curve point, with its dimension and imposed rate where it is not a 2D stress-controlled
    run, or the radii where not bidisperse: ``400``, ``500 (3D)``, ``500 (3D, rate 0.1)``,
    ``400 (polydisperse 0.05)``."""
    notes = ["3D"] if point.get("dim", 2) == 3 else []
    if point.get("imposed_rate", 0.0):
        notes.append(f"rate {point['imposed_rate']:g}")
    if point.get("radii"):
        notes.append(point["radii"])
    return f"{point['n_particles']}" + (f" ({', '.join(notes)})" if notes else "")


def markdown_table(points, reference=()) -> str:
    lines = [
        "| N | φ | σ/σ0 | disp_max | integrator | seeds | strain | η_r | Π/σ | Π_2D/σ (=1.5Π/σ) | Z_μ | Z "
        "| status |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for p in points:
        # under rate control the stress is measured, not imposed: sigma = eta_r * rate
        rate = p.get("imposed_rate", 0.0)
        p = {**p, "stress": p["viscosity"] * rate} if rate else p
        # the 2D monolayer's pressure convention (sigma_zz = 0) has no meaning for a 3D suspension
        pressure_2d = "–" if p.get("dim", 2) == 3 else f"{1.5 * p['pressure'] / p['stress']:.3f}"
        if p["jammed"] and not np.isfinite(p["viscosity"]):
            vals = (
                f"shear-jammed | {p['pressure'] / p['stress']:.3f} | "
                f"{pressure_2d} | {p['z_mu']:.2f} ± {p['z_mu_se']:.2f} | "
                f"{p['z']:.2f}"
            )
        else:
            vals = (
                f"{p['viscosity']:.1f} ± {p['viscosity_se']:.1f} | {p['pressure'] / p['stress']:.3f} | "
                f"{pressure_2d} | {p['z_mu']:.2f} ± {p['z_mu_se']:.2f} | "
                f"{p['z']:.2f}"
            )
        lines.append(
            f"| {system_label(p)} | {p['phi']:g} | {p['stress']:g} | {p['disp_max']:g} | "
            f"{p['integrator']} | {p['n_seeds']} | {p['strain']:.1f} | {vals} | "
            f"{','.join(p['statuses'])} |"
        )
    if reference:
        lines += [
            "",
            "LF_DEM reference (same estimator, strain ≥ 1):",
            "",
            "| N | φ | σ/σ0 | disp_max | strain | η_r | Π/σ | Π_2D/σ | Z_μ | Z |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in reference:
            lines.append(
                f"| {r['n_particles']} | {r['phi']:g} | {r['stress']:g} | {r['disp_max']:g} | "
                f"{r['strain']:.1f} | {r['viscosity']:.1f} ± {r['viscosity_se']:.1f} | "
                f"{r['pressure'] / r['stress']:.3f} | {1.5 * r['pressure'] / r['stress']:.3f} | "
                f"{r['z_mu']:.2f} | {r['z']:.2f} |"
            )
    return "\n".join(lines) + "\n"


# what the figure plots of a state point (its series, its position and its three means with their errors)
FIGURE_KEYS = ("phi", "disp_max", "integrator", "dim", "imposed_rate", "radii", "stress", "jammed")
PLOTTED = ("viscosity", "pressure", "z_mu")
DPI = 120  # dots per inch of flow_curves.png


def figure_data(points, reference=()) -> dict:
    """The numbers :func:`draw` plots: ``points`` (state points, :func:`state_points`) and ``reference``
    (LF_DEM's, :func:`reference_points`) reduced to their series keys, σ/σ0 and the means ± standard
    errors of η_r, Π/σ0 and Z_μ (JSON-serialisable: the figure's record)."""
    values = [k for key in PLOTTED for k in (key, key + "_se")]
    return {
        "points": [{**{k: p.get(k, "") for k in FIGURE_KEYS}, **{k: p[k] for k in values}} for p in points],
        "reference": [{k: r[k] for k in ("phi", "disp_max", "stress", *values)} for r in reference],
    }


def draw(data: dict):
    """The flow-curve figure of :func:`figure_data`'s numbers: η_r, Π and Z_μ against σ/σ0, one line per
    (φ, disp_max, integrator, dimension, imposed rate, radii), LF_DEM's points hollow triangles."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4.9))
    series = defaultdict(list)
    for p in data["points"]:
        key = (p["phi"], p["disp_max"], p["integrator"], p["dim"], p["imposed_rate"], p["radii"])
        series[key].append(p)
    for (phi, disp, integrator, dim, rate, radii), pts in sorted(series.items()):
        pts = sorted(pts, key=lambda q: q["stress"])
        s = np.array([q["stress"] for q in pts])
        label = f"φ={phi:g} (disp_max {disp:g}, {integrator})"
        label += ", 3D" if dim == 3 else ""
        label += f", rate {rate:g}" if rate else ""
        label += f", {radii}" if radii else ""
        if all(q["jammed"] for q in pts):
            label += ", shear-jammed"
        for ax, key in zip(axes, PLOTTED):
            y = np.array([q[key] for q in pts])
            e = np.array([q[key + "_se"] for q in pts])
            ax.errorbar(s, y, yerr=e, marker="o", capsize=3, label=label)
        jam = [q["stress"] for q in pts if q["jammed"]]
        if jam:
            axes[0].plot(jam, [axes[0].get_ylim()[1]] * len(jam), "kx", label=f"φ={phi:g} shear-jammed")
    reference = data["reference"]
    for r_disp in sorted({r["disp_max"] for r in reference}):
        ref = sorted((r for r in reference if r["disp_max"] == r_disp), key=lambda q: q["stress"])
        s = np.array([r["stress"] for r in ref])
        for ax, key in zip(axes, PLOTTED):
            ax.errorbar(
                s,
                [r[key] for r in ref],
                yerr=[r[key + "_se"] for r in ref],
                fmt="^",
                mfc="none",
                capsize=2,
                label=f"LF_DEM φ={ref[0]['phi']:g} disp_max {r_disp:g}",
            )
    for ax, label, logy in zip(axes, ("η_r", "Π / σ0  (−tr σ / 3)", "Z_μ"), (True, True, False)):
        ax.set_xscale("log")
        if logy:
            ax.set_yscale("log")
        ax.set_xlabel("σ / σ0")
        ax.set_ylabel(label)
    # one legend below the panels: inside one it would cover the densest (highest) curves
    handles, labels = axes[0].get_legend_handles_labels()
    rows = -(-len(labels) // 3)
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0.032 * rows + 0.01, 1, 1))
    return fig


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("directories", nargs="+", help="directories searched recursively for trajectory files")
    ap.add_argument("--out", required=True, help="output directory for flow_curves.png / flow_curves.md")
    ap.add_argument("--reference", help="directory of LF_DEM data_*.dat files to compare with")
    ap.add_argument("--record", help="JSON file to keep the figure's numbers in (what redraws it)")
    args = ap.parse_args(argv)
    reference = reference_points(args.reference) if args.reference else []
    points = state_points(args.directories)
    if not points:
        raise InputError(f"no rheograph trajectory files under {args.directories}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    data = figure_data(points, reference)
    save_png(draw(data), out / "flow_curves.png", DPI, drawn_from=data)
    if args.record:
        command = "python -m rheograph.analysis.flow_curves " + " ".join(
            argv if argv is not None else sys.argv[1:]
        )
        write_record(Path(args.record), {"command": command, "figure": data})
    table = markdown_table(points, reference)
    (out / "flow_curves.md").write_text(table)
    print(table)
    print(f"wrote {out / 'flow_curves.png'} and {out / 'flow_curves.md'}")


if __name__ == "__main__":
    with one_line_errors("python -m rheograph.analysis.flow_curves"):
        main()
