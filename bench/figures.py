"""Every published figure of the docs, drawn from the JSON record of the numbers it plots.

:data:`FIGURES` maps each published PNG (its path under docs/) to the function that draws it and the
record it is drawn from: a file under docs/results/bench/ and the key in it that holds the plotted
numbers.  The table is code: no record chooses which function draws which file.  The benchmark or
analysis that computes the numbers writes the record (its ``command`` says which, and rerunning it
refreshes both record and figure); ``python -m bench.render`` redraws every figure from its record alone.
The figures of the user-facing commands (the dataset card's Fig. 2 and 3, the flow curves, the phase
diagram) are drawn by those commands' own functions, the others by the functions below.

Every PNG is written by :func:`rheograph.io.figures.save_png` with the SHA-256 of the numbers it was
drawn from in a text chunk of the file.  ``python -m bench.render --check`` (:func:`differences`) names
every figure

* linked from a docs page (outside docs/results/, whose training reports train.py writes) that has no
  entry in :data:`FIGURES`,
* whose record, or the key of its numbers, is missing,
* whose committed PNG carries no hash, or the hash of other numbers than its record's (a number changed
  in the record, or a figure drawn from elsewhere),
* that does not draw from its record (redrawn into a temporary folder), or draws at another size in
  pixels than the committed PNG.

Pixels are never compared: the hash ties a figure to its numbers whatever the matplotlib version that
drew it, and cannot go stale silently, since a PNG redrawn from changed numbers carries their hash.
"""

from __future__ import annotations

import re
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.records import DOCS, RECORDS
from rheograph.analysis import collapse, dataset_card, flow_curves, jamming_points
from rheograph.errors import InputError
from rheograph.io.figures import data_hash, drawn_from_hash, png_size, save_png
from rheograph.io.pages import read_record, write_record

# the three targets of the surrogate figures: (key of a score, label)
SCORES = (("r2_log_eta", "log η_r"), ("r2_log_pressure", "log Π"), ("r2_z_mu", "Z_μ"))


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ---- position noise ------------------------------------------------------------------------------------
NOISE_TARGETS = (("R² log η_r", "log η_r"), ("R² log Π", "log Π"), ("R² Z_μ", "Z_μ"))
NOISE_FLOOR = 5e-4  # half the last digit the tables print: an R² shown as 1.000 is drawn here
NOISE_STYLE = {
    "exact model": dict(color="tab:red", marker="x"),
    "exact model, relaxed positions": dict(color="tab:orange", marker="v"),
    "trees on descriptors + σ": dict(color="tab:green", marker="s"),
    "gap shells, ε known": dict(color="tab:purple", marker="D"),
    "imaging model": dict(color="tab:blue", marker="o", linewidth=2.2),
    "lookup: mean at (φ, σ)": dict(color="black", linestyle="--", marker=""),
}


def draw_imaging_noise(data: dict):
    """Unexplained variance 1 − R² (held out) against the position noise ε per coordinate [a], one row
    per ``panels`` entry (its φ, its ``noise`` levels and its ``curves``: a legend ``label`` and the R² per
    ε of each of :data:`NOISE_TARGETS`), one column per target; ε = 0 drawn a decade below the smallest
    ε > 0 on the log axis."""
    plt = _pyplot()
    panels = data["panels"]
    fig, axes = plt.subplots(len(panels), len(NOISE_TARGETS), figsize=(12, 10), sharex=True, squeeze=False)
    for row, panel in enumerate(panels):
        eps = panel["noise"]
        x = np.array([e if e > 0 else min(v for v in eps if v > 0) / 10 for e in eps])
        for col, (metric, title) in enumerate(NOISE_TARGETS):
            ax = axes[row, col]
            for curve in panel["curves"]:
                unexplained = np.maximum(1.0 - np.asarray(curve["r2"][metric]), NOISE_FLOOR)
                ax.plot(x, unexplained, label=curve["label"], **NOISE_STYLE[curve["label"]])
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_ylim(NOISE_FLOOR / 1.5, 5e3)
            ax.set_title(f"φ = {panel['phi']:.2f}: {title}", fontsize=10)
            ax.grid(True, which="major", alpha=0.3)
            ax.set_xticks(x, ["0" if e == 0 else f"{e:g}" for e in eps], rotation=45, fontsize=8)
            ax.minorticks_off()
            if col == 0:
                ax.set_ylabel("1 − R² (held out)")
            if row == len(panels) - 1:
                ax.set_xlabel("position noise ε per coordinate [a]")
    handles = {}
    for ax in axes.flat:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    fig.legend(handles.values(), handles.keys(), loc="lower center", ncol=3, frameon=False)
    fig.suptitle("Imprecise positions, N = 400: unexplained variance against the noise (lower is better)")
    fig.tight_layout(rect=(0, 0.06, 1, 0.97))
    return fig


