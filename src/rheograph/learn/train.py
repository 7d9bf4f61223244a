"""Training driver shared by ``train.py`` and the hyperparameter search: K folds, report, model bundles."""

from __future__ import annotations

import functools
import json
import logging
import logging.handlers
import os
import shutil
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from rheograph.errors import InputError, OtherRunError
from rheograph.graphs.dataset import GraphSettings
from rheograph.graphs.features import NODE_FEATURES
from rheograph.graphs.targets import TargetSpec
from rheograph.io.hdf5 import read_run_info
from rheograph.io.snapshots import data_fingerprint
from rheograph.learn.baselines import baseline_predictions, dataset_arrays
from rheograph.learn.bundle import predict_dataset, save_bundle
from rheograph.learn.datamodule import SPLIT_VERSION, check_num_folds
from rheograph.learn.error_model import fit_error_model, write_error_model
from rheograph.learn.jamming import jam_rule_scores
from rheograph.learn.module import (
    LEGACY_NET_OPTIONS,
    TARGET_NAMES,
    EpochLog,
    FoldResumePoint,
    check_training_factories,
    fold_metrics,
)
from rheograph.naming import run_name, state_point_key
from rheograph.sim.params import SimParams

log = logging.getLogger("rheograph.train")


def ensure_dataset(cfg: DictConfig) -> None:
    """Simulate the state points of ``cfg.simulate_missing`` whose files do not exist yet."""
    spec = cfg.get("simulate_missing")
    if not spec:
        return
    from hydra import compose

    from rheograph.runs.runner import run_state_point

    directory = Path(spec.directory)
    directory.mkdir(parents=True, exist_ok=True)
    base = compose(config_name="simulate", overrides=[f"sim={spec.preset}"]).sim
    for phi in spec.phi:
        for stress in spec.stress:
            for seed in spec.seeds:
                values = {
                    **OmegaConf.to_container(base),
                    **OmegaConf.to_container(spec.overrides),
                    "phi": float(phi),
                    "stress": float(stress),
                    "seed": int(seed),
                }
                params = SimParams.from_mapping(values)
                path = directory / (run_name(params) + ".h5")
                if path.exists():
                    if read_run_info(path)["status"] in ("completed", "jammed"):
                        continue
                log.info("simulating missing state point %s", path.name)
                run_state_point(params, path, progress=False)


def graph_settings(cfg: DictConfig) -> GraphSettings:
    values = OmegaConf.to_container(cfg.graph, resolve=True)
    values["edge_features"] = tuple(values["edge_features"])
    values["graph_inputs"] = tuple(values.get("graph_inputs", ()))
    values["noise_range"] = tuple(values.get("noise_range", ()))
    values["axial_noise_range"] = tuple(values.get("axial_noise_range", ()))
    values["targets"] = TargetSpec.from_config(values.get("targets"))
    return GraphSettings(**values)


def input_sizes(settings: GraphSettings) -> dict:
    """The input sizes of ``model.net`` that the graph settings decide (not options of their own): node
    features (the one-hot radius), edge features and graph-level inputs; ``setup_fold`` completes the
    network's partial with them."""
    return {
        "node_in": NODE_FEATURES,
        "edge_in": len(settings.edge_features),
        "global_in": len(settings.graph_inputs),
    }


def setup_fold(cfg: DictConfig, k: int, settings: GraphSettings):
    """(datamodule, module) of fold ``k``: split made, target and edge-feature scaling fitted on its
    training part and set in the (untrained) module."""
    dm = instantiate(cfg.data, graph=settings, fold=k, _convert_="all")
    dm.setup()
    module = instantiate(
        cfg.model,
        net=input_sizes(settings),
        targets=settings.targets.to_config(),
        graph_inputs=list(settings.graph_inputs),
        state_mean_by_stress=settings.stress_known,
        _convert_="all",
    )
    train = torch.as_tensor(dm.train_idx)
    module.fit_target_scaling(
        dm.dataset.y[train],
        dm.dataset.stress[train],
        dm.dataset.u[train],
        phi=dm.dataset.phi[train],
        jammed=dm.dataset.jammed[train],
    )
    module.net.set_edge_scaling(dm.edge_mean, dm.edge_std)
    return dm, module


