"""Dataset card of a set of trajectory runs: counts, decorrelation, transient, cost, sizes, flow curves,
and the seed paper's Fig. 2 (targets of every snapshot against sigma and shear rate) and Fig. 3
(densities of eta_r and Pi against Z_mu, with marginals).

    python -m rheograph.analysis.dataset_card data/paper --out docs --min-strain 1.0

writes ``dataset.md`` (tables) and ``figures/dataset_fig2.png``, ``figures/dataset_fig3.png`` into --out,
and ``index.json`` (``rheograph.runs.sweep_index``) into the data directory; with ``--record FILE`` also
the numbers the two figures plot (``fig2``: :func:`fig2_data`, ``fig3``: :func:`fig3_data`) as JSON, from
which :func:`draw_fig2` and :func:`draw_fig3` redraw them alone.
"""

from __future__ import annotations

import argparse
import re
import shlex
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from rheograph.analysis.flow_curves import radii_label, state_points
from rheograph.analysis.steady import (
    decorrelation_strain,
    ensemble_transient,
    stall_start,
    transient_strain,
)
from rheograph.errors import InputError, one_line_errors
from rheograph.io.figures import save_png, significant
from rheograph.io.hdf5 import jammed_snapshots, read_run_info, read_snapshot_table, read_timeseries
from rheograph.io.index import USABLE, build_index, write_index
from rheograph.io.pages import write_record
from rheograph.sim.params import SimParams

TARGETS = ("viscosity", "pressure", "z_mu")
# what regenerates the committed paper-scale set (data/paper), quoted in its card
PAPER_SET_COMMANDS = (
    "python simulate.py -m campaign=dataset_paper_n400_phi070_074      # N = 400, phi 0.70-0.74",
    "python simulate.py -m campaign=dataset_paper_n400                 # N = 400, phi 0.76, 0.78",
    "python simulate.py -m campaign=dataset_paper_phi080               # N = 400, phi 0.80 (1e-3)",
    "python simulate.py -m campaign=dataset_paper_n2000 sim.phi=0.70,0.76   # N = 2000, two seeds",
    "python simulate.py -m campaign=dataset_paper_phi080 sim.n_particles=2000 sim.seed=1,2"
    "   # N = 2000, phi 0.80",
)


def run_cpu_seconds(path: str | Path) -> float:
    """CPU seconds a run cost: ``summary/cpu_seconds`` of its file, or, for files written before it was
    recorded, the seconds that simulate.log reports over all invocations (single-threaded runs, one per
    core, so wall time is CPU time).  NaN when neither exists."""
    path = Path(path)
    summary = read_run_info(path)["summary"]
    if "cpu_seconds" in summary:
        return float(summary["cpu_seconds"])
    log = path.parent / "simulate.log"
    if not log.exists():
        return float("nan")
    return sum(float(m) for m in re.findall(r"steps, ([\d.]+) s\)", log.read_text()))


def cpu_seconds_per_decorrelated_snapshot(path: str | Path) -> float:
    """What one independent snapshot of a run cost the simulator: its CPU seconds per unit strain reached
    x the 1/e decorrelation strain of log eta_r over the steady window (at least one output interval)."""
    info, ts = read_run_info(path), read_timeseries(path)
    params = info["params"]
    steady = ts["strain"] >= float(params["steady_state_strain"])
    interval = float(params["output_interval"])
    tau = decorrelation_strain(np.log(np.abs(ts["viscosity"][steady])), interval)
    return run_cpu_seconds(path) / info["strain"] * max(tau, interval)