# ---- time stepping -------------------------------------------------------------------------------------
SCHEME_MARKERS = {"euler-lagged": "^", "euler": "o", "implicit": "s", "LF_DEM": "x"}
SCHEME_COLOURS = {"euler": "tab:red", "implicit": "tab:blue", "euler-lagged": "tab:orange"}


def draw_time_step_convergence(data: dict):
    """η_r, Π/σ and Z_μ (± standard error) against steps per unit strain, one row per σ/σ0 and one line
    per scheme (:data:`SCHEME_MARKERS`), each point labelled with its disp_max; ``points``: one per run
    (``stress``, ``scheme``, ``disp_max``, ``steps_per_strain`` and the means ``viscosity``,
    ``pressure`` [σ0], ``z_mu`` with their ``_se``) at ``phi``, N = ``n``."""
    import matplotlib.ticker

    plt = _pyplot()
    points = data["points"]
    stresses = sorted({p["stress"] for p in points})
    fig, axes = plt.subplots(len(stresses), 3, figsize=(13, 3.6 * len(stresses)), squeeze=False)
    for row_axes, stress in zip(axes, stresses):
        for scheme, marker in SCHEME_MARKERS.items():
            sel = sorted(
                (p for p in points if p["stress"] == stress and p["scheme"] == scheme),
                key=lambda p: -p["disp_max"],
            )
            if not sel:
                continue
            cost = np.array([p["steps_per_strain"] for p in sel])
            for ax, key, scale in zip(row_axes, ("viscosity", "pressure", "z_mu"), (1.0, 1.0 / stress, 1.0)):
                y = np.array([p[key] for p in sel]) * scale
                err = np.array([p[key + "_se"] for p in sel]) * scale
                ax.errorbar(cost, y, yerr=err, marker=marker, capsize=3, label=scheme)
                for c, yy, p in zip(cost, y, sel):
                    ax.annotate(
                        f"{p['disp_max']:g}", (c, yy), textcoords="offset points", xytext=(4, 4), fontsize=7
                    )
        for ax, label in zip(row_axes, ("η_r", "Π/σ", "Z_μ")):
            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            ax.set_xlabel(f"steps per unit strain (cost; N = {data['n']})")
            ax.set_ylabel(label)
            ax.set_title(f"φ = {data['phi']}, σ/σ0 = {stress:g}")
            ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def draw_scheme_near_jamming(data: dict):
    """η_r = σ Δt/Δγ of each flowing output interval against strain, one panel per (σ/σ0, seed) and one
    line per (scheme, disp_max); ``runs``: ``stress``, ``seed``, ``scheme``, ``disp_max``, ``status``
    and the ``strain`` and ``viscosity`` of its flowing intervals, at ``phi``."""
    plt = _pyplot()
    runs = data["runs"]
    panels = sorted({(r["stress"], r["seed"]) for r in runs}, key=lambda k: (-k[0], k[1]))
    fig, axes = plt.subplots(1, len(panels), figsize=(4.5 * len(panels), 3.8), squeeze=False)
    disps = sorted({r["disp_max"] for r in runs}, reverse=True)
    styles = dict(zip(disps, ["-", "--", ":", "-."] * 3))
    for ax, (stress, seed) in zip(axes[0], panels):
        mine = sorted(
            (r for r in runs if (r["stress"], r["seed"]) == (stress, seed)), key=lambda r: r["scheme"]
        )
        for r in mine:
            label = f"{r['scheme']} {r['disp_max']:g}" + (" (jammed)" if r["status"] == "jammed" else "")
            ax.semilogy(
                r["strain"],
                r["viscosity"],
                styles[r["disp_max"]],
                color=SCHEME_COLOURS.get(r["scheme"]),
                lw=1,
                label=label,
            )
        ax.set_title(f"φ = {data['phi']:g}, σ/σ0 = {stress:g}, seed {seed}")
        ax.set_xlabel("strain γ")
        ax.set_ylabel("η_r = σ Δt/Δγ per 0.01 strain")
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