def _unreadable_checkpoint(path: Path) -> str:
    """Why the checkpoint at ``path`` cannot be read as tensors and plain values ('' if it can).  Read
    with ``torch.load(weights_only=True)``: a run directory may come from elsewhere, and an object in it
    must never be unpickled (what Lightning writes needs nothing more)."""
    try:
        torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated, garbage or pickled objects: whatever the unpickler raises
        text = str(exc).strip()
        if text.startswith("Weights only load failed"):
            return "it holds objects other than tensors and plain values"
        return (text.splitlines() or [type(exc).__name__])[0][:160]
    return ""


def train_fold(
    cfg: DictConfig, run_dir: Path, k: int, settings: GraphSettings, extra_callbacks: list = ()
) -> tuple[dict, dict]:
    """Train, test and save fold ``k``; returns (result row, test predictions with baselines).
    ``extra_callbacks`` join the configured Lightning callbacks (the search's per-epoch pruning)."""
    import lightning as L
    from lightning.pytorch.callbacks import ModelCheckpoint

    L.seed_everything(int(cfg.seed) + k, workers=True)
    dm, module = setup_fold(cfg, k, settings)
    dm.save_split(run_dir / f"fold{k}_split.json")
    # a fold killed mid-way resumes from its last finished epoch, not its first (check_resumable has
    # already refused another configuration or other data in this run directory)
    resume_dir = run_dir / f"fold{k}_resume"
    resume_point = resume_dir / "last.ckpt"
    callbacks = [instantiate(c) for c in cfg.callbacks.values()] + list(extra_callbacks)
    for callback in callbacks:
        if isinstance(callback, EpochLog):
            callback.label = f"fold {k}"
        # the best-so-far weights are scratch of an unfinished fold (fold<k>.pt keeps them once it
        # finishes): beside the resume point and removed with it, not left in the run or TensorBoard folder
        if isinstance(callback, ModelCheckpoint) and callback.dirpath is None:
            callback.dirpath = str((resume_dir / "best").resolve())
    resume = FoldResumePoint(resume_dir)
    logger = instantiate(cfg.logger, version=f"fold{k}") if cfg.get("logger") else False
    trainer = instantiate(
        cfg.trainer, callbacks=[*callbacks, resume], logger=logger, default_root_dir=str(resume_dir)
    )
    if resume_point.exists():
        # the resume point and the best-so-far weights it refers to: both are read back
        for path in [resume_point, *sorted((resume_dir / "best").glob("*.ckpt"))]:
            why = _unreadable_checkpoint(path)
            if why:
                log.warning(
                    "fold %d: %s is unreadable (%s; killed while writing it?): the fold starts again",
                    k,
                    path,
                    why,
                )
                resume_point.unlink()
                shutil.rmtree(resume_dir / "best", ignore_errors=True)
                break
    if resume_point.exists():
        log.info("fold %d: resuming from its last finished epoch (%s)", k, resume_point)
    fitted = np.r_[dm.train_idx, dm.val_idx]  # baselines have no early stopping: fit on both
    fit_baselines = functools.partial(
        baseline_predictions,
        dataset_arrays(dm.dataset, fitted),
        dataset_arrays(dm.dataset, dm.test_idx),
        settings.targets,
    )
    # while a GPU trains the network the CPU idles: the descriptor baselines (two gradient-boosted tree
    # models, ~6 s a demo fold, longer than the fold's training on a GPU) are fitted alongside, in a
    # thread (their fits run in compiled code, outside the interpreter lock); on a CPU, after it
    alongside = ThreadPoolExecutor(1) if baselines_alongside(trainer) else None
    baselines_future = alongside.submit(fit_baselines) if alongside else None
    try:
        trainer.fit(
            module,
            datamodule=dm,
            ckpt_path=str(resume_point) if resume_point.exists() else None,
            weights_only=True,
        )
    finally:
        if alongside:
            alongside.shutdown(wait=True)
    ckpt = next((c for c in callbacks if hasattr(c, "best_model_path")), None)
    if ckpt is not None and ckpt.best_model_path:
        state = torch.load(ckpt.best_model_path, map_location="cpu", weights_only=True)["state_dict"]
        module.load_state_dict(state)
    best_val = (
        float(ckpt.best_model_score)
        if ckpt is not None and ckpt.best_model_score is not None
        else float(trainer.callback_metrics.get("val/loss", np.nan))
    )
    if not np.isfinite(best_val):
        raise FloatingPointError(f"fold {k}: validation loss is {best_val} (diverged)")
    test_metrics = trainer.test(module, datamodule=dm, verbose=False)[0]
    pred, true, meta = predict_dataset(module, dm.graphs(dm.test_idx))
    baselines = baselines_future.result() if baselines_future else fit_baselines()
    prediction = dict(fold=k, pred=pred, true=true, baselines=baselines, **meta)
    save_bundle(run_dir / f"fold{k}.pt", module, settings, k, dm.split, dm.domain)
    result = {"fold": k, "val/loss": best_val, **{k2: float(v) for k2, v in test_metrics.items()}}
    jam = jam_rule_scores(dm.domain["jam_map"], meta["phi"], meta["stress"], meta["run_id"], meta["jammed"])
    result.update({f"test/{name}": value for name, value in jam.items()})
    groups = state_point_key(meta["phi"], meta["stress"])
    for name, value in fold_metrics(pred, true, groups, meta["jammed"]).items():
        result[f"test/{name}"] = value
    for model_name, model_pred in baselines.items():
        for name, value in fold_metrics(model_pred, true, groups, meta["jammed"]).items():
            result[f"baseline/{model_name}/{name}"] = value
    save_finished_fold(run_dir, k, result, prediction)
    shutil.rmtree(resume_dir, ignore_errors=True)  # finished: the bundle is what is kept
    if logger:
        logger.log_hyperparams(
            _flat_hparams(cfg),
            {"hp/" + key.replace("/", "_"): v for key, v in result.items() if key != "fold"},
        )
    return result, prediction


