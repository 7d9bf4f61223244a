"""The model file: one fold model's bundle (``fold<k>.pt``), its format, writing, reading and
completing, and batched prediction with a loaded module.  A bundle is also a Lightning checkpoint:
``SurrogateModule.load_from_checkpoint("fold0.pt", weights_only=True)`` rebuilds its network.

A bundle holds tensors and plain Python values only (``torch.load(weights_only=True)`` reads it): the
module's weights and hyperparameters, the graph settings it was trained with, its fold and split, and
the domain it was trained on (state points, N, size ratio, edge-feature ranges, the suspension's
physical parameters), so that predictions outside it are flagged.  Training writes bundles, inference
and the registry read them; neither imports the other.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import torch

from rheograph.errors import InputError
from rheograph.graphs.dataset import GraphSettings
from rheograph.graphs.targets import LEGACY_GRAPH_KEYS, spec_of_record
from rheograph.learn.datamodule import suspension_record
from rheograph.learn.module import SurrogateModule, network_hparams, physical_targets, upgraded_hparams
from rheograph.learn.nets import graph_network
from rheograph.learn.networks import registered_network

BUNDLE_FORMAT = "rheograph-surrogate-5"
# read through _upgraded, the one place that knows them (with rheograph.learn.module.upgraded_hparams):
# format 4 holds the network's options flat among the module's hyperparameters (the network then always
# a ResGCN); format 3 also states the targets in the form of earlier versions (graph booleans and scales,
# module columns: rheograph.graphs.targets.from_legacy); format 2 (before bundles were Lightning
# checkpoints) also holds the hyperparameters under "hparams"
OLDER_FORMATS = ("rheograph-surrogate-4", "rheograph-surrogate-3", "rheograph-surrogate-2")


def save_bundle(path: Path, module, settings: GraphSettings, fold: int, split: str, domain: dict) -> None:
    """A checkpoint loadable with torch.load(weights_only=True): tensors and plain Python values only.

    ``domain`` records what the model was trained on (phi and sigma ranges, N, size ratio, edge-feature
    ranges) so that predictions outside it are flagged."""
    import lightning as L

    hp = {k: (list(v) if isinstance(v, tuple) else v) for k, v in dict(module.hparams).items()}
    write_bundle(
        path,
        {
            "format": BUNDLE_FORMAT,
            "pytorch-lightning_version": L.__version__,
            # a subclass of SurrogateModule (another network) is rebuilt as itself; SurrogateModule's own
            # bundles carry no class name, so that they outlive a move of its module
            "module_class": None
            if type(module) is SurrogateModule
            else f"{type(module).__module__}:{type(module).__qualname__}",
            "state_dict": module.state_dict(),
            "hyper_parameters": hp,  # Lightning's key: load_from_checkpoint rebuilds the module from them
            "graph": {
                **settings.__dict__,
                "targets": settings.targets.to_config(),
                "edge_features": list(settings.edge_features),
                "graph_inputs": list(settings.graph_inputs),
                "noise_range": list(settings.noise_range),
                "axial_noise_range": list(settings.axial_noise_range),
            },
            "fold": fold,
            "split": split,
            "domain": domain,
        },
    )


def write_bundle(path: Path, bundle: dict) -> None:
    """Writes ``bundle`` (tensors and plain values) to ``path`` whole or not at all."""
    buffer = io.BytesIO()
    torch.save(bundle, buffer)
    # written by Python, not torch's writer: a full disk raises OSError (ENOSPC, one line at the entry
    # points) instead of torch's errno-less RuntimeError; through a temporary file, so a bundle is whole
    tmp = Path(path).with_name(Path(path).name + ".tmp")
    try:
        tmp.write_bytes(buffer.getvalue())
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def read_bundle(path: str | Path) -> dict:
    """The contents of a bundle written by ``save_bundle``: tensors and plain values, read with
    ``torch.load(weights_only=True)``; anything else is refused in one line."""
    try:
        bundle = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # a truncated or foreign file: torch raises several types, in many lines
        text = str(exc).strip()
        if text.startswith("Weights only load failed"):  # torch's advice to load unsafely does not apply
            why = "not a torch file of tensors and plain values, as bundles are"
        else:  # the first sentence: the rest is torch's advice to its own developers
            why = (text.splitlines() or [type(exc).__name__])[0].split(". ")[0][:160]
        raise InputError(
            f"{path}: not a readable rheograph model bundle ({why}); a model is a shipped model's name, "
            "a training run directory or one of its fold*.pt"
        ) from exc
    if not isinstance(bundle, dict) or bundle.get("format") not in (BUNDLE_FORMAT, *OLDER_FORMATS):
        raise InputError(
            f"{path}: not a rheograph model bundle ({BUNDLE_FORMAT}); bundles of older versions must be "
            "retrained"
        )
    try:
        return _upgraded(bundle)
    except InputError as exc:  # its records of the targets contradict each other
        raise InputError(f"{path}: a damaged rheograph model bundle ({exc})") from exc


def _upgraded(bundle: dict) -> dict:
    """A bundle of an older format in the current one (the weights and every other record unchanged; the
    targets as a specification and the network as a record of its class and options, through
    rheograph.learn.module.upgraded_hparams)."""
    if bundle["format"] == BUNDLE_FORMAT:
        return bundle
    import lightning as L

    upgraded = {k: v for k, v in bundle.items() if k != "hparams"}
    if bundle["format"] == "rheograph-surrogate-2":
        upgraded["hyper_parameters"] = bundle.get("hparams")
    upgraded.update({"format": BUNDLE_FORMAT, "pytorch-lightning_version": L.__version__})
    graph, hparams = upgraded.get("graph"), upgraded.get("hyper_parameters")
    if isinstance(graph, dict) and isinstance(hparams, dict):
        upgraded["hyper_parameters"] = upgraded_hparams(hparams, graph)
        upgraded["graph"] = {
            **{k: v for k, v in graph.items() if k not in LEGACY_GRAPH_KEYS},
            "targets": upgraded["hyper_parameters"]["targets"],
        }
    return upgraded


def bundle_graph_settings(bundle: dict) -> GraphSettings:
    """The graph settings a bundle (``read_bundle``) was trained with."""
    graph = dict(bundle["graph"])
    graph["edge_features"] = tuple(graph["edge_features"])
    graph["graph_inputs"] = tuple(graph.get("graph_inputs", ()))
    graph["noise_range"] = tuple(graph.get("noise_range", ()))
    graph["axial_noise_range"] = tuple(graph.get("axial_noise_range", ()))
    graph["targets"] = spec_of_record(graph)
    return GraphSettings(**{k: v for k, v in graph.items() if k not in LEGACY_GRAPH_KEYS})


def load_bundle(
    path: str | Path, network_class: type | None = None
) -> tuple[SurrogateModule, GraphSettings, dict]:
    """(module, graph settings, training domain) of a bundle written by ``save_bundle``.  The
    module is ``SurrogateModule`` or the registered subclass the bundle names (rheograph.learn.networks;
    ``network_class``: one registered for this call)."""
    bundle = read_bundle(path)
    module_class = registered_network(bundle.get("module_class"), path, network_class)
    net = (bundle.get("hyper_parameters") or {}).get("net")
    if isinstance(net, dict):  # its graph network: a registered class, or refused in one line
        graph_network(net.get("name"), path)
    try:  # a damaged bundle: entries missing or of the wrong type, weights of another network
        module = module_class(**network_hparams(bundle["hyper_parameters"], module_class))
        module.load_state_dict(bundle["state_dict"])
        module.eval()
        settings = bundle_graph_settings(bundle)
        domain = dict(bundle["domain"])
        missing = {"phi", "stress", "n_particles", "size_ratio", "edge_min", "edge_max"} - set(domain)
        if missing:
            raise KeyError(f"its training domain lacks {sorted(missing)}")
        return module, settings, domain
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        why = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:160]
        raise InputError(f"{path}: a damaged rheograph model bundle ({type(exc).__name__}: {why})") from exc


def complete_bundle(bundle: dict, split_file: Path) -> dict:
    """A bundle with the suspension record of its training data (bundles of older runs lack it): the
    split file lists every run of the training run's dataset, one suspension."""
    domain = bundle["domain"]
    if "physical_params" in domain and "solve_numerics" in domain:
        return bundle
    files = json.loads(split_file.read_text())["files"]
    return {**bundle, "domain": {**domain, **suspension_record(files)}}


