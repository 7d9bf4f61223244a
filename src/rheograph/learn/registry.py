"""Shipped surrogate models: named ensembles of fold bundles with a model card, inside the package
(``rheograph/models/<name>/``: ``fold*.pt``, ``error_model.json``, ``card.json``, ``card.md``).

    python -m rheograph.learn.registry ship outputs/train/<timestamp> --name my_model
    python predict.py --list-models

``ship`` makes a named model out of a training run directory: its fold bundles, completed where a run of
an older version lacks them with the physical parameters and the one-solve step of its training data
(read from the trajectories its split files list), its error model, and a card written from its
``metrics.json``: training data, protocol, held-out scores beside the physics-only rows and the
baselines, the trained domain, the parameters a snapshot must carry, and what is computed from physics
versus learned.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
from pathlib import Path

import numpy as np

from rheograph.errors import InputError, one_line_errors
from rheograph.graphs.targets import spec_of_record
from rheograph.io.json_files import read_json
from rheograph.learn.baselines import physics_fold_metrics
from rheograph.learn.bundle import complete_bundle, read_bundle, write_bundle

MODELS_DIR = Path(__file__).resolve().parents[1] / "models"


def list_models() -> list[str]:
    """The names of the shipped models (``rheograph/models/<name>/``, each with a ``card.json``)."""
    if not MODELS_DIR.is_dir():
        return []
    return sorted(p.name for p in MODELS_DIR.iterdir() if (p / "card.json").is_file() and p.name[0] != ".")


def model_paths(name_or_path: str | Path) -> tuple[list[Path], str]:
    """(fold bundles, label) of a shipped model name, a training run directory or one bundle file."""
    text = str(name_or_path)
    if text in list_models():
        directory = MODELS_DIR / text
        return sorted(directory.glob("fold*.pt")), text
    path = Path(text)
    if path.is_file():
        return [path], str(path)
    if path.is_dir():
        bundles = sorted(path.glob("fold*.pt"))
        if not bundles:
            raise InputError(f"model {path}: a directory without fold*.pt bundles (a training run?)")
        return bundles, str(path)
    shipped = ", ".join(list_models()) or "none installed"
    raise InputError(
        f"model {text}: neither a shipped model ({shipped}) nor a training run directory or bundle"
    )


def _finite_numbers(value, count: int | None = None) -> bool:
    """Whether ``value`` is a list of ``count`` (any number if None, at least one) finite numbers."""
    return (
        isinstance(value, list)
        and (len(value) == count if count is not None else bool(value))
        and all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    )


def read_card(paths: list[Path]) -> dict | None:
    """The ``card.json`` beside the bundles ``paths``, or None where there is none; one that is not JSON
    or lacks what predictions read of it (its ``domain``: ``phi`` and ``stress`` ranges, ``n_particles``;
    ``position_noise``) is refused by name."""
    path = paths[0].parent / "card.json"
    if not path.is_file():
        return None
    card = read_json(path, "model card", "; is the model folder damaged?")
    domain = card.get("domain") if isinstance(card, dict) else None
    noise = card.get("position_noise") if isinstance(card, dict) else None
    if not (
        isinstance(domain, dict)
        and _finite_numbers(domain.get("phi"), 2)
        and _finite_numbers(domain.get("stress"), 2)
        and _finite_numbers(domain.get("n_particles"))
        and (_finite_numbers([noise]) or _finite_numbers(noise, 2))
        and ("axial_noise" not in card or _finite_numbers(card["axial_noise"], 2))
    ):
        raise InputError(
            f"{path}: not a model card: it needs domain.phi and domain.stress (two numbers each), "
            "domain.n_particles (a list) and position_noise (a number or two; axial_noise, where present, "
            "two); is the model folder damaged?"
        )
    return card


# ---- making a shipped model ----------------------------------------------------------------------
# the graph inputs computed from physics, and what each is
COMPUTED_INPUTS = {
    "solve_viscosity": "the η_r of one resistance solve at the imposed stress",
    "frictional_coordination": "the CLM's frictional contacts counted",
    "spring_pressure": "the contact-spring sum of the particle pressure",
    "relaxed_viscosity": "the η_r of the relaxed configuration, with the springs the relaxation loaded",
    "relaxed_viscosity_early": "the η_r a quarter of the way through the relaxation",
    "relaxed_pressure": "the particle pressure of the relaxed configuration",
    "relaxed_coordination": "the frictional contacts of the relaxed configuration",
}


def _score_rows(metrics: dict) -> list[dict]:
    mean = metrics["mean"]
    from rheograph.learn.report import BASELINE_LABELS

    rows = [("graph network", "test/")]
    names = ("physics_solve", "physics_offset", "stress_mean", "descriptors", "descriptors_solve")
    rows += [(BASELINE_LABELS[name], f"baseline/{name}/") for name in names]
    out = []
    for label, prefix in rows:
        scores = {
            target: mean.get(f"{prefix}r2_{scale}{target}")
            for target, scale in (("eta", "log_"), ("pressure", "log_"), ("z_mu", ""))
        }
        if any(v is not None for v in scores.values()):
            out.append({"model": label, **scores})
    return out


def _relative(path: Path) -> str:
    try:
        return str(path.resolve().relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def _with_physics_rows(run_dir: Path, metrics: dict, cache_dir) -> dict:
    """``metrics`` with the physics-only rows' fold means, computed on the run's test folds where a run
    of an older version lacks them."""
    if any(key.startswith("baseline/physics_") for key in metrics["mean"]):
        return metrics
    per_fold = [physics_fold_metrics(run_dir, f["fold"], cache_dir) for f in metrics["folds"]]
    mean = dict(metrics["mean"])
    for name in per_fold[0]:
        for key in per_fold[0][name]:
            mean[f"baseline/{name}/{key}"] = float(np.nanmean([f[name][key] for f in per_fold]))
    return {**metrics, "mean": mean}


def write_card(directory: Path, name: str, run_dir: Path, bundle: dict, cache_dir="data/cache") -> dict:
    metrics = _with_physics_rows(run_dir, json.loads((run_dir / "metrics.json").read_text()), cache_dir)
    domain, graph = bundle["domain"], bundle["graph"]
    card = {
        "name": name,
        "trained_from": _relative(run_dir),
        "split": metrics.get("split"),
        "folds": len(metrics["folds"]),
        "graph": graph,
        "domain": {
            k: domain[k] for k in ("phi", "stress", "n_particles", "size_ratio", "dim") if k in domain
        },
        "physical_params": domain["physical_params"],
        "solve_numerics": domain["solve_numerics"],
        "position_noise": domain.get("position_noise", 0.0),
        **({"axial_noise": domain["axial_noise"]} if "axial_noise" in domain else {}),
        # another network than SurrogateModule's own: its class must be registered where the model is used
        "module_class": bundle.get("module_class"),
        "on_state_mean": bool(bundle["hyper_parameters"].get("on_state_mean", False)),
        "held_out_r2": _score_rows(metrics),
    }
    (directory / "card.json").write_text(json.dumps(card, indent=1))
    (directory / "card.md").write_text(card_markdown(card))
    return card


def _noise_text(card: dict) -> str:
    noise = card["position_noise"]
    if "axial_noise" in card:
        axial, axis = card["axial_noise"], card["graph"].get("optical_axis", "y")
        return (
            f"trained on confocal-grade positions: Gaussian noise of {noise[0]:g}–{noise[1]:g} a per "
            f"coordinate across the optical axis ({axis}) and {axial[0]:g}–{axial[1]:g} a along it, each "
            "log-uniform: beyond either range a snapshot is flagged."
        )
    if isinstance(noise, list):
        return (
            f"trained on positions with Gaussian noise of {noise[0]:g}–{noise[1]:g} a per coordinate "
            "(log-uniform): outside that range a snapshot is flagged."
        )
    return "positions exact to 1e-7 a (simulator output): a snapshot less precise than 3e-5 a is flagged."


def card_markdown(card: dict) -> str:
    d = card["domain"]
    targets = spec_of_record(card["graph"])  # cards of earlier versions: the legacy form
    computed = [x for x in card["graph"]["graph_inputs"] if x in COMPUTED_INPUTS]
    lines = [
        f"# Model card: {card['name']}",
        "",
        f"Ensemble of {card['folds']} fold models (ResGCN) trained by `train.py` on rheograph simulations "
        f"(split: {card['split']}; held-out scores are on test folds the fold models never saw).",
        "",
        "## Trained domain",
        # cards written before 3D models record no dimension: 2D, and their text stays as it was
        *(["* 3D: spheres in a cubic box (a 2D snapshot is refused)."] if d.get("dim", 2) == 3 else []),
        f"* φ {d['phi'][0]:g}–{d['phi'][1]:g}, σ/σ0 {d['stress'][0]:g}–{d['stress'][1]:g}, "
        f"N {d['n_particles']}, "
        f"size ratio {d['size_ratio']}; " + _noise_text(card),
        "* A snapshot must carry these physical parameters, equal to the model's (refused otherwise): "
        + ", ".join(f"`{k}` = {v:g}" for k, v in card["physical_params"].items()),
        "* The one-solve input is computed with the model's own step: "
        + "; ".join(f"φ {e['phi']:g}: disp_max {e['disp_max']:g}" for e in card["solve_numerics"]),
        "",
        "## What is computed from physics and what is learned",
        "* Edge features: "
        + ", ".join(f"`{x}`" for x in card["graph"]["edge_features"])
        + " (from positions, radii, box, "
        "and the imposed stress).",
    ]
    if computed:
        lines.append(
            "* Computed graph inputs: "
            + "; ".join(f"`{x}` ({COMPUTED_INPUTS[x]})" for x in computed)
            + "."
            + "".join(
                f" {target} is learned as a correction to {reference}."
                for spec_reference, target, reference in (
                    (targets.eta_r.relative_to == "solve_viscosity", "η_r", "the one-solve value"),
                    (
                        targets.eta_r.relative_to == "relaxed_viscosity",
                        "η_r",
                        "the relaxed configuration's value",
                    ),
                    (targets.pi.relative_to == "spring_pressure", "Π", "the spring sum"),
                    (targets.z_mu.relative_to == "frictional_coordination", "Z_μ", "the count"),
                )
                if spec_reference
            )
        )
    graph = card["graph"]
    if graph.get("relax_strain"):
        lines.append(
            f"* Every snapshot is first sheared by {graph['relax_strain']:g} strain under the simulator's "
            "dynamics at its imposed stress (repairs the overlaps that imprecise positions make), then "
            "the inputs are computed from it: ~0.4 s per N = 400 snapshot."
        )
    if "position_noise" in graph["graph_inputs"]:
        lines.append(
            "* The positions' RMS precision `position_noise` (a) is an input: a snapshot must state it "
            "(file key, `predict.py --position-noise`, or `position_noise=` in `model.predict`)."
        )
    if "axial_noise" in graph["graph_inputs"]:
        lines.append(
            f"* So is the precision along the optical axis ({graph.get('optical_axis', 'y')}) `axial_noise` "
            "(a), `position_noise` then being the in-plane one (file key, `predict.py --axial-noise`, or "
            "`axial_noise=` in `model.predict`)."
        )
    if graph.get("stress_known", True) is False:
        lines.append(
            "* Positions only: the imposed stress is not an input (a snapshot need not state it).  Π is "
            "learned per stress: the model predicts μ_eff = σ/Π and Π/σ, and Π in σ0 only where σ is "
            "given (with k_n ∝ σ, positions do not fix Π in σ0)."
        )
    if card.get("on_state_mean"):
        lines.append(
            "* Each target is learned as the deviation from the training folds' mean at the snapshot's "
            "(φ, σ): where a snapshot says little, the prediction falls back on that lookup"
            + (
                " (for η_r, learned as a correction to the one-solve value: that value times the mean "
                "correction at (φ, σ))."
                if targets.eta_r.relative_to == "solve_viscosity"
                else " (for η_r, learned as a correction to the relaxed configuration's value: that "
                "value times the mean correction at (φ, σ))."
                if targets.eta_r.relative_to == "relaxed_viscosity"
                else "."
            )
        )
    lines += [
        "* Learned: the message-passing network and its head (η_r, Π, Z_μ)"
        + (
            f" — class `{card['module_class']}`, which the model folder does not carry: it loads where "
            "that class is registered (`rheograph.load_model(..., network_class=...)`, "
            "`rheograph.register_network` or the `rheograph.networks` entry-point group)."
            if card.get("module_class")
            else "."
        ),
        "",
        "## Held-out R² (mean over folds)",
        "",
        *(
            [
                "On noisy copies of the test trajectories (noise log-uniform over the trained range, "
                "several copies per snapshot, every predictor on the same copies); by noise level: "
                "`python -m bench.noise_bins` on the training run named below (these rows split by "
                "their noise) and the project's results page.",
                "",
            ]
            if isinstance(card["position_noise"], list)
            else []
        ),
        "| model | R² log η_r | R² log Π | R² Z_μ |",
        "|---|---|---|---|",
    ]

    def fmt(v):
        return "–" if v is None else f"{v:.5f}"

    for row in card["held_out_r2"]:
        lines.append(f"| {row['model']} | {fmt(row['eta'])} | {fmt(row['pressure'])} | {fmt(row['z_mu'])} |")
    lines += ["", f"Trained in `{card['trained_from']}`."]
    return "\n".join(lines) + "\n"


def ship(run_dir: str | Path, name: str, replace: bool = False) -> Path:
    """Makes ``rheograph/models/<name>/`` from the training run ``run_dir``.  A model already shipped
    under ``name`` is kept unless ``replace``; then the new one is built beside it and swapped in whole,
    so that no folder ever mixes the folds, error model or card of two runs."""
    import re
    import tempfile

    run_dir = Path(run_dir)
    bundles = sorted(run_dir.glob("fold*.pt"))
    if not bundles:
        raise InputError(f"{run_dir}: no fold*.pt bundles")
    if not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.-]*", name):
        raise InputError(
            f"--name {name!r}: a model name is letters, digits, _ - . (not starting with . or -)"
        )
    directory, retired = MODELS_DIR / name, MODELS_DIR / f".{name}.replaced"
    if retired.exists() and not directory.exists():  # a replacement cut between its two renames
        retired.rename(directory)
    if directory.exists() and not replace:
        raise InputError(
            f"--name {name}: a model of that name is shipped ({directory}); pick another name, or add "
            "--replace to replace it whole"
        )
    MODELS_DIR.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{name}.shipping.", dir=MODELS_DIR))
    try:
        first = None
        for path in bundles:
            bundle = complete_bundle(read_bundle(path), path.with_name(path.stem + "_split.json"))
            write_bundle(staging / path.name, bundle)
            first = first or bundle
        if (run_dir / "error_model.json").is_file():
            shutil.copy(run_dir / "error_model.json", staging / "error_model.json")
        write_card(staging, name, run_dir, first)
        staging.chmod(0o755)  # mkdtemp's 0700 would hide the model from other users of an installation
        if directory.exists():
            shutil.rmtree(retired, ignore_errors=True)
            directory.rename(retired)
            staging.rename(directory)
            shutil.rmtree(retired)
        else:
            staging.rename(directory)
    finally:
        shutil.rmtree(staging, ignore_errors=True)  # gone already where the model was shipped
    return directory


def upgrade(name: str) -> int:
    """Rewrites the bundles of the shipped model ``name`` in the current format (weights and records
    unchanged: ``read_bundle`` upgrades them) and removes the separate Lightning checkpoints that older
    versions shipped beside them (a bundle is one now).  Returns the number of bundles rewritten."""
    paths, _ = model_paths(name)
    for path in paths:
        write_bundle(path, read_bundle(path))
        path.with_suffix(".ckpt").unlink(missing_ok=True)
    return len(paths)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    s = sub.add_parser("ship", help="make a named model of a training run directory")
    s.add_argument("run_dir")
    s.add_argument("--name", required=True)
    s.add_argument("--replace", action="store_true", help="replace a model already shipped under --name")
    sub.add_parser("list", help="the shipped models")
    u = sub.add_parser("upgrade", help="rewrite shipped models' bundles in the current format")
    u.add_argument("names", nargs="*", help="default: every shipped model")
    args = ap.parse_args(argv)
    if args.command == "ship":
        print(ship(args.run_dir, args.name, replace=args.replace))
    elif args.command == "upgrade":
        for name in args.names or list_models():
            print(name, upgrade(name))
    else:
        for name in list_models():
            print(name)


if __name__ == "__main__":
    with one_line_errors("rheograph.learn.registry"):
        main()