def baselines_alongside(trainer) -> bool:
    """Whether a fold's baselines are fitted while ``trainer`` trains its network: on a GPU."""
    return trainer.strategy.root_device.type == "cuda"


class _RelayToLoggers(logging.Handler):
    """Hands a record from a fold process to the logger of its name in this process, whose handlers
    (Hydra's console and ``train.log``) write it."""

    def emit(self, record: logging.LogRecord) -> None:
        logging.getLogger(record.name).handle(record)


GPU_ACCELERATORS = ("gpu", "cuda")

# the GPU a fold process trains on (set once per process by _pin_fold_process; None on the CPU)
_fold_device: int | None = None


def _pin_fold_process(device_queue) -> None:
    """Initialiser of a fold process on a GPU machine: takes one device index for all its folds."""
    global _fold_device
    _fold_device = device_queue.get()
    torch.cuda.set_device(_fold_device)


def fold_process_devices(cfg: DictConfig, workers: int) -> list[int] | None:
    """The GPU index of each of ``workers`` fold processes (in turn over the visible GPUs, so that with
    as many processes as GPUs each has its own), or None when training on the CPU."""
    if str(cfg.trainer.get("accelerator", "cpu")) not in GPU_ACCELERATORS:
        return None
    count = torch.cuda.device_count()
    return [k % count for k in range(workers)]