@torch.no_grad()
def predict_dataset(module, dataset, batch_size: int = 64, device=None):
    """Physical predictions and truths (G, 3) and per-graph metadata for a dataset of graphs, in forward
    passes of ``batch_size`` graphs on ``device`` (None: where the module is)."""
    from torch_geometric.loader import DataLoader

    module.eval()
    if device is not None:
        module.to(device)
    device = next(module.parameters()).device
    preds, trues, stress, phi, run, jammed, size = [], [], [], [], [], [], []
    for batch in DataLoader(dataset, batch_size=batch_size):
        preds.append(module(batch.to(device)).cpu().numpy())
        batch = batch.cpu()  # moved in place: its truths and metadata back as numpy
        trues.append(batch.y_raw.numpy())
        stress.append(batch.stress.numpy())
        phi.append(batch.phi.numpy())
        run.append(batch.run_id.numpy())
        jammed.append(batch.jammed.numpy())
        size.append(batch.n_particles.numpy())
    pred = physical_targets(np.concatenate(preds), module.targets)
    return (
        pred,
        np.concatenate(trues),
        {
            "stress": np.concatenate(stress),
            "phi": np.concatenate(phi),
            "run_id": np.concatenate(run),
            "jammed": np.concatenate(jammed),
            "n_particles": np.concatenate(size),
        },
    )
