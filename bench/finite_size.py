"""Finite-size effects: the steady η_r, Π and Z_μ of the same state points at N = 400 … 20 000, and how
often a run arrests (shear-jams) at each N.

    python -m bench.finite_size data/paper/multirun data/large_n/multirun

Every state point (φ, μ, σ/σ0, disp_max, scheme) simulated at ``--min-sizes`` or more N is a row per
N, with the slowest shear rate its flowing runs recorded: seeds pooled as in the flow curves (mean;
error the larger of the spread of seeds / sqrt(n) and the propagated block standard errors of the
strain window ≥ each run's steady_state_strain), a seed counted once where several sweeps hold it (the
longest run).  Arrested runs are counted, never averaged into
η_r.  Results replace the marked section of docs/jamming.md unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict

import numpy as np
from scipy.stats import binomtest

from bench.publishing import Section, command_line, publish
from bench.publishing import table as table_block


def fmt(value: float, se: float) -> str:
    if not np.isfinite(value):
        return "—"
    digits = max(0, 2 - int(np.floor(np.log10(abs(se))))) if np.isfinite(se) and se > 0 else 3
    digits = min(digits, 4)
    return f"{value:.{digits}f} ± {se:.{digits}f}" if np.isfinite(se) else f"{value:.{digits}f}"


def _two_digits(value: float) -> str:
    """Two significant digits, trailing zeros kept (0.0090, 0.060); — where undefined."""
    return "—" if not np.isfinite(value) else f"{float(f'{value:.2g}'):#.2g}".rstrip(".")


def table(points, min_sizes: int) -> dict:
    """A table block: the steady values of every state point simulated at ``min_sizes`` or more N."""
    by_state = defaultdict(list)
    for p in points:
        by_state[(p["phi"], p["mu"], p["stress"], p["disp_max"], p["integrator"])].append(p)
    header = ["φ", "μ", "σ/σ0", "scheme", "disp_max", "N", "runs (arrested)", "strain", "η_r", "Π/σ0", "Z_μ"]
    header.append("slowest γ̇ η0/σ0")
    body = []
    for (phi, mu, stress, disp, scheme), members in sorted(by_state.items()):
        if len({p["n_particles"] for p in members}) < min_sizes:
            continue
        for p in sorted(members, key=lambda q: q["n_particles"]):
            body.append(
                [f"{phi:g}", f"{mu:g}", f"{stress:g}", scheme, f"{disp:g}", f"{p['n_particles']}"]
                + [f"{p['n_runs']} ({p['n_jammed']})", f"{p['strain']:.2f}"]
                + [fmt(p["viscosity"], p["viscosity_se"]), fmt(p["pressure"], p["pressure_se"])]
                + [fmt(p["z_mu"], p["z_mu_se"]), _two_digits(p["slowest_rate"])]
            )
    return table_block(header, body)


def arrest_table(points, phi: float) -> list[str]:
    """Share of runs that arrested at each (σ, N) at one φ, and per N over the stresses from the arrest
    onset on, with its binomial interval."""
    rows = [p for p in points if np.isclose(p["phi"], phi) and p["mu"] > 0]
    sizes = sorted({p["n_particles"] for p in rows})
    stresses = sorted({p["stress"] for p in rows})
    cells = {(p["stress"], p["n_particles"]): p for p in rows}
    lines = [
        "| σ/σ0 | " + " | ".join(f"N = {n}" for n in sizes) + " |",
        "|---|" + "---|" * len(sizes),
    ]
    for s in stresses:
        out = []
        for n in sizes:
            p = cells.get((s, n))
            if p is None:
                out.append("")
                continue
            unfinished = p["n_runs"] - p["n_finished"]
            out.append(
                f"{p['n_jammed']}/{p['n_finished']}" + (f" (+{unfinished} unfinished)" if unfinished else "")
            )
        lines.append(f"| {s:g} | " + " | ".join(out) + " |")
    onset = min((p["stress"] for p in rows if p["n_jammed"]), default=None)
    if onset is not None:
        # one probability per N over every stress from the smallest at which any run arrested, with the
        # exact (Clopper-Pearson) 68 % binomial interval: seeds and stresses are the trials
        out = []
        for n in sizes:
            above = [p for p in rows if p["n_particles"] == n and p["stress"] >= onset]
            jammed, finished = sum(p["n_jammed"] for p in above), sum(p["n_finished"] for p in above)
            if not finished:
                out.append("")
                continue
            ci = binomtest(jammed, finished).proportion_ci(confidence_level=0.68)
            out.append(f"{jammed / finished:.2f} ({ci.low:.2f}–{ci.high:.2f}) of {finished}")
        lines.append(f"| arrest probability, σ/σ0 ≥ {onset:g} (68 %) | " + " | ".join(out) + " |")
    return lines


def main(argv=None) -> int:
    from rheograph.analysis.flow_curves import state_points

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("directories", nargs="+", help="directories of trajectory files (searched recursively)")
    ap.add_argument("--min-sizes", type=int, default=3, help="state points simulated at this many N or more")
    ap.add_argument("--arrest-phi", type=float, default=0.80, help="φ of the arrest table")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    points = state_points(args.directories)
    out = Section(
        f"Steady values (strain ≥ each run's steady_state_strain) of the state points simulated at "
        f"{args.min_sizes} or more N; mean ± error over seeds and strain blocks; arrested runs counted, "
        "not averaged into η_r (— where every run arrested); slowest γ̇: the lowest shear rate recorded "
        "(every output row) by any flowing run of the state point in that window — how close the flow came "
        "to arresting; a minimum over more seeds or rows tends to be lower.",
        "",
    )
    out.table(**table(points, args.min_sizes)["table"])
    # the arrest table keeps its published form (empty cells of two spaces): prose lines
    out.add(
        "",
        f"Arrested runs / finished runs at φ = {args.arrest_phi:g} (every stress and N simulated there; a "
        "run stopped early decides nothing yet):",
        "",
        *arrest_table(points, args.arrest_phi),
    )
    command = command_line("finite_size", argv)
    out.add("", f"Command: `{command}`")
    publish("finite_size", out, not args.no_write, page="jamming.md", command=command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