def _fold_process(cfg_yaml: str, run_dir: str, k: int, log_queue) -> None:
    """Entry of one fold process (``fold_workers`` > 1): one torch thread, results to ``run_dir``, log
    records (the per-epoch lines) to the parent through ``log_queue``; on a GPU machine the trainer uses
    the process's own device.  The OpenMP wait policy is inherited from the parent's environment (set by
    the entry points before torch loads: OpenMP reads it once)."""
    root = logging.getLogger()
    root.handlers = [logging.handlers.QueueHandler(log_queue)]
    root.setLevel(logging.INFO)
    cfg = OmegaConf.create(cfg_yaml)
    if _fold_device is not None:
        cfg.trainer.devices = [_fold_device]
    torch.set_num_threads(1)
    logging.getLogger("lightning.pytorch.utilities.rank_zero").setLevel(logging.WARNING)
    train_fold(cfg, Path(run_dir), k, graph_settings(cfg))


def train_folds_in_processes(cfg: DictConfig, run_dir: Path, folds: list[int]) -> None:
    """Train ``folds`` in ``cfg.fold_workers`` parallel processes (one per core, one thread each); each
    writes its finished-fold files, which the caller then collects like a resumed run's."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    if not folds:
        return
    # the graph cache is built once, here, not by every process at the same time
    instantiate(cfg.data, graph=graph_settings(cfg), fold=0, _convert_="all").setup()
    cfg_yaml = OmegaConf.to_yaml(cfg, resolve=True)
    workers = min(int(cfg.fold_workers), len(folds))
    log.info("training folds %s in %d processes", folds, workers)
    context = mp.get_context("spawn")
    devices = fold_process_devices(cfg, workers)
    with context.Manager() as manager:
        log_queue = manager.Queue()
        pinning = {}
        if devices is not None:
            log.info("fold processes on GPUs %s", devices)
            device_queue = manager.Queue()
            for device in devices:
                device_queue.put(device)
            pinning = {"initializer": _pin_fold_process, "initargs": (device_queue,)}
        listener = logging.handlers.QueueListener(log_queue, _RelayToLoggers())
        listener.start()
        try:
            with ProcessPoolExecutor(max_workers=workers, mp_context=context, **pinning) as pool:
                futures = [pool.submit(_fold_process, cfg_yaml, str(run_dir), k, log_queue) for k in folds]
                for future in futures:
                    future.result()  # re-raises a fold's error here
        finally:
            listener.stop()


def folds_to_train(cfg: DictConfig) -> list[int]:
    """The folds ``cfg.fold`` selects: null = all ``data.num_folds``, an integer or a list of them."""
    num_folds = int(cfg.data.num_folds)
    check_num_folds(num_folds)
    chosen = cfg.get("fold")
    if chosen is None:
        return list(range(num_folds))
    folds = [chosen] if isinstance(chosen, int) else list(chosen)
    if not folds or any(not isinstance(k, int) or not 0 <= k < num_folds for k in folds):
        raise InputError(
            f"fold={chosen} is invalid: null, or an integer or list of integers in 0..{num_folds - 1}"
        )
    return folds


def check_run_settings(cfg: DictConfig) -> None:
    """How a run trains, refused by name before any work: an epoch budget of at least one (the cosine
    schedule spans it: Lightning's -1 for "unlimited" would make it oscillate), threads >= 1 or null
    (null: the cores this process may use, at most 2), fold processes >= 1, an optimiser and schedule
    that torch accepts."""
    flat = [key for key in cfg.model if key in LEGACY_NET_OPTIONS]
    if flat:  # an experiment file of an earlier version: the network's options moved under model.net
        raise InputError(
            f"model.{flat[0]} is an option of the network: set model.net.{flat[0]} (model.net holds "
            f"the network's options: {', '.join(f'model.{k}' for k in flat)})"
        )
    check_training_factories(instantiate(cfg.model.optimizer), instantiate(cfg.model.get("scheduler")))
    epochs = cfg.trainer.get("max_epochs")
    if not isinstance(epochs, int) or epochs < 1:
        raise InputError(f"trainer.max_epochs={epochs} is invalid: allowed an integer >= 1")
    for key, low in (("threads", 1), ("fold_workers", 1)):
        value = cfg.get(key)
        if value is not None and (not isinstance(value, int) or value < low):
            raise InputError(f"{key}={value} is invalid: allowed an integer >= {low}")
    accelerator = str(cfg.trainer.get("accelerator", "cpu"))
    if accelerator in GPU_ACCELERATORS and not torch.cuda.is_available():
        raise InputError(
            f"trainer.accelerator={accelerator}: no CUDA GPU is visible to this process "
            "(torch.cuda.is_available() is false): train on the CPU with trainer=cpu (the default)"
        )
    in_processes = int(cfg.get("fold_workers") or 1) > 1 and len(folds_to_train(cfg)) > 1
    if "ddp" in str(cfg.trainer.get("strategy", "")) and in_processes:
        raise InputError(
            f"fold_workers={cfg.fold_workers} with trainer.strategy={cfg.trainer.strategy}: a fold process "
            "cannot start the processes of a data-parallel fold; use fold_workers=1 with trainer=ddp*, or "
            "fold processes (one per device) without it"
        )


def train_folds(cfg: DictConfig, run_dir: Path, fold_callbacks=None) -> dict:
    """Train the configured folds; write bundles, splits, predictions and the report into ``run_dir``.

    Returns the mean (over folds) of every test metric plus ``val/loss`` (the mean best validation loss).
    ``fold_callbacks(position, k)`` (the hyperparameter search) returns extra Lightning callbacks for the
    ``position``-th trained fold ``k``; folds then train in this process, one after the other.
    """
    check_run_settings(cfg)
    # default: the cores this process may run on (taskset, a SLURM cpuset), at most 2 — not the machine's
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    threads = cfg.get("threads") or max(1, min(2, usable))
    torch.set_num_threads(threads)
    ensure_dataset(cfg)
    settings = graph_settings(cfg)
    run_dir.mkdir(parents=True, exist_ok=True)
    check_resumable(cfg, run_dir)
    folds = folds_to_train(cfg)
    workers = int(cfg.get("fold_workers") or 1)
    in_processes = []
    if workers > 1 and fold_callbacks is None and len(folds) > 1:
        in_processes = [k for k in folds if load_finished_fold(run_dir, k) is None]
        train_folds_in_processes(cfg, run_dir, in_processes)
    fold_results, predictions = [], []
    for position, k in enumerate(folds):
        finished = load_finished_fold(run_dir, k)
        if finished is not None:  # trained by a fold process just now, or by an earlier run: kept
            if k not in in_processes:
                log.info("fold %d was finished by an earlier run into %s: kept", k, run_dir)
            result, prediction = finished
        else:
            extra = fold_callbacks(position, k) if fold_callbacks is not None else []
            result, prediction = train_fold(cfg, run_dir, k, settings, extra)
        fold_results.append(result)
        predictions.append(prediction)
    stacked = _stack_predictions(predictions)
    np.savez_compressed(run_dir / "test_predictions.npz", **stacked)
    if cfg.data.split != "random":  # held-out trajectories (or phi): residuals of unseen data only
        model = fit_error_model(
            stacked["pred"], stacked["true"], stacked["stress"], stacked["phi"], stacked["jammed"]
        )
        write_error_model(run_dir, model)
    # folds kept from an earlier version may lack newer metrics: those average over the folds that have them
    keys = dict.fromkeys(key for r in fold_results for key in r if key != "fold")
    with warnings.catch_warnings():  # a metric undefined in every fold (e.g. no jammed run) stays NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        summary = {key: float(np.nanmean([r.get(key, np.nan) for r in fold_results])) for key in keys}
    (run_dir / "metrics.json").write_text(
        json.dumps({"folds": fold_results, "mean": summary, "split": cfg.data.split}, indent=1)
    )
    if cfg.get("report", True):
        from rheograph.learn.report import write_report

        write_report(run_dir, fold_results, predictions, split=cfg.data.split)
    return summary


NEUTRAL_LATER_OPTIONS = (
    ("data", "train_fraction", 1.0),
    ("model", "global_mixing", "none"),
    # the target specification enters in the form of earlier versions (config_fingerprint)
    ("graph", "z_mu_on_count", False),
    ("graph", "viscosity_on_solve", False),
    ("graph", "viscosity_on_relaxed", False),
    ("graph", "noise_range", []),
    ("graph", "noise_copies", 0),
    ("graph", "axial_noise_range", []),
    ("graph", "optical_axis", "y"),
    ("graph", "relax_strain", 0.0),
    ("graph", "stress_known", True),
    ("model", "on_state_mean", False),
)


DEFAULT_NET_TARGET = "rheograph.learn.model.ResGCN"


def legacy_model_options(model: dict) -> dict:
    """``model`` settings with the network (``model.net``) in the form of earlier versions, in which runs
    trained before it have their fingerprint: its options flat among the model's, its ``_target_`` left
    out where it is the ResGCN (then the only network) and kept as ``net_target`` otherwise."""
    model = dict(model)
    net = model.pop("net", None)
    if not isinstance(net, dict):
        return model if net is None else {**model, "net": net}
    target = net.get("_target_")
    options = {k: v for k, v in net.items() if not k.startswith("_")}
    if target != DEFAULT_NET_TARGET:
        options["net_target"] = target
    return {**model, **options}


def config_fingerprint(cfg: DictConfig) -> str:
    """Hash of everything that determines the trained folds (not which folds run, nor reporting)."""
    import hashlib

    skip = ("fold", "report", "threads", "fold_workers")  # how and which folds run, not what they learn
    keep = {k: v for k, v in OmegaConf.to_container(cfg, resolve=True).items() if k not in skip}
    # how batches are assembled, not which: the device-resident batches equal the per-batch loader's
    keep.get("data", {}).pop("device_resident", None)
    # the target specification in the form of earlier versions (graph.* booleans and scales), in which
    # runs trained before it have their fingerprint
    graph = keep.get("graph", {})
    if "targets" in graph:
        graph.update(TargetSpec.from_config(graph.pop("targets")).legacy_options())
    # the network's options in the form of earlier versions, flat among the model's (model.hidden, ...)
    keep["model"] = legacy_model_options(keep.get("model", {}))
    # options added later, at the value that reproduces what came before them: left out, so that runs
    # trained before the option existed stay valid (resumable, reportable)
    for group, key, neutral in NEUTRAL_LATER_OPTIONS:
        if keep.get(group, {}).get(key, neutral) == neutral:
            keep.get(group, {}).pop(key, None)
    keep["split_version"] = SPLIT_VERSION  # the fold assignment is code, not configuration
    return hashlib.sha1(json.dumps(keep, sort_keys=True, default=str).encode()).hexdigest()[:16]


def run_stamps(cfg: DictConfig) -> dict[str, str]:
    """What a run directory of this configuration holds, by stamp file: the configuration's fingerprint and
    that of the trajectory files it selects (``data_fingerprint``: added, extended or resimulated files
    change it)."""
    files = instantiate(cfg.data, graph=graph_settings(cfg), _convert_="all").selected_files()
    return {
        "config_fingerprint.txt": config_fingerprint(cfg),
        "data_fingerprint.txt": data_fingerprint(files),
    }


def stamps_differ(run_dir: Path, stamps: dict[str, str]) -> list[str]:
    """The stamp files of ``run_dir`` that hold something else than ``stamps``, or are missing next to
    finished folds (what those folds were trained with is then unknown: never stamped after the fact)."""
    trained = any(run_dir.glob("fold*_result.json"))

    def differs(name: str, value: str) -> bool:
        path = run_dir / name
        return path.read_text().strip() != value if path.exists() else trained

    return [name for name, value in stamps.items() if differs(name, value)]


def check_resumable(cfg: DictConfig, run_dir: Path) -> None:
    """A run directory holds folds of one configuration trained on one set of data: rerunning the same
    command into it (e.g. ``hydra.run.dir=<that run>``) resumes; another configuration, or trajectory
    files that changed since, are refused."""
    stamps = run_stamps(cfg)
    differ = stamps_differ(run_dir, stamps)
    if "config_fingerprint.txt" in differ:
        raise OtherRunError(
            f"{run_dir} holds folds trained with another configuration: resume with the same overrides, "
            "or train into a new directory"
        )
    if differ:
        raise OtherRunError(
            f"{run_dir} holds folds trained on other data (trajectory files added, removed, extended or "
            "resimulated since) or on data it did not record: train into a new directory"
        )
    for name, value in stamps.items():
        (run_dir / name).write_text(value + "\n")


def save_finished_fold(run_dir: Path, k: int, result: dict, prediction: dict) -> None:
    """Written last, after the fold's bundle: its presence marks fold k as finished."""
    arrays = {key: value for key, value in prediction.items() if key != "baselines"}
    arrays.update({f"baseline_{name}": value for name, value in prediction.get("baselines", {}).items()})
    np.savez_compressed(run_dir / f"fold{k}_predictions.npz", **arrays)
    tmp = run_dir / f"fold{k}_result.json.tmp"
    tmp.write_text(json.dumps(result))
    tmp.replace(run_dir / f"fold{k}_result.json")


def load_finished_fold(run_dir: Path, k: int):
    """(result, prediction) of a fold finished earlier in ``run_dir``, or None."""
    done = run_dir / f"fold{k}_result.json"
    if not (done.exists() and (run_dir / f"fold{k}.pt").exists()):
        return None
    return json.loads(done.read_text()), read_fold_predictions(run_dir, k)


def read_fold_predictions(run_dir: Path, k: int) -> dict:
    """Fold k's test predictions as ``save_finished_fold`` wrote them: ``pred``, ``true`` (G, 3),
    ``stress``, ``phi``, ``run_id``, ``jammed`` (G,), ``fold`` and ``baselines`` {name: (G, 3)}."""
    with np.load(Path(run_dir) / f"fold{k}_predictions.npz") as data:
        arrays = {key: data[key] for key in data.files}
    baselines = {
        key[len("baseline_") :]: arrays.pop(key) for key in list(arrays) if key.startswith("baseline_")
    }
    arrays["fold"] = int(arrays["fold"])
    return {**arrays, "baselines": baselines}


def _stack_predictions(predictions) -> dict:
    out = {}
    for key in ("pred", "true", "stress", "phi", "run_id", "jammed"):
        out[key] = np.concatenate([p[key] for p in predictions])
    if all("n_particles" in p for p in predictions):  # folds finished before it was recorded lack it
        out["n_particles"] = np.concatenate([p["n_particles"] for p in predictions])
    for name in predictions[0].get("baselines", {}):
        out[f"baseline_{name}"] = np.concatenate([p["baselines"][name] for p in predictions])
    out["fold"] = np.concatenate([np.full(p["pred"].shape[0], p["fold"]) for p in predictions])
    out["targets"] = np.array(TARGET_NAMES)
    return out


def _flat_hparams(cfg: DictConfig) -> dict:
    """``model.optimizer.lr``-style keys of the model, graph and data settings (TensorBoard's hparams)."""
    flat = {}

    def walk(prefix: str, node) -> None:
        for key, value in node.items():
            if key.startswith("_"):
                continue
            if isinstance(value, dict):
                walk(f"{prefix}.{key}", value)
            else:
                flat[f"{prefix}.{key}"] = value if isinstance(value, int | float | str | bool) else str(value)

    for group in ("model", "graph", "data"):
        walk(group, OmegaConf.to_container(cfg[group], resolve=True))
    return flat