def run_records(index: dict, min_strain: float) -> list[dict]:
    """Per run: parameters, status, snapshot targets after ``min_strain``, decorrelation and transient
    strains of the instantaneous eta_r (log), Pi and Z_mu, CPU seconds and file size."""
    records = []
    for entry in index["runs"]:
        path = Path(entry["path"])
        p = entry["params"]
        ts = read_timeseries(path)
        sn = read_snapshot_table(path, ("strain", *TARGETS, "shear_rate"))
        strain = ts["strain"]
        series = {
            "viscosity": np.log(np.abs(ts["viscosity"]) + 1e-12),
            "pressure": ts["pressure"],
            "z_mu": ts["z_mu"],
        }
        snap_strain = sn["strain"]
        # an unfinished run whose last rows are each slower than jam_viscosity: stalling, not yet
        # called jammed (the detector's window is not full); the strain where the stall began
        slow = ts["jammed"] if "jammed" in ts else np.zeros(strain.size, dtype=bool)
        stalled_since = stall_start(strain, slow) if entry["status"] not in USABLE else None
        jammed = jammed_snapshots(
            entry["status"], snap_strain, strain, p.get("jam_intervals", SimParams.jam_intervals)
        )
        # as the learning reads them: flowing after the transient, arrested packings at any strain
        flowing_snaps = (snap_strain >= min_strain) & ~jammed
        snaps = {k: sn[k][flowing_snaps] for k in (*TARGETS, "shear_rate")}
        # the static packing under load: what a run that arrested before the steady window reports
        arrested = {k: sn[k][jammed] for k in ("pressure", "z_mu")}
        cpu = run_cpu_seconds(path)
        steady = strain >= p["steady_state_strain"]
        flowing = entry["status"] != "jammed"
        records.append(
            dict(
                n=p["n_particles"],
                dim=p.get("dim", 2),
                phi=p["phi"],
                mu=p["mu"],
                radii=radii_label(p),
                stress=p["stress"],
                seed=p["seed"],
                status=entry["status"],
                snapshots=snaps,
                arrested=arrested,
                n_snapshots=int(flowing_snaps.sum() + jammed.sum()),
                n_flowing_snapshots=int(flowing_snaps.sum()),
                n_jammed_snapshots=int(jammed.sum()),
                snapshot_interval=p["snapshot_interval"],
                decorrelation={
                    k: decorrelation_strain(v[steady], p["output_interval"]) if flowing else np.nan
                    for k, v in series.items()
                },
                transient=transient_strain(strain, series["viscosity"], p["steady_state_strain"])
                if flowing
                else np.nan,
                log_viscosity_series=(strain, series["viscosity"], p["stress"]),
                stalled_since=stalled_since,
                cpu_seconds=cpu,
                bytes=path.stat().st_size,
            )
        )
    return records


def _ensemble_transient_cells(runs: list[dict], min_strain: float) -> str:
    """The ensemble-transient and bias cells of the decorrelation table for the runs of one (N, φ)."""
    series = [r["log_viscosity_series"] for r in runs if r["status"] == "completed"]
    result = ensemble_transient(series, min_strain)
    if not np.isfinite(result["transient"]):
        return "– | –"
    transient = ("≥ " if result["at_ceiling"] else "") + f"{result['transient']:.1f}"
    if result["transient"] <= min_strain:
        return f"{transient} | 0"
    return (
        f"{transient} | {result['bias_mean']:+.3f}; largest {result['bias_largest']:+.3f} "
        f"(σ/σ0 = {result['bias_largest_at']:g})"
    )


def flow_curve_cell(point: dict, key: str, records: list[dict]) -> str:
    """One cell of the flow-curve table: the steady mean ± standard error over seeds; for a state point
    whose every seed arrested before the steady window, η_r reads "jammed" and Π, Z_μ are the mean ±
    standard error over its arrested-packing snapshots (all seeds pooled), marked "(arrested)"."""
    if np.isfinite(point[key]):
        return f"{point[key]:.4g} ± {point[key + '_se']:.2g}"
    if not point["jammed"]:
        return "–"
    if key == "viscosity":
        return "jammed"
    values = np.concatenate(
        [
            r["arrested"][key]
            for r in records
            if (r["n"], *series_of(r), r["stress"])
            == (point["n_particles"], *series_of(point), point["stress"])
        ]
    )
    if values.size == 0:
        return "jammed (no snapshot)"
    se = values.std(ddof=1) / np.sqrt(values.size) if values.size > 1 else float("nan")
    return f"{values.mean():.4g} ± {se:.2g} (arrested)"


