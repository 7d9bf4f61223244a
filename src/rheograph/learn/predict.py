"""Predict eta_r, Pi, Z_mu for every snapshot of a trajectory file with the fold models of a training run
(an ensemble: mean and spread over folds).

    python predict.py --models outputs/train/<run> --input trajectory.h5 --out predictions.csv

Model bundles (``fold*.pt``) are loaded with ``torch.load(weights_only=True)``: no code is unpickled.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import torch

from rheograph.errors import InputError, one_line_errors
from rheograph.graphs.dataset import GraphSettings, snapshot_graphs
from rheograph.learn.module import TARGET_NAMES, SurrogateModule
from rheograph.learn.train import predict_dataset

BUNDLE_FORMAT = "rheograph-surrogate-1"


def load_bundle(path: str | Path) -> tuple[SurrogateModule, GraphSettings]:
    bundle = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(bundle, dict) or bundle.get("format") != BUNDLE_FORMAT:
        raise InputError(f"{path}: not a rheograph model bundle ({BUNDLE_FORMAT})")
    module = SurrogateModule(**bundle["hparams"])
    module.load_state_dict(bundle["state_dict"])
    module.eval()
    graph = dict(bundle["graph"])
    graph["edge_features"] = tuple(graph["edge_features"])
    graph["graph_inputs"] = tuple(graph.get("graph_inputs", ()))
    return module, GraphSettings(**graph)


def predict_file(model_paths, trajectory: str | Path) -> dict:
    """Ensemble prediction for all snapshots of ``trajectory``: arrays (S,) per column."""
    models = [load_bundle(p) for p in sorted(model_paths)]
    if not models:
        raise InputError("no model bundles (fold*.pt) given")
    settings = dataclasses.replace(models[0][1], min_strain=0.0)
    if any(dataclasses.replace(s, min_strain=0.0) != settings for _, s in models):
        raise InputError("the model bundles were trained with different graph settings")
    graphs = snapshot_graphs(trajectory, settings, run_id=0)
    preds = []
    for module, _ in models:
        pred, true, meta = predict_dataset(module, graphs)
        preds.append(pred)
    preds = np.stack(preds)  # (models, S, 3)
    out = {
        "strain": np.array([g.strain.item() for g in graphs]),
        "stress": meta["stress"],
        "phi": meta["phi"],
    }
    for k, name in enumerate(TARGET_NAMES):
        out[f"{name}_pred"] = preds[:, :, k].mean(axis=0)
        out[f"{name}_pred_std"] = preds[:, :, k].std(axis=0)
        out[f"{name}_sim"] = true[:, k]
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", required=True, help="training run directory holding fold*.pt (or one .pt)")
    ap.add_argument("--input", required=True, help="trajectory .h5 file")
    ap.add_argument("--out", required=True, help="output .csv or .h5")
    args = ap.parse_args(argv)
    models = Path(args.models)
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
    print(f"{len(result['strain'])} snapshots, {len(paths)} model(s) -> {out}")


if __name__ == "__main__":
    with one_line_errors("predict.py"):
        main()
