"""Discs and spheres against the distance to frictional jamming: does the rheology of the 2D monolayer
and of the 3D suspension collapse once the packing fraction is measured from φ_J^μ?

    python -m rheograph.analysis.collapse \\
        --two data/paper/index.json data/jamming/index.json --n-two 400 \\
        --three data/flow_curves_3d/index.json data/jamming_3d/index.json --n-three 500 \\
        --out docs/jamming.md --record docs/results/bench/collapse_2d_3d.json \\
        --figure docs/figures/collapse_2d_3d.png

Each set's φ_J^μ comes from its own runs through :func:`rheograph.analysis.jamming_points.jamming_table`
with one method for both (``--method``, default the plateau divergence with β = 2, the fit that needs
the fewest packing fractions), so the two distances Δφ = φ_J^μ − φ are measured the same way.  The
steady means of every flowing state point (mean over its seeds) of η_r, Π/σ and Z_μ are compared at
equal stress and equal Δφ: each 3D state point against the 2D curve at its stress interpolated to its
Δφ (linear in log Δφ; in log η_r and log Π/σ, in Z_μ itself), where its Δφ lies within the 2D points'
range at that stress.  The ratios (differences for Z_μ) say what collapses: a ratio near 1 at every
stress is a collapse, one that drifts with Δφ or σ is not.  State points at or beyond φ_J^μ (Δφ ≤ 0)
have no distance to plot and are left out.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from rheograph.analysis.jamming_points import (
    add_mixed_rules_argument,
    docs_page,
    flowing,
    jamming_table,
    read_runs,
    select_rules,
)
from rheograph.errors import InputError, one_line_errors
from rheograph.io.figures import save_png
from rheograph.io.pages import render_blocks, replace_section, table_block, write_record

DPI = 120
DEFAULT_METHOD = "divergence, beta = 2"
QUANTITIES = ("eta", "pressure_ratio", "z_mu")  # eta_r, Pi/sigma, Z_mu
LABELS = {"eta": r"$\eta_r$", "pressure_ratio": r"$\Pi/\sigma$", "z_mu": r"$Z_\mu$"}
LOGARITHMIC = {"eta": True, "pressure_ratio": True, "z_mu": False}
# the isostatic coordination of frictional grains, d + 1: Z_mu measured against it compares discs and
# spheres at the same share of what rigidity needs
ISOSTATIC_FRICTIONAL = {2: 3.0, 3: 4.0}
# Z_mu / (d + 1) is compared where the 2D state point is frictional (below it the ratio of two small
# counts says little)
FRICTIONAL_Z_MU = 1.0


def frictional_jamming_point(
    runs: list[dict], dim: int, n: int, method: str, n_boot: int, single_run_error: bool = False
) -> dict:
    """φ_J^μ of the (dim, N) system of ``runs`` by the jamming-point fit named ``method``: the
    jamming-point row (``phi_j``, its 68 % interval ``phi_j_ci`` over ``n_boot`` bootstrap samples;
    ``single_run_error`` as in ``jamming_points.bootstrap``)."""
    system = [r for r in runs if r["dim"] == dim and r["n"] == n]
    if not system:
        raise InputError(f"no run with dim {dim} and N = {n} in the indexes given for that dimension")
    rows = [
        r
        for r in jamming_table(system, n_boot=n_boot, single_run_error=single_run_error)
        if r["quantity"] == "phi_J^mu" and r["method"] == method and r["dim"] == dim and r["n"] == n
    ]
    if not rows:
        raise InputError(
            f"--method {method!r}: no such phi_J^mu fit for dim {dim}, N = {n} (too few packing "
            "fractions on the high-stress plateau, or a method name not among jamming_points' rows)"
        )
    return rows[0]


def state_means(runs: list[dict], dim: int, n: int, phi_j_mu: float) -> list[dict]:
    """One record per flowing (φ, σ/σ0) state point of the (dim, N) frictional runs: Δφ = φ_J^μ − φ,
    seeds, and the mean over seeds of η_r, Π/σ and Z_μ (state points with Δφ ≤ 0 left out)."""
    groups: dict[tuple[float, float], list[dict]] = {}
    for r in runs:
        if r["dim"] == dim and r["n"] == n and r["mu"] > 0 and flowing(r) and np.isfinite(r["pressure"]):
            groups.setdefault((r["phi"], r["stress"]), []).append(r)
    states = []
    for (phi, stress), members in sorted(groups.items()):
        distance = phi_j_mu - phi
        if distance <= 0:
            continue
        states.append(
            {
                "phi": phi,
                "stress": stress,
                "distance": distance,
                "seeds": len(members),
                "eta": float(np.mean([r["eta"] for r in members])),
                "pressure_ratio": float(np.mean([r["pressure"] / r["stress"] for r in members])),
                "z_mu": float(np.mean([r["z_mu"] for r in members])),
            }
        )
    return states


def interpolate(curve: list[dict], distance: float, key: str) -> float:
    """The 2D ``key`` at ``distance`` from the state points of one stress (linear in log Δφ, in the
    logarithm of η_r and Π/σ); NaN outside their range or with fewer than two points."""
    if len(curve) < 2:
        return np.nan
    x = np.log([s["distance"] for s in curve])
    order = np.argsort(x)
    x = x[order]
    y = np.array([s[key] for s in curve])[order]
    at = np.log(distance)
    if not x[0] <= at <= x[-1]:
        return np.nan
    if LOGARITHMIC[key]:
        return float(np.exp(np.interp(at, x, np.log(y))))
    return float(np.interp(at, x, y))


def matched(two: list[dict], three: list[dict]) -> list[dict]:
    """Each 3D state point with the 2D values at its stress and Δφ, and the 3D/2D ratio of η_r and Π/σ
    and the 3D − 2D difference of Z_μ; only those whose Δφ lies within the 2D range at that stress."""
    rows = []
    for s3 in three:
        curve = [s for s in two if s["stress"] == s3["stress"]]
        values = {key: interpolate(curve, s3["distance"], key) for key in QUANTITIES}
        if not np.isfinite(values["eta"]):
            continue
        rows.append(
            {
                "stress": s3["stress"],
                "phi": s3["phi"],
                "distance": s3["distance"],
                "three": {key: s3[key] for key in QUANTITIES},
                "two": values,
                "eta_ratio": s3["eta"] / values["eta"],
                "pressure_ratio": s3["pressure_ratio"] / values["pressure_ratio"],
                "z_mu_difference": s3["z_mu"] - values["z_mu"],
                # against each dimension's isostatic frictional coordination d + 1
                "z_mu_isostatic_ratio": (s3["z_mu"] / ISOSTATIC_FRICTIONAL[3])
                / (values["z_mu"] / ISOSTATIC_FRICTIONAL[2]),
            }
        )
    return rows


def fraction(side: dict) -> str:
    low, high = side["phi_j_mu_interval"]
    return f"{side['phi_j_mu']:.4f} ({low:.4f}–{high:.4f})"


def section_blocks(data: dict, command: str) -> list[dict]:
    """The published section: the jamming points used, one row per matched 3D state point and a
    summary row of the ratios (median and range)."""
    intro = (
        f"φ_J^μ ({data['method']}; 68 % bootstrap interval): "
        f"2D N = {data['two']['n']} {fraction(data['two'])}, 3D N = {data['three']['n']} "
        f"{fraction(data['three'])}.  "
        f"{len(data['matched'])} of {len(data['three']['states'])} flowing 3D state points lie within "
        "the 2D range of Δφ at their stress.\n"
    )
    header = [
        "σ/σ0",
        "φ (3D)",
        "Δφ",
        "η_r 3D",
        "η_r 2D",
        "ratio",
        "Π/σ 3D",
        "Π/σ 2D",
        "ratio",
        "Z_μ 3D",
        "Z_μ 2D",
        "difference",
    ]
    body = [
        [
            f"{m['stress']:g}",
            f"{m['phi']:g}",
            f"{m['distance']:.4f}",
            f"{m['three']['eta']:.4g}",
            f"{m['two']['eta']:.4g}",
            f"{m['eta_ratio']:.2f}",
            f"{m['three']['pressure_ratio']:.3f}",
            f"{m['two']['pressure_ratio']:.3f}",
            f"{m['pressure_ratio']:.2f}",
            f"{m['three']['z_mu']:.3f}",
            f"{m['two']['z_mu']:.3f}",
            f"{m['z_mu_difference']:+.3f}",
        ]
        for m in data["matched"]
    ]
    summary = []
    if data["matched"]:
        for key, label in (
            ("eta_ratio", "η_r 3D / 2D"),
            ("pressure_ratio", "Π/σ 3D / 2D"),
            ("z_mu_difference", "Z_μ 3D − 2D"),
        ):
            v = np.array([m[key] for m in data["matched"]])
            summary.append([label, f"{np.median(v):.3g}", f"{v.min():.3g}–{v.max():.3g}"])
        frictional = [m for m in data["matched"] if m["two"]["z_mu"] >= FRICTIONAL_Z_MU]
        if frictional:
            v = np.array([m["z_mu_isostatic_ratio"] for m in frictional])
            summary.append(
                [
                    f"Z_μ/(d + 1) 3D / 2D (where 2D Z_μ ≥ {FRICTIONAL_Z_MU:g}: {len(v)} points)",
                    f"{np.median(v):.3g}",
                    f"{v.min():.3g}–{v.max():.3g}",
                ]
            )
    blocks = [{"text": intro}, table_block(header, body)]
    if summary:
        blocks += [{"text": ""}, table_block(["at equal σ and Δφ", "median", "range"], summary)]
    return blocks + [{"text": f"\nCommand: `{command}`"}]


def draw(data: dict):
    """η_r, Π/σ and Z_μ against Δφ = φ_J^μ − φ, discs (circles, solid) and spheres (triangles, dashed),
    coloured by σ/σ0."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    stresses = [s["stress"] for side in ("two", "three") for s in data[side]["states"]]
    norm = LogNorm(min(stresses), max(stresses))
    cmap = plt.get_cmap("viridis")
    fig, axes = plt.subplots(1, 3, figsize=(13.5, 4.0), constrained_layout=True)
    for side, marker, style in (("two", "o", "-"), ("three", "^", "--")):
        states = data[side]["states"]
        for stress in sorted({s["stress"] for s in states}):
            curve = sorted((s for s in states if s["stress"] == stress), key=lambda s: s["distance"])
            x = [s["distance"] for s in curve]
            for ax, key in zip(axes, QUANTITIES):
                ax.plot(x, [s[key] for s in curve], style, marker=marker, ms=4, color=cmap(norm(stress)))
    for ax, key in zip(axes, QUANTITIES):
        ax.set_xscale("log")
        if LOGARITHMIC[key]:
            ax.set_yscale("log")
        ax.set_xlabel(r"$\phi_J^\mu - \phi$")
        ax.set_ylabel(LABELS[key])
    axes[0].plot([], [], "k-o", ms=4, label=f"2D, N = {data['two']['n']}")
    axes[0].plot([], [], "k--^", ms=4, label=f"3D, N = {data['three']['n']}")
    axes[0].legend(fontsize=8, frameon=False)
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=axes, label=r"$\sigma/\sigma_0$")
    return fig


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--two", nargs="+", required=True, help="run indexes of the 2D sets")
    ap.add_argument("--three", nargs="+", required=True, help="run indexes of the 3D sets")
    ap.add_argument("--n-two", type=int, default=400, help="N of the 2D system (default 400)")
    ap.add_argument("--n-three", type=int, default=500, help="N of the 3D system (default 500)")
    ap.add_argument(
        "--method",
        default=DEFAULT_METHOD,
        help=f"the jamming_points fit that gives both phi_J^mu (default {DEFAULT_METHOD!r})",
    )
    ap.add_argument(
        "--bootstrap", type=int, default=400, help="bootstrap samples of the phi_J^mu intervals (default 400)"
    )
    ap.add_argument(
        "--single-run-error",
        action="store_true",
        help="bootstrap: draw the eta_r of a state point with one trajectory from its block standard "
        "error (as jamming_points --single-run-error; default: held fixed)",
    )
    ap.add_argument("--out", help="markdown file whose <!-- collapse_2d_3d:start/end --> section gets it")
    ap.add_argument("--record", help="JSON record of the section and the figure's numbers")
    ap.add_argument("--figure", help="PNG of the three quantities against the distance to jamming")
    add_mixed_rules_argument(ap)
    args = ap.parse_args(argv)
    if args.bootstrap < 10:
        raise InputError(f"--bootstrap {args.bootstrap}: at least 10 samples make a 68 % interval")
    if args.record and not args.out:
        raise InputError("--record: give the page too (--out), whose section the record draws")
    data = {"method": args.method}
    for side, indexes, dim, n in (("two", args.two, 2, args.n_two), ("three", args.three, 3, args.n_three)):
        runs, _ = select_rules(read_runs(indexes), args.mixed_rules)
        if any(r["dim"] != dim for r in runs):
            raise InputError(f"--{side}: {indexes} hold runs of another dimension than {dim}")
        fit = frictional_jamming_point(runs, dim, n, args.method, args.bootstrap, args.single_run_error)
        data[side] = {
            "n": n,
            "phi_j_mu": fit["phi_j"],
            "phi_j_mu_interval": list(fit["phi_j_ci"]),
            "states": state_means(runs, dim, n, fit["phi_j"]),
        }
    data["matched"] = matched(data["two"]["states"], data["three"]["states"])
    command = "python -m rheograph.analysis.collapse " + " ".join(argv if argv is not None else sys.argv[1:])
    blocks = section_blocks(data, command)
    text = render_blocks(blocks)
    print(text)
    if args.out:
        replace_section(Path(args.out), "collapse_2d_3d", text)
    if args.record:
        write_record(
            Path(args.record),
            {
                "section": "collapse_2d_3d",
                "page": docs_page(args.out),
                "command": command,
                "blocks": blocks,
                "figure": data,
            },
        )
    if args.figure:
        save_png(draw(data), Path(args.figure), DPI, drawn_from=data)


if __name__ == "__main__":
    with one_line_errors("python -m rheograph.analysis.collapse"):
        main()