def jamming_onset(runs: list[dict]) -> str:
    """The smallest σ/σ0 at which one seed's runs (records with ``stress`` and ``status``) shear-jammed,
    or ``none up to`` the largest that completed; unfinished runs below the onset leave it open and
    are named, with the strain since which a stalling one's rows are each slower than jam_viscosity."""
    jammed = sorted(r["stress"] for r in runs if r["status"] == "jammed")
    flowed = [r["stress"] for r in runs if r["status"] == "completed"]
    limit = jammed[0] if jammed else np.inf
    open_runs = sorted(
        (r["stress"], r.get("stalled_since"))
        for r in runs
        if r["status"] not in ("jammed", "completed") and r["stress"] < limit
    )
    stalls = "".join(
        f"; {x:g} stalling since strain {since:.2f}" for x, since in open_runs if since is not None
    )
    pending = f" ({', '.join(f'{x:g}' for x, _ in open_runs)} unfinished{stalls})" if open_runs else ""
    if jammed:
        return f"{jammed[0]:g}{pending}"
    return (f"none up to {max(flowed):g}" if flowed else "none yet") + pending


def series_label(phi: float, mu: float, radii: str) -> str:
    """φ as simulated (two decimals at least, no rounding: 0.785 and 0.79 stay apart), with frictionless
    runs (μ = 0) and radii other than the bidisperse default (``radii``: ``radii_label``) marked."""
    text = f"{phi:.2f}" if round(phi, 2) == phi else f"{phi:g}"
    return text + (", μ = 0" if mu == 0.0 else "") + (f", {radii}" if radii else "")


def series_of(entry: dict) -> tuple[float, float, str]:
    """(φ, μ, radii) of a run record or a flow-curve point: the runs one flow curve pools (seeds only)."""
    return entry["phi"], entry["mu"], entry["radii"]


def _median(values) -> str:
    v = np.array([x for x in values if np.isfinite(x)])
    return f"{np.median(v):.3f} ({v.min():.3f}–{v.max():.3f})" if v.size else "–"


