"""Predict eta_r, Pi, Z_mu for every snapshot of a trajectory file with the fold models of a training run
(an ensemble: mean and spread over folds), in one batched pass.

    python predict.py --models outputs/train/<run> --input trajectory.h5 --out predictions.csv

Model bundles (``fold*.pt``) are loaded with ``torch.load(weights_only=True)``: no code is unpickled.
Each bundle records the domain it was trained on; every prediction carries ``in_domain`` (the state point
lies in the trained phi, sigma and N ranges, and the snapshot's edge features in the trained ranges),
and a warning names what lies outside.  Inputs the model cannot read (another size ratio) are refused.

Columns per target: ``*_pred`` (ensemble mean), ``*_pred_std`` (spread over the fold models: flags
disagreement, too narrow to be an error bar), ``*_pred_err`` (the cross-validated error bar of the
training run's ``error_model.json``, rheograph.learn.error_model: one RMS of held-out residuals, in log10
units for η_r and Π — the truth lies within pred × 10^(±err) about 68 % of the time — and absolute for
Z_μ; absent for runs without an error model) and ``*_sim`` (the simulator's value); ``jammed_fraction``:
the share of training trajectories at the nearest trained state point that shear-jammed
(rheograph.learn.jamming; jammed when >= 0.5).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
import torch

from rheograph.errors import InputError
from rheograph.graphs.dataset import GraphSettings, snapshot_graphs
from rheograph.learn.error_model import predicted_error, read_error_model
from rheograph.learn.jamming import jammed_fraction
from rheograph.learn.module import TARGET_NAMES, SurrogateModule
from rheograph.learn.train import BUNDLE_FORMAT, predict_dataset


def load_bundle(path: str | Path) -> tuple[SurrogateModule, GraphSettings, dict]:
    """(module, graph settings, training domain) of a bundle written by ``train.save_bundle``."""
    try:
        bundle = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # a truncated or foreign file: torch raises several types
        raise InputError(f"{path}: not a readable rheograph model bundle ({exc})") from exc
    if not isinstance(bundle, dict) or bundle.get("format") != BUNDLE_FORMAT:
        raise InputError(
            f"{path}: not a rheograph model bundle ({BUNDLE_FORMAT}); bundles of older versions must be "
            "retrained"
        )
    module = SurrogateModule(**bundle["hparams"])
    module.load_state_dict(bundle["state_dict"])
    module.eval()
    graph = dict(bundle["graph"])
    graph["edge_features"] = tuple(graph["edge_features"])
    graph["graph_inputs"] = tuple(graph.get("graph_inputs", ()))
    return module, GraphSettings(**graph), bundle["domain"]


def _trajectory_params(path) -> dict:
    from rheograph.io.hdf5 import read_params

    try:
        return read_params(path)
    except (OSError, KeyError) as exc:
        raise InputError(
            f"{path}: not a readable rheograph trajectory ({exc}); check the path, or move a truncated "
            "file aside and rerun its simulation"
        ) from exc


def domain_report(domain: dict, params: dict, graphs, edge_features) -> tuple[np.ndarray, list[str]]:
    """Per-snapshot in-domain flags (S,) and the reasons for any snapshot outside."""
    reasons = []
    for key in ("phi", "stress"):
        low, high = domain[key]
        if not low * (1 - 1e-9) <= params[key] <= high * (1 + 1e-9):
            reasons.append(f"{key} = {params[key]:g} outside the trained [{low:g}, {high:g}]")
    if params["n_particles"] not in domain["n_particles"]:
        reasons.append(f"N = {params['n_particles']} not among the trained N {domain['n_particles']}")
    flags = np.full(len(graphs), not reasons)
    low, high = np.array(domain["edge_min"]), np.array(domain["edge_max"])
    span = np.maximum(high - low, 1e-12)
    outside = set()
    for k, g in enumerate(graphs):
        attr = g.edge_attr.numpy()
        bad = (attr.min(axis=0) < low - 0.05 * span) | (attr.max(axis=0) > high + 0.05 * span)
        if bad.any():
            flags[k] = False
            outside.update(np.asarray(edge_features)[bad].tolist())
    if outside:
        reasons.append(f"edge features {sorted(outside)} beyond their trained range in some snapshots")
    return flags, reasons


def predict_file(model_paths, trajectory: str | Path) -> dict:
    """Ensemble prediction for all snapshots of ``trajectory``: arrays (S,) per column."""
    if not model_paths:
        raise InputError("no model bundles (fold*.pt) given: --models must name a training run directory")
    models = [load_bundle(p) for p in sorted(model_paths)]
    settings = dataclasses.replace(models[0][1], min_strain=0.0)
    if any(dataclasses.replace(s, min_strain=0.0) != settings for _, s, _ in models):
        raise InputError("the model bundles were trained with different graph settings")
    params = _trajectory_params(trajectory)
    domain = models[0][2]
    if round(params["size_ratio"], 6) not in domain["size_ratio"]:
        raise InputError(
            f"{trajectory}: size ratio {params['size_ratio']} but the model was trained on "
            f"{domain['size_ratio']}: its one-hot radius input cannot represent these particles"
        )
    graphs = snapshot_graphs(trajectory, settings, run_id=0)
    if not graphs:
        raise InputError(f"{trajectory}: no snapshot with finite targets to predict")
    preds = []
    for module, _, _ in models:
        pred, true, meta = predict_dataset(module, graphs, batch_size=len(graphs))
        preds.append(pred)
    preds = np.stack(preds)  # (models, S, 3)
    in_domain, reasons = domain_report(domain, params, graphs, settings.edge_features)
    if reasons:
        print(
            f"warning: {trajectory}: input outside the training domain: " + "; ".join(reasons),
            file=sys.stderr,
        )
    out = {
        "strain": np.array([g.strain.item() for g in graphs]),
        "stress": meta["stress"],
        "phi": meta["phi"],
        "in_domain": in_domain.astype(np.int64),
    }
    if "jam_map" in domain:  # bundles of older versions have none
        out["jammed_fraction"] = jammed_fraction(domain["jam_map"], meta["phi"], meta["stress"])
    error_model = read_error_model(Path(sorted(model_paths)[0]).parent)
    errors = predicted_error(error_model, meta["stress"], meta["phi"]) if error_model else None
    for k, name in enumerate(TARGET_NAMES):
        out[f"{name}_pred"] = preds[:, :, k].mean(axis=0)
        out[f"{name}_pred_std"] = preds[:, :, k].std(axis=0)
        if errors is not None:
            out[f"{name}_pred_err"] = errors[:, k]
        out[f"{name}_sim"] = true[:, k]
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", required=True, help="training run directory holding fold*.pt (or one .pt)")
    ap.add_argument("--input", required=True, help="trajectory .h5 file")
    ap.add_argument("--out", required=True, help="output .csv or .h5")
    args = ap.parse_args(argv)
    models = Path(args.models)
    if not models.exists():
        raise InputError(f"--models {models} does not exist")
    paths = [models] if models.is_file() else sorted(models.glob("fold*.pt"))
    result = predict_file(paths, args.input)
    out = Path(args.out)
    if out.suffix == ".h5":
        import h5py

        with h5py.File(out, "w") as h5:
            for key, value in result.items():
                h5[key] = value
            h5.attrs["models"] = [str(p) for p in paths]
    else:
        cols = list(result)
        np.savetxt(
            out,
            np.stack([result[c] for c in cols], axis=1),
            delimiter=",",
            header=",".join(cols),
            comments="",
        )
    n_out = int((result["in_domain"] == 0).sum())
    print(
        f"{len(result['strain'])} snapshots ({n_out} outside the training domain), "
        f"{len(paths)} model(s) -> {out}"
    )