# ---- surrogate accuracy and cost -----------------------------------------------------------------------
def draw_surrogate_r2_vs_phi(data: dict):
    """Held-out R² of the three targets against φ, mean ± std over the test folds, one line per
    (``split``, ``n``) of ``series`` (its ``phi``, ``mean`` and ``std`` per score key, and for the
    grouped split the trees' mean ``trees``), beside the seed paper's values (``paper``: R² ``r2`` over
    ``phi``, and per target ``phi_080_r2`` at φ = 0.80)."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for line in data["series"]:
        style = "-" if line["split"] == "grouped" else "--"
        for k, (key, _) in enumerate(SCORES):
            axes[k].errorbar(
                line["phi"],
                line["mean"][key],
                yerr=line["std"][key],
                marker="o",
                ls=style,
                capsize=3,
                label=f"N = {line['n']}, {line['split']}",
            )
            if line["trees"]:
                label = f"trees, N = {line['n']}" if k == 0 else None
                axes[k].plot(line["phi"], line["trees"][key], "k:", marker="x", label=label)
    paper = data["paper"]
    for k, (_, label) in enumerate(SCORES):
        axes[k].plot(
            paper["phi"],
            [paper["r2"]] * len(paper["phi"]),
            "r--",
            lw=0.8,
            label="paper (≳ 0.99)" if k == 0 else None,
        )
        axes[k].plot(
            [0.80], [paper["phi_080_r2"][k]], "r*", ms=10, label="paper φ = 0.80" if k == 0 else None
        )
        axes[k].set_xlabel("φ")
        axes[k].set_ylabel(f"R² {label}")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def draw_time_to_accuracy(data: dict):
    """Held-out R² of each target against training minutes, one row per N and one line per
    configuration; ``runs``: ``n``, ``label`` and per epoch its ``minutes`` and each score."""
    plt = _pyplot()
    runs = data["runs"]
    ns = sorted({r["n"] for r in runs})
    fig, axes = plt.subplots(len(ns), 3, figsize=(12, 3.3 * len(ns)), squeeze=False)
    for i, n in enumerate(ns):
        for j, (key, label) in enumerate(SCORES):
            ax = axes[i, j]
            for r in (r for r in runs if r["n"] == n):
                ax.plot(r["minutes"], r[key], label=r["label"])
            ax.set_ylim(0.5 if key != "r2_log_eta" else 0.0, 1.0)
            ax.set_title(f"N = {n}: R² {label} (held-out)")
            ax.set_xlabel("training minutes (1 thread)")
            ax.legend()
    fig.tight_layout()
    return fig


def pareto_front(points) -> list[int]:
    """Indices of the (cost, score) ``points`` not dominated in (cost lower, score higher)."""
    front = []
    for i, (c, s) in enumerate(points):
        if not any((c2 <= c and s2 >= s) and (c2, s2) != (c, s) for c2, s2 in points):
            front.append(i)
    return front


PARETO_MARKERS = {"physics": "o", "physics_positions": "s", "paper": "^", "physics_layer_norm": "D"}


def draw_surrogate_pareto(data: dict):
    """Held-out R² of each target against ms per snapshot (graph building + forward pass) and against
    training minutes, one point per model of ``models`` (``variant``, ``layers``, ``width``, ``ms``,
    ``train_minutes`` and its ``scores``), the Pareto front of the physics variant dashed, at ``phi``."""
    plt = _pyplot()
    models = data["models"]
    fig, axes = plt.subplots(2, 3, figsize=(13, 7))
    for j, (key, label) in enumerate(SCORES):
        for i, cost in enumerate(("ms", "train_minutes")):
            ax = axes[i, j]
            xs = [m[cost] for m in models]
            for m, x in zip(models, xs):
                ax.scatter(
                    x,
                    m["scores"][key],
                    marker=PARETO_MARKERS.get(m["variant"], "o"),
                    color="k" if (m["layers"], m["width"]) == (2, 64) else "tab:blue",
                )
                ax.annotate(f"{m['layers']}×{m['width']}", (x, m["scores"][key]), fontsize=7)
            phys = [k for k, m in enumerate(models) if m["variant"] == "physics"]
            front = [phys[k] for k in pareto_front([(xs[k], models[k]["scores"][key]) for k in phys])]
            front.sort(key=lambda k: xs[k])
            ax.plot([xs[k] for k in front], [models[k]["scores"][key] for k in front], "r--", lw=1)
            ax.set_xscale("log")
            ax.set_xlabel(
                "ms per snapshot (build + forward)" if cost == "ms" else "training minutes (1 fold, 1 thread)"
            )
            ax.set_ylabel(f"held-out R² {label}")
    fig.suptitle(
        f"fold 0, φ = {data['phi']:g}, N = 400; circles: physics + σ, diamond: physics + σ with layer norm, "
        "squares: physics positions only, triangles: paper; black: the paper's 2×64; red: Pareto front "
        "(physics)",
        fontsize=9,
    )
    fig.tight_layout()
    return fig


# ---- the table ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Figure:
    """How a published figure is drawn: ``draw`` (the plotted numbers -> a matplotlib figure) from
    ``record`` (a file under docs/results/bench/) at its ``key``, at ``dpi`` dots per inch."""

    draw: Callable[[dict], object]
    record: str
    key: str
    dpi: int


def _card(folder: str, dataset: str) -> dict[str, Figure]:
    """The two figures of a dataset card under docs/``folder``, from figures/dataset_``dataset``.json."""
    record = f"figures/dataset_{dataset}.json"
    return {
        f"{folder}figures/dataset_fig2.png": Figure(
            dataset_card.draw_fig2, record, "fig2", dataset_card.FIG2_DPI
        ),
        f"{folder}figures/dataset_fig3.png": Figure(
            dataset_card.draw_fig3, record, "fig3", dataset_card.FIG3_DPI
        ),
    }


FIGURES: dict[str, Figure] = {
    **_card("", "paper"),
    **_card("datasets/flow_curves_3d/", "flow_curves_3d"),
    **_card("datasets/near_jamming_3d/", "near_jamming_3d"),
    **_card("datasets/polydisperse_flow_curves_3d/", "polydisperse_flow_curves_3d"),
    **_card("datasets/jamming/", "jamming"),
    **_card("datasets/large_n/", "large_n"),
    "figures/flow_curves.png": Figure(
        flow_curves.draw, "figures/flow_curves.json", "figure", flow_curves.DPI
    ),
    "figures/phase_diagram.png": Figure(
        jamming_points.draw_phase_diagram, "jamming_fits.json", "figure", jamming_points.DPI
    ),
    "figures/phase_diagram_3d.png": Figure(
        jamming_points.draw_phase_diagram, "jamming_fits_3d.json", "figure", jamming_points.DPI
    ),
    "figures/collapse_2d_3d.png": Figure(collapse.draw, "collapse_2d_3d.json", "figure", collapse.DPI),
    "figures/imaging_noise.png": Figure(draw_imaging_noise, "figures/imaging_noise.json", "figure", 110),
    "figures/scheme_near_jamming.png": Figure(
        draw_scheme_near_jamming, "scheme_near_jamming.json", "figure", 120
    ),
    "figures/time_step_convergence.png": Figure(
        draw_time_step_convergence, "time_step_convergence.json", "figure", 120
    ),
    "figures/surrogate_r2_vs_phi.png": Figure(
        draw_surrogate_r2_vs_phi, "surrogate_per_phi.json", "figure", 110
    ),
    "figures/time_to_accuracy.png": Figure(draw_time_to_accuracy, "train_speed_accuracy.json", "figure", 110),
    "figures/surrogate_pareto.png": Figure(draw_surrogate_pareto, "train_speed_pareto.json", "figure", 110),
}


def figure_data(name: str, records: Path = RECORDS) -> dict:
    """The numbers the published figure ``name`` plots, from its record (InputError naming the figure
    where the record or its key is missing)."""
    spec = FIGURES[name]
    path = Path(records) / spec.record
    if not path.exists():
        raise InputError(f"{name}: its record {spec.record} is missing")
    record = read_record(path, f"record of {name}")
    if spec.key not in record:
        raise InputError(f"{name}: its record {spec.record} holds no '{spec.key}'")
    return record[spec.key]


def draw(name: str, out: Path = DOCS, records: Path = RECORDS) -> Path:
    """Draw the published figure ``name`` from its record into ``out``/``name`` (a palette PNG stamped
    with the hash of the numbers drawn)."""
    spec, data = FIGURES[name], figure_data(name, records)
    fig = spec.draw(data)
    path = Path(out) / name
    path.parent.mkdir(parents=True, exist_ok=True)
    save_png(fig, path, spec.dpi, drawn_from=data)
    _pyplot().close(fig)
    return path


def figures_of(record: str) -> list[str]:
    """The published figures drawn from ``record`` (a file name under docs/results/bench/)."""
    return [name for name, spec in FIGURES.items() if spec.record == record]


def publish_figure(name: str, data: dict, command: str, records: Path = RECORDS, docs: Path = DOCS) -> Path:
    """Keep the numbers of the figure ``name`` (``data``, with the ``command`` that computed them) in
    its own record and draw the figure from that record."""
    spec = FIGURES[name]
    write_record(Path(records) / spec.record, {"command": command, spec.key: data})
    return draw(name, docs, records)


FIGURE_LINK = re.compile(r"\]\(([^)\s]+\.png)\)")


def published_figures(docs: Path = DOCS) -> set[str]:
    """Every PNG that a docs page links (path under docs/), the training reports under docs/results/
    excepted."""
    docs = Path(docs).resolve()
    found = set()
    for page in docs.rglob("*.md"):
        if (docs / "results") in page.parents:
            continue
        for link in FIGURE_LINK.findall(page.read_text()):
            found.add((page.parent / link).resolve().relative_to(docs).as_posix())
    return found


def figure_problems(name: str, docs: Path, records: Path, scratch: Path) -> list[str]:
    """What is wrong with the committed figure ``name`` against its record (empty: nothing); it is
    redrawn into ``scratch``."""
    committed = Path(docs) / name
    try:
        data = figure_data(name, records)
    except InputError as exc:
        return [str(exc)]
    if not committed.exists():
        return [f"{name}: not drawn (python -m bench.render draws it)"]
    out = []
    if drawn_from_hash(committed) != data_hash(data):
        out.append(f"{name}: figure differs from its record {FIGURES[name].record} (python -m bench.render)")
    try:
        redrawn = draw(name, scratch, records)
    except Exception as exc:  # any failure of a plotting function is a finding, named with its figure
        return out + [f"{name}: does not draw from its record: {type(exc).__name__}: {exc}"]
    if png_size(redrawn) != png_size(committed):
        out.append(
            f"{name}: drawn at {png_size(redrawn)} pixels from its record, committed at {png_size(committed)}"
        )
    return out


def differences(docs: Path = DOCS, records: Path = RECORDS) -> list[str]:
    """One line per published figure that has no record, does not draw from it, or does not show its
    numbers (see the module docstring)."""
    out = [
        f"{name}: published figure without an entry in bench.figures.FIGURES"
        for name in sorted(published_figures(docs) - set(FIGURES))
    ]
    with tempfile.TemporaryDirectory() as scratch:
        for name in FIGURES:
            out += figure_problems(name, docs, records, Path(scratch))
    return out


def render(docs: Path = DOCS, records: Path = RECORDS) -> int:
    """Redraw every published figure from its record; the number whose record differed from the PNG."""
    changed = 0
    for name in FIGURES:
        committed = Path(docs) / name
        before = drawn_from_hash(committed) if committed.exists() else None
        changed += before != data_hash(figure_data(name, records))
        draw(name, docs, records)
    return changed