def card_markdown(
    records: list[dict], points: list[dict], command: str, min_strain: float, title: str = "Dataset card"
) -> str:
    by_phi_n = defaultdict(list)
    for r in records:
        by_phi_n[(r["n"], *series_of(r))].append(r)
    three_d = [
        "3D suspensions: spheres in a cube, φ a volume fraction (every file's `dim` is 3).",
        "",
    ]
    lines = [
        f"# {title}",
        "",
        *(three_d if any(r.get("dim", 2) == 3 for r in records) else []),  # records without dim: 2D
        "Regenerate (resumable; finished state points are skipped):",
        "",
        "```bash",
        command,
        "```",
        "",
        f"Flowing snapshots count from strain {min_strain:g} on (the start-up transient skipped; a slower "
        "drift of a few per cent that outlasts it at some (N, φ) is measured in the decorrelation table).  "
        "A run whose "
        "flow stops ends with status `jammed` and one last snapshot of the arrested packing; its snapshots "
        "from the start of the stalled window on are labelled jammed (kept at any strain: an arrested "
        "packing is not a transient): their Π and Z_μ (the static packing under load) are valid targets, "
        "their η_r is not.  Its earlier snapshots flowed and count as flowing.",
        "",
        "## Runs and snapshots per (N, φ)",
        "",
        "| N | φ | runs | seeds | completed | jammed | other | flowing snapshots | jammed snapshots "
        "| CPU h | MB |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (n, *series), runs in sorted(by_phi_n.items()):
        status = [r["status"] for r in runs]
        usable = [r for r in runs if r["status"] in USABLE]
        lines.append(
            f"| {n} | {series_label(*series)} | {len(runs)} | {len({r['seed'] for r in runs})} "
            f"| {status.count('completed')} | {status.count('jammed')} "
            f"| {len(runs) - len(usable)} "
            f"| {sum(r['n_flowing_snapshots'] for r in usable)} "
            f"| {sum(r['n_jammed_snapshots'] for r in usable)} "
            f"| {np.nansum([r['cpu_seconds'] for r in runs]) / 3600:.2f} "
            f"| {sum(r['bytes'] for r in runs) / 1e6:.1f} |"
        )
    total_bytes = sum(r["bytes"] for r in records)
    unfinished = [r for r in records if r["status"] not in USABLE]
    lines += [
        "",
        f"{len(records)} runs, {sum(r['n_snapshots'] for r in records if r['status'] in USABLE)} "
        f"snapshots of finished runs, {total_bytes / 1e6:.1f} MB in all.  CPU hours: process CPU time "
        "recorded in each file (`summary/cpu_seconds`), or for older files the seconds in `simulate.log` "
        "(single-threaded runs)."
        + (
            f"  *other*: {len(unfinished)} unfinished run(s) (status "
            f"{', '.join(sorted({r['status'] for r in unfinished}))}; committed with their checkpoint, "
            "resumed by the command above) with "
            f"{sum(r['n_snapshots'] for r in unfinished)} snapshot(s) so far, counted in CPU hours and MB "
            "but not in the snapshot columns; the learning reads finished runs only "
            "(`rheograph.io.index.USABLE`)."
            if unfinished
            else ""
        ),
        "",
        "## Storage",
        "",
        "A run is written raw and, once finished, rewritten compact (`rheograph.io.hdf5.AT_REST`; "
        "`python -m rheograph.runs.sweep_index DIR --out DIR/index.json --compress` converts files of older "
        "versions): gzip + shuffle on everything; snapshot positions quantised to 1e-7 a (HDF5 "
        "scale-offset, error ≤ 5e-8 a, i.e. 10⁻⁴–10⁻³ of the 10⁻⁴–10⁻³ a overlaps that decide contacts; "
        "float32 would err by ~3e-6 a at the ~50 a coordinates of N = 2000, a few % of a small overlap); "
        "tangential spring stretches float32; pair indices int32.  Targets, time series and the "
        "checkpoint are lossless, so every run can be resumed or extended; the graphs of a compact file "
        "have the same edges and contact flags as those of the raw one "
        "(`tests/test_runner.py::test_the_compact_layout_keeps_what_the_learning_and_a_resume_need`).  "
        "Measured: N = 2000, 3 strain, 30 snapshots: 2.34 → 1.33 MB; N = 400: 0.59 → 0.38 MB.",
        "",
        "## Runs per state point (seeds finished / runs; J: jammed)",
        "",
    ]
    stresses = sorted({r["stress"] for r in records})
    for n in sorted({r["n"] for r in records}):
        series = sorted({series_of(r) for r in records if r["n"] == n})
        lines += [
            f"N = {n}:",
            "",
            "| σ/σ0 | " + " | ".join(f"φ = {series_label(*x)}" for x in series) + " |",
            "|---|" + "---|" * len(series),
        ]
        for s in stresses:
            cells = []
            for x in series:
                runs = [r for r in records if r["n"] == n and series_of(r) == x and r["stress"] == s]
                done = sum(r["status"] == "completed" for r in runs)
                jam = sum(r["status"] == "jammed" for r in runs)
                cells.append(f"{done}/{len(runs)}" + (f" J{jam}" if jam else "") if runs else "–")
            lines.append(f"| {s:g} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += [
        "## Decorrelation and start-up transient (flowing runs)",
        "",
        "Decorrelation strain: where the autocorrelation of the instantaneous series (log η_r, Π, Z_μ; "
        "rows every output interval, steady window) first drops below 1/e; median (min–max) over runs.  "
        "Transient: the strain after which 0.1-strain block means of log η_r stay within 2 standard "
        "deviations of the steady ones (searched below the steady window's start, so 1.0 means: not "
        "settled before it in that run).  Ensemble transient: one run cannot resolve a drift of a few per "
        "cent, the runs of an (N, φ) together can (`rheograph.analysis.steady.ensemble_transient`): per run, "
        "0.5-strain block means of log η_r relative to its mean over the second half of its strain beyond "
        f"{min_strain:g}, in units of its standard deviation there; each block tested for a mean offset at "
        "any state point (F test against the scatter between seeds) or of one sign at all (t test over "
        "state points), at 5 % with a Bonferroni bound over blocks; the transient ends with the last "
        "significant block (≥: still drifting at the earliest reference window).  "
        f"Bias from strain {min_strain:g}: what counting each run from strain {min_strain:g} instead of "
        "from the ensemble transient adds to its mean log η_r, mean over runs and the largest over state "
        "points (mean over its seeds; 0.01 is 1 %).  The snapshots of that stretch stay in the learning "
        "set: their targets are their own instantaneous values, right for their configurations whether "
        "or not the run has settled.  "
        "Neighbour correlation: exp(−Δγ/τ) for the snapshot spacing Δγ and the median decorrelation "
        "strain τ of log η_r (1/e at Δγ = τ).",
        "",
        "| N | φ | decorrelation log η_r | decorrelation Π | decorrelation Z_μ | transient "
        f"| ensemble transient | bias from strain {min_strain:g} | snapshot spacing "
        "| neighbour correlation |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (n, *series), runs in sorted(by_phi_n.items()):
        taus = [r["decorrelation"]["viscosity"] for r in runs if np.isfinite(r["decorrelation"]["viscosity"])]
        spacing = np.median([r["snapshot_interval"] for r in runs])
        neighbour = f"{np.exp(-spacing / np.median(taus)):.2f}" if taus else "–"
        lines.append(
            f"| {n} | {series_label(*series)} | "
            + " | ".join(_median([r["decorrelation"][k] for r in runs]) for k in TARGETS)
            + f" | {_median([r['transient'] for r in runs])} | {_ensemble_transient_cells(runs, min_strain)}"
            f" | {spacing:g} | {neighbour} |"
        )
    jam_lines = []
    for (n, *series), runs in sorted(by_phi_n.items()):
        for seed in sorted({r["seed"] for r in runs}):
            onset = jamming_onset([r for r in runs if r["seed"] == seed])
            jam_lines.append(f"| {n} | {series_label(*series)} | {seed} | {onset} |")
    lines += [
        "",
        "## Shear jamming: smallest jammed σ/σ0 per seed",
        "",
        "| N | φ | seed | smallest jammed σ/σ0 |",
        "|---|---|---|---|",
        *jam_lines,
        "",
        "## Thickening: continuous or discontinuous",
        "",
        "From the flow-curve means below (γ̇ = σ/η_r): a steady shear rate that falls while the stress "
        "rises is the S-shaped flow curve of discontinuous shear thickening; stresses where no seed flows "
        "are shear jammed.",
        "",
        "| N | φ | thickening | σ/σ0 where γ̇ falls | σ/σ0 with no flowing seed |",
        "|---|---|---|---|---|",
        *thickening_lines(points),
        "",
        "## Flow curves (steady means over seeds ± standard error)",
        "",
        "| N | φ | σ/σ0 | seeds | η_r | Π / σ0 | Z_μ |",
        "|---|---|---|---|---|---|---|",
    ]
    for pt in points:
        cells = [flow_curve_cell(pt, k, records) for k in TARGETS]
        # a point averaged over an unfinished run is provisional: said in the seeds column
        seeds = f"{pt['n_seeds']}" + ("" if set(pt["statuses"]) <= set(USABLE) else " (unfinished)")
        lines.append(
            f"| {pt['n_particles']} | {series_label(*series_of(pt))} | {pt['stress']:g} | {seeds} | "
            + " | ".join(cells)
            + " |"
        )
    lines += [
        "",
        "## Figures",
        "",
        "Seed paper Fig. 2, one row per N (one point per flowing snapshot after the transient; crosses: "
        "arrested packings, Π and Z_μ only; lines: the steady means of the table above; η_r against σ/σ0 "
        "and against γ̇/γ̇0 — where the line bends back, the S-shape —, Π and Z_μ against σ/σ0):",
        "",
        "![fig2](figures/dataset_fig2.png)",
        "",
        "Seed paper Fig. 3 (density of η_r and Π against Z_μ per φ, flowing snapshots of both N, with "
        "the marginals of Z_μ above and of η_r or Π beside):",
        "",
        "![fig3](figures/dataset_fig3.png)",
        "",
    ]
    return "\n".join(lines)


def thickening_lines(points: list[dict]) -> list[str]:
    """Per (N, phi): where the steady shear rate falls while the stress rises -- the S-shaped flow curve of
    discontinuous shear thickening -- and where no seed flows any more (shear jammed), from the flow-curve
    means (gamma_dot = sigma / eta_r)."""
    by_n_phi = defaultdict(list)
    for pt in points:
        by_n_phi[(pt["n_particles"], *series_of(pt))].append(pt)
    lines = []
    for (n, *series), pts in sorted(by_n_phi.items()):
        pts = sorted(pts, key=lambda q: q["stress"])
        rate = {q["stress"]: q["stress"] / q["viscosity"] for q in pts if np.isfinite(q["viscosity"])}
        flowing = sorted(rate)
        falls = [
            f"{a:g} → {b:g} (γ̇ {rate[a]:.3g} → {rate[b]:.3g})"
            for a, b in zip(flowing, flowing[1:])
            if rate[b] < rate[a]
        ]
        stopped = [q["stress"] for q in pts if q["jammed"] and not np.isfinite(q["viscosity"])]
        # a flow curve needs two flowing stresses to be called anything
        if falls:
            kind = "discontinuous (S-shape)"
        elif len(flowing) > 1:
            kind = "continuous"
        else:
            kind = "– (one flowing stress)" if flowing else "–"
        lines.append(
            f"| {n} | {series_label(*series)} | {kind} | {', '.join(falls) or '–'} | "
            f"{', '.join(f'{s:g}' for s in stopped) or 'none'} |"
        )
    return lines


def _flow_curve(points, n, series, key):
    """(stresses, steady means) of one flow curve (N and ``series_of``), NaN-free."""
    pts = sorted(
        (q for q in points if q["n_particles"] == n and series_of(q) == series), key=lambda q: q["stress"]
    )
    s = np.array([q["stress"] for q in pts])
    v = np.array([q[key] for q in pts])
    ok = np.isfinite(v)
    return s[ok], v[ok]


FIG2_DPI, FIG3_DPI = 100, 90  # dots per inch of dataset_fig2.png and dataset_fig3.png
FIG3_BINS = 30  # bins per axis of the Fig. 3 densities


def fig2_data(records: list[dict], points: list[dict]) -> dict:
    """The numbers of :func:`draw_fig2`: per N (``sizes``) and (φ, μ, radii) series, the flowing snapshots'
    σ/σ0, η_r, γ̇/γ̇0, Π/σ0 and Z_μ (one entry per snapshot), the arrested snapshots' σ/σ0, Π/σ0 and Z_μ,
    and the steady flow-curve means (σ/σ0 and value per target, NaN-free)."""
    sizes = sorted({r["n"] for r in records})
    series = sorted({series_of(r) for r in records})
    panels = []
    for n in sizes:
        for x in series:
            runs = [r for r in records if r["n"] == n and series_of(r) == x and r["status"] in USABLE]
            if not runs:
                continue
            flowing = [r for r in runs if r["n_flowing_snapshots"]]
            arrested = [r for r in runs if r["n_jammed_snapshots"]]
            panels.append(
                {
                    "n": n,
                    "phi": x[0],
                    "mu": x[1],
                    "radii": x[2],
                    "flowing": _snapshots(
                        flowing, "n_flowing_snapshots", "snapshots", (*TARGETS, "shear_rate")
                    ),
                    "arrested": _snapshots(arrested, "n_jammed_snapshots", "arrested", ("pressure", "z_mu")),
                    "means": {
                        key: [significant(v, 6) for v in _flow_curve(points, n, x, key)] for key in TARGETS
                    },
                }
            )
    return {"sizes": sizes, "series": [list(s) for s in series], "panels": panels}


def _snapshots(runs: list[dict], count: str, table: str, keys) -> dict:
    """σ/σ0 of every snapshot of ``runs`` (``count`` of each) and its ``keys`` of ``table``."""
    out = {"stress": significant(np.concatenate([np.full(r[count], r["stress"]) for r in runs] or [[]]))}
    for key in keys:
        out[key] = significant(np.concatenate([r[table][key] for r in runs] or [[]]))
    return out


def draw_fig2(data: dict):
    """Seed paper Fig. 2 from :func:`fig2_data`, one row per N: flowing snapshots as dots, arrested
    packings (jammed snapshots: Π and Z_μ only) as crosses, the steady flow-curve means as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ns, series = data["sizes"], [tuple(s) for s in data["series"]]
    colours = dict(zip(series, plt.cm.viridis(np.linspace(0, 0.9, len(series)))))
    fig, grid = plt.subplots(len(ns), 4, figsize=(17, 4.0 * len(ns)), squeeze=False)
    rng = np.random.default_rng(0)
    for axes, n in zip(grid, ns):
        for panel in (p for p in data["panels"] if p["n"] == n):
            colour = colours[series_of(panel)]
            snap = {k: np.array(v) for k, v in panel["flowing"].items()}
            if snap["stress"].size:
                s = snap["stress"] * np.exp(rng.normal(0, 0.03, snap["stress"].size))  # side by side
                kw = dict(s=4, alpha=0.35, color=colour)
                axes[0].scatter(s, snap["viscosity"], label=f"φ = {series_label(*series_of(panel))}", **kw)
                axes[1].scatter(snap["shear_rate"], snap["viscosity"], **kw)
                axes[2].scatter(s, snap["pressure"], **kw)
                axes[3].scatter(s, snap["z_mu"], **kw)
            arrested = panel["arrested"]
            if arrested["stress"]:
                kw = dict(s=30, marker="x", color=colour, linewidths=1.2)
                axes[2].scatter(arrested["stress"], arrested["pressure"], **kw)
                axes[3].scatter(arrested["stress"], arrested["z_mu"], **kw)
            stress, eta = (np.array(v) for v in panel["means"]["viscosity"])
            axes[0].plot(stress, eta, "-", color=colour, lw=1.5)
            axes[1].plot(stress / eta, eta, "-", color=colour, lw=1.5)
            for ax, key in ((axes[2], "pressure"), (axes[3], "z_mu")):
                ax.plot(*panel["means"][key], "-", color=colour, lw=1.5)
        labels = [("σ/σ0", "η_r"), ("γ̇/γ̇0", "η_r"), ("σ/σ0", "Π/σ0"), ("σ/σ0", "Z_μ")]
        for ax, (xl, yl) in zip(axes, labels):
            ax.set_xlabel(xl)
            ax.set_ylabel(yl)
            # a size whose every run arrested has no flowing η_r to draw: its panels stay empty, and an
            # empty axis cannot be log-scaled
            if not _has_points(ax):
                continue
            ax.set_xscale("log")
            if yl != "Z_μ":
                ax.set_yscale("log")
        axes[0].set_title(f"N = {n}", loc="left", fontsize=10)
        axes[3].set_title("×: arrested (jammed) packings; lines: steady means", fontsize=8)
        axes[0].legend(fontsize=8, markerscale=3)
    fig.tight_layout()
    return fig


def _has_points(ax) -> bool:
    """Whether an axis holds any drawn point (scatter or line)."""
    return any(len(c.get_offsets()) for c in ax.collections) or any(
        len(line.get_xdata()) for line in ax.get_lines()
    )


def fig3_data(records: list[dict]) -> dict:
    """The numbers of :func:`draw_fig3`: per (φ, μ, radii) series (flowing snapshots of finished runs, all N),
    the counts of (Z_μ, log10 η_r) and of (Z_μ, log10 Π/σ0) in ``FIG3_BINS`` x ``FIG3_BINS`` bins
    (``counts[i][j]``: Z_μ bin i, log bin j) and the bin edges (``FIG3_BINS`` + 1 each); null for a
    series without flowing snapshots."""
    out = []
    for phi, mu, radii in sorted({series_of(r) for r in records}):
        runs = [
            r
            for r in records
            if series_of(r) == (phi, mu, radii) and r["n_flowing_snapshots"] and r["status"] in USABLE
        ]
        densities = {"viscosity": None, "pressure": None}  # a series that never flowed: an empty column
        if not runs:
            out.append({"phi": phi, "mu": mu, "radii": radii, **densities})
            continue
        z = np.concatenate([r["snapshots"]["z_mu"] for r in runs])
        for key in ("viscosity", "pressure"):
            v = np.concatenate([r["snapshots"][key] for r in runs])
            ok = v > 0
            counts, z_edges, log_edges = np.histogram2d(z[ok], np.log10(v[ok]), bins=FIG3_BINS)
            densities[key] = {
                "z_mu_edges": z_edges.tolist(),
                "log_edges": log_edges.tolist(),
                "counts": counts.astype(int).tolist(),
            }
        out.append({"phi": phi, "mu": mu, "radii": radii, **densities})
    return {"series": out}


def draw_fig3(data: dict):
    """Seed paper Fig. 3 from :func:`fig3_data`: density of log η_r and log Π against Z_μ per φ, with the
    marginal of Z_μ above and of η_r or Π beside each panel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series = data["series"]
    fig = plt.figure(figsize=(4.4 * len(series), 7.4))
    ratios = dict(height_ratios=[1, 3, 1, 3], width_ratios=[3, 1] * len(series))
    grid = fig.add_gridspec(4, 2 * len(series), hspace=0.5, wspace=0.35, **ratios)
    for col, entry in enumerate(series):
        for row, key in ((1, "viscosity"), (3, "pressure")):
            density = entry[key]
            if density is None:
                continue
            x, y = np.array(density["z_mu_edges"]), np.array(density["log_edges"])
            counts = np.array(density["counts"], dtype=np.float64)
            main = fig.add_subplot(grid[row, 2 * col])
            top = fig.add_subplot(grid[row - 1, 2 * col], sharex=main)
            side = fig.add_subplot(grid[row, 2 * col + 1], sharey=main)
            main.pcolormesh(x, y, counts.T, cmap="magma_r")
            main.set_xlim(x[0], x[-1])
            main.set_ylim(y[0], y[-1])
            # the marginals are the densities' sums: the histograms of Z_μ and of the log on those bins
            top.hist(x[:-1], bins=x, weights=counts.sum(axis=1), color="grey")
            side.hist(y[:-1], bins=y, weights=counts.sum(axis=0), color="grey", orientation="horizontal")
            top.set_title(f"φ = {series_label(*series_of(entry))}" if row == 1 else "", fontsize=9)
            top.tick_params(labelbottom=False)
            side.tick_params(labelleft=False)
            main.set_xlabel("Z_μ")
            main.set_ylabel("log10 η_r" if key == "viscosity" else "log10 Π/σ0")
    return fig


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data", help="directory of trajectory runs (searched recursively)")
    ap.add_argument("--out", required=True, help="directory for dataset.md and figures/")
    ap.add_argument("--min-strain", type=float, default=1.0)
    ap.add_argument(
        "--command",
        action="append",
        help="a command that regenerates (part of) the set, quoted in the card; repeat for several "
        "(default: the paper-scale set's)",
    )
    ap.add_argument("--title", default="Dataset card", help="the card's heading")
    ap.add_argument("--record", help="JSON file to keep the figures' numbers in (what redraws them)")
    args = ap.parse_args(argv)
    data, out = Path(args.data), Path(args.out)
    if not data.is_dir():
        raise InputError(f"data directory {data} does not exist")
    index = build_index([data])
    if len({entry["params"].get("dim", 2) for entry in index["runs"]}) > 1:
        raise InputError(
            f"{data} holds both 2D and 3D runs: a card describes one dimension (its flow curves and counts "
            "never pool them); card each from its own directory"
        )
    write_index(index, data / "index.json")
    records = run_records(index, args.min_strain)
    if not records:
        raise InputError(f"no rheograph trajectory under {data}")
    (out / "figures").mkdir(parents=True, exist_ok=True)
    points = state_points([data])
    commands = "\n".join(args.command or PAPER_SET_COMMANDS)
    (out / "dataset.md").write_text(card_markdown(records, points, commands, args.min_strain, args.title))
    figures = {"fig2": fig2_data(records, points), "fig3": fig3_data(records)}
    save_png(draw_fig2(figures["fig2"]), out / "figures" / "dataset_fig2.png", FIG2_DPI, figures["fig2"])
    save_png(draw_fig3(figures["fig3"]), out / "figures" / "dataset_fig3.png", FIG3_DPI, figures["fig3"])
    if args.record:
        command = "python -m rheograph.analysis.dataset_card " + shlex.join(
            argv if argv is not None else sys.argv[1:]
        )
        write_record(Path(args.record), {"command": command, **figures})
    print(f"{len(records)} runs -> {out / 'dataset.md'}, {data / 'index.json'}")


if __name__ == "__main__":
    with one_line_errors("python -m rheograph.analysis.dataset_card"):
        main()
