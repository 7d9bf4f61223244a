"""K-fold LightningDataModule over snapshot graphs.

Splits (``split``): ``random`` shuffles snapshots (the seed paper's choice; snapshots of one trajectory are
correlated, so test scores are optimistic) or ``grouped`` keeps every run (trajectory file) inside one
fold — the honest estimate on trajectories the model has never seen — with the runs of each state point
(phi, sigma) spread over every other fold (f, f + 2, ...), so that with >= 3 seeds per state point every
stress is present in the training part of every fold.  Fold k is the test set, fold (k + 1) mod K the
validation set (early stopping, checkpointing), the rest the training set.  Target and edge-feature
standardisation are fitted on the training part only.

With ``device_resident`` (the default) each of the three graph sets is collated once and kept on the
trainer's device, and every mini-batch is built there by indexing (``rheograph.learn.device_batch``):
the same batches, in the same order, as PyG's loader, without per-batch collation or copies. Training
graphs re-noised at every epoch (``graph.noise_range`` without ``noise_copies``) cannot be kept: they
are rebuilt and collated per batch as before (their fixed-noise validation and test graphs are kept).
"""

from __future__ import annotations

import dataclasses
import glob
import json
import logging
from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch_geometric.loader import DataLoader

from rheograph.errors import InputError
from rheograph.graphs.batched_solve import physics_solver_device
from rheograph.graphs.dataset import SOLVE_NUMERICS, GraphSettings, NoisyGraphs, SnapshotGraphDataset
from rheograph.io.configurations import PHYSICAL_PARAMS
from rheograph.io.hdf5 import read_params
from rheograph.io.index import index_files
from rheograph.io.snapshots import read_snapshots, source_kind
from rheograph.learn.device_batch import DeviceGraphSet, device_loader
from rheograph.learn.jamming import fit_jam_map
from rheograph.naming import state_point_key
from rheograph.sim.params import SimParams

log = logging.getLogger("rheograph")

SPLITS = ("random", "grouped", "phi")
LISTED_FILES = 10  # files named in the warning about files left out of a training set (then a count)


# bumped when the fold assignment changes, so that run directories trained on other splits are not
# resumed as if they were the same configuration (rheograph.learn.train.config_fingerprint)
SPLIT_VERSION = 2  # 2: state points' runs in every other fold (1: consecutive folds)


def kfold_assignment(
    n_items: int,
    num_folds: int,
    seed: int,
    groups: np.ndarray | None = None,
    strata: np.ndarray | None = None,
) -> np.ndarray:
    """Fold index (0..K-1) of every item; with ``groups`` all items of a group share a fold.

    With ``strata`` (one label per item, constant within a group: the state point of a run) the groups
    of each stratum go to every other fold (f, f + 2, f + 4, ... mod K), continuing where the previous
    stratum ended, so that folds hold equal numbers of groups and a stratum with g groups appears in
    min(g, K) folds.  Every other, not consecutive: fold k is tested with fold k + 1 as validation, so
    with consecutive folds a state point with two runs (N = 2000) would have its second run in the
    validation fold and none in training, turning a held-out trajectory into an unseen stress.  With
    odd K (default 5) each state point with >= 2 runs keeps one in training for every test fold.
    """
    rng = np.random.default_rng(seed)
    if groups is None:
        order = rng.permutation(n_items)
        folds = np.empty(n_items, dtype=np.int64)
        folds[order] = np.arange(n_items) % num_folds
        return folds
    unique = np.unique(groups)
    if unique.size < num_folds:
        raise InputError(f"grouped split needs at least num_folds={num_folds} runs, got {unique.size}")
    if strata is not None:
        stratum_of = {g: strata[np.flatnonzero(groups == g)[0]] for g in unique}
        # every other fold; for even K the evens then the odds (not every pair avoids k, k + 1 there)
        order = (
            [(2 * i) % num_folds for i in range(num_folds)]
            if num_folds % 2
            else (list(range(0, num_folds, 2)) + list(range(1, num_folds, 2)))
        )
        fold_of, position = {}, int(rng.integers(num_folds))
        for stratum in sorted(set(stratum_of.values())):
            members = rng.permutation([g for g in unique if stratum_of[g] == stratum])
            for g in members:
                fold_of[g] = order[position]
                position = (position + 1) % num_folds
        return np.array([fold_of[g] for g in groups], dtype=np.int64)
    # greedy balancing: largest groups first into the currently smallest fold (ties broken by seed)
    sizes = {g: int(np.sum(groups == g)) for g in unique}
    order = sorted(rng.permutation(unique), key=lambda g: -sizes[g])
    load = np.zeros(num_folds, dtype=np.int64)
    fold_of = {}
    for g in order:
        f = int(np.argmin(load + rng.random(num_folds) * 1e-3))
        fold_of[g] = f
        load[f] += sizes[g]
    return np.array([fold_of[g] for g in groups], dtype=np.int64)


class SnapshotDataModule(L.LightningDataModule):
    """Fold ``fold`` of a K-fold split (module docstring) of the snapshot graphs of ``files`` (trajectory
    files, LF_DEM runs, globs or an index .json), built once with ``graph`` settings into ``cache_dir``;
    ``phi`` / ``n_particles`` select the files of one area fraction / system size (null: all),
    ``train_fraction`` < 1 keeps that share of each training run's snapshots, ``device_resident`` keeps the
    graph sets collated on the trainer's device (module docstring; ``num_workers`` loader processes serve
    only the per-batch path: false, or re-noised training graphs), ``physics_solver`` how the cache's
    physics inputs are solved (``rheograph.graphs.batched_solve``; ``auto``: in dense batches on the
    trainer's GPU, sparse on a CPU).  Configured by the ``data``
    group (``conf/data/``); ``setup`` makes the split and fits the standardisation on the training part."""

    def __init__(
        self,
        files: list[str] | str,
        cache_dir: str = "data/cache",
        graph: GraphSettings | dict | None = None,
        fold: int = 0,
        num_folds: int = 5,
        split: str = "random",
        split_seed: int = 0,
        batch_size: int = 16,
        num_workers: int = 0,
        phi: float | None = None,
        n_particles: int | None = None,
        train_fraction: float = 1.0,
        lfdem_params: str | None = None,
        device_resident: bool = True,
        physics_solver: str = "auto",
    ):
        super().__init__()
        physics_solver_device(physics_solver, torch.device("cpu"), 0)  # an unknown choice refused here
        if split not in SPLITS:
            raise InputError(f"data.split={split!r} is invalid: allowed {SPLITS}")
        check_num_folds(num_folds)
        if not 0 <= fold < num_folds:
            raise InputError(f"fold={fold} is invalid: allowed 0..{num_folds - 1}")
        if not 0.0 < train_fraction <= 1.0:
            raise InputError(f"data.train_fraction={train_fraction} is invalid: allowed (0, 1]")
        if batch_size < 1:
            raise InputError(f"data.batch_size={batch_size} is invalid: allowed >= 1")
        self.files = expand_files(files)
        self.graph = graph if isinstance(graph, GraphSettings) else GraphSettings(**(graph or {}))
        self.cache_dir, self.fold, self.num_folds = cache_dir, fold, num_folds
        self.split, self.split_seed, self.batch_size = split, split_seed, batch_size
        self.num_workers, self.phi, self.n_particles = num_workers, phi, n_particles
        self.train_fraction = train_fraction
        self.lfdem_params = lfdem_params
        self.device_resident = device_resident
        self.physics_solver = physics_solver
        self.device_sets = {}  # {(stage, device): DeviceGraphSet}, built on first use
        self.dataset = None
        self.run_params = None  # {run_id: parameter mapping}, for graphs rebuilt from noisy positions

    def selected_files(self) -> list[str]:
        """The trajectory files of ``data.files`` at ``data.phi`` and ``data.n_particles`` (either null: all):
        a model per area fraction (and system size) out of a pooled file list; other files are never read."""
        files = self.files
        for key, wanted in (("phi", self.phi), ("n_particles", self.n_particles)):
            if wanted is None:
                continue
            values = {f: trajectory_param(f, key, self.lfdem_params) for f in files}
            left_out = [f for f in files if not np.isclose(values[f], wanted)]
            files = [f for f in files if f not in left_out]
            if not files:
                raise InputError(
                    f"data.{key}={wanted}: no trajectory with this value in data.files (they hold "
                    f"{key} = {', '.join(f'{v:g}' for v in sorted(set(values.values())))})"
                )
            if left_out:  # said, so that a file meant for the set but made at other settings is noticed
                named = [f"{f} ({key} {values[f]:g})" for f in left_out[:LISTED_FILES]]
                more = len(left_out) - len(named)
                log.warning(
                    "data.%s=%g: %d file(s) of data.files at another %s left out of this training set: %s%s",
                    key, wanted, len(left_out), key, ", ".join(named), f" and {more} more" if more else "",
                )  # fmt: skip
        return files

    def setup(self, stage=None):
        if self.dataset is not None:
            return
        self.files = self.selected_files()
        device = self.trainer.strategy.root_device if self.trainer is not None else torch.device("cpu")
        dataset = SnapshotGraphDataset(
            self.files, self.graph, self.cache_dir, self.lfdem_params, (self.physics_solver, device)
        )
        index = np.arange(len(dataset))
        self.dataset = dataset
        runs = dataset.run_id.numpy()
        state_points = state_point_key(dataset.phi.numpy(), dataset.stress.numpy())
        if self.split == "phi":
            # leave one area fraction out: fold k tests the k-th phi; validation = one in five of the
            # other phi's trajectories (stratified like the grouped split), training = the rest
            phis = np.unique(np.round(dataset.phi.numpy(), 6))
            if phis.size != self.num_folds:
                raise InputError(
                    f"data.split=phi holds out one area fraction per fold: data.num_folds must be "
                    f"{phis.size} (the area fractions {phis.tolist()}), got {self.num_folds}"
                )
            test = np.isclose(dataset.phi.numpy(), phis[self.fold])
            rest = index[~test]
            n_inner = min(5, np.unique(runs[rest]).size)
            inner = kfold_assignment(rest.size, n_inner, self.split_seed, runs[rest], state_points[rest])
            self.test_idx, self.val_idx, self.train_idx = index[test], rest[inner == 0], rest[inner != 0]
        else:
            grouped = self.split == "grouped"
            folds = kfold_assignment(
                index.size,
                self.num_folds,
                self.split_seed,
                runs if grouped else None,
                state_points if grouped else None,
            )
            self.test_idx = index[folds == self.fold]
            self.val_idx = index[folds == (self.fold + 1) % self.num_folds]
            self.train_idx = index[(folds != self.fold) & (folds != (self.fold + 1) % self.num_folds)]
        if self.train_idx.size == 0 or self.val_idx.size == 0:
            raise InputError(
                f"data.num_folds={self.num_folds} with data.split={self.split} leaves fold {self.fold} no "
                f"training or validation snapshots ({index.size} snapshots of {np.unique(runs).size} runs; "
                "fold k tests, fold k+1 validates, the rest train): use more folds or more data"
            )
        if self.train_fraction < 1.0:
            self.train_idx = thin_snapshots(self.train_idx, runs, self.train_fraction)
        # edge-feature standardisation, fitted on the training graphs only (binary and constant
        # features get std 1 where they do not vary)
        train_graphs = self.graphs(self.train_idx)  # as the model sees them (re-noised where trained so)
        edges = torch.cat([train_graphs[k].edge_attr for k in range(len(train_graphs))]).double()
        self.edge_mean = edges.mean(dim=0).float()
        self.edge_std = edges.std(dim=0).clamp_min(1e-6).float()
        extremes = edges
        if self.graph.noise_range and not self.graph.noise_copies:
            # the trained range of the features reaches what the largest trained noise makes
            loudest = NoisyGraphs(
                dataset[torch.as_tensor(self.train_idx)],
                dataclasses.replace(
                    self.graph,
                    noise_range=(self.graph.noise_range[1],) * 2,
                    axial_noise_range=self.graph.axial_noise_range[1:] * 2,
                ),
                self.run_params,
                fresh=False,
                seed=self.split_seed + 1,
            )
            extremes = torch.cat([edges, *(loudest[k].edge_attr.double() for k in range(len(loudest)))])
        train = torch.as_tensor(self.train_idx)
        self.domain = {  # what the model has seen: predict.py flags inputs outside it
            "phi": [float(dataset.phi[train].min()), float(dataset.phi[train].max())],
            "stress": [float(dataset.stress[train].min()), float(dataset.stress[train].max())],
            "n_particles": sorted({int(n) for n in dataset.n_particles[train]}),
            "size_ratio": sorted(
                {round(trajectory_param(f, "size_ratio", self.lfdem_params), 6) for f in self.files}
            ),
            "edge_min": extremes.min(dim=0).values.tolist(),
            "edge_max": extremes.max(dim=0).values.tolist(),
            # which trained state points jammed (rheograph.learn.jamming): the surrogate's jam rule
            "jam_map": fit_jam_map(
                dataset.phi[train].numpy(),
                dataset.stress[train].numpy(),
                dataset.run_id[train].numpy(),
                dataset.jammed[train].numpy(),
            ),
            # the position noise the model was trained on [a] (predict.py flags a snapshot beyond it)
            "position_noise": list(self.graph.noise_range) if self.graph.noise_range else 0.0,
            # 3D confocal training: the noise along the optical axis [a] (graph.optical_axis)
            **({"axial_noise": list(self.graph.axial_noise_range)} if self.graph.axial_noise_range else {}),
            # the suspension a snapshot must match, and the step of the one-solve input (predict.py)
            **suspension_record(self.files, self.lfdem_params),
        }

    def split_record(self) -> dict:
        return {
            "split": self.split,
            "split_seed": self.split_seed,
            "fold": self.fold,
            "num_folds": self.num_folds,
            "train": self.train_idx.tolist(),
            "val": self.val_idx.tolist(),
            "test": self.test_idx.tolist(),
            "files": self.files,
            "cache": self.dataset.digest,
        }

    def save_split(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.split_record()))

    def graphs(self, idx, fresh: bool = False):
        """The graphs at ``idx`` as the model sees them: with ``graph.noise_range``, rebuilt from
        re-noised positions (``fresh``: new noise at every access, else one fixed draw per graph)."""
        subset = self.dataset[torch.as_tensor(idx)]
        if not self.graph.noise_range or self.graph.noise_copies:  # exact, or noisy copies in the cache
            return subset
        if self.run_params is None:
            self.run_params = {
                run_id: read_snapshots(path, self.lfdem_params).graph_params()
                for run_id, path in enumerate(self.dataset.files)
            }
        return NoisyGraphs(subset, self.graph, self.run_params, fresh=fresh, seed=self.split_seed)

    def training_device(self) -> torch.device:
        """The device of the attached trainer's process (its rank's under DDP); the CPU without one."""
        trainer = getattr(self, "trainer", None)
        return trainer.strategy.root_device if trainer is not None else torch.device("cpu")

    def _loader(self, stage: str, idx, shuffle: bool):
        graphs = self.graphs(idx, fresh=shuffle)
        redrawn = shuffle and isinstance(graphs, NoisyGraphs)  # new noise every epoch: nothing to keep
        if not self.device_resident or redrawn:
            return DataLoader(
                graphs, batch_size=self.batch_size, shuffle=shuffle, num_workers=self.num_workers
            )
        device = self.training_device()
        key = (stage, str(device))
        if key not in self.device_sets:
            self.device_sets[key] = DeviceGraphSet(graphs, device)
        return device_loader(self.device_sets[key], self.batch_size, shuffle)

    def train_dataloader(self):
        return self._loader("train", self.train_idx, True)

    def val_dataloader(self):
        return self._loader("val", self.val_idx, False)

    def test_dataloader(self):
        return self._loader("test", self.test_idx, False)


def check_num_folds(num_folds: int) -> None:
    """K-fold cross-validation needs a test and a validation fold: 2..20 folds."""
    if not 2 <= num_folds <= 20:
        raise InputError(f"data.num_folds={num_folds} is invalid: allowed 2..20")


def thin_snapshots(idx: np.ndarray, runs: np.ndarray, fraction: float) -> np.ndarray:
    """Keep ``fraction`` of the snapshots ``idx`` of every run, evenly spaced along it (at least one per
    run): a learning curve in snapshots per trajectory that keeps every run and so every state point.
    ``runs`` (all graphs,) gives each graph's run; graphs of a run are in strain order."""
    kept = []
    for run in np.unique(runs[idx]):
        members = np.sort(idx[runs[idx] == run])
        n_keep = max(1, int(round(fraction * members.size)))
        kept.append(members[np.unique(np.round(np.linspace(0, members.size - 1, n_keep)).astype(np.int64))])
    return np.sort(np.concatenate(kept))


def source_summary(path: str, lfdem_params=None) -> dict:
    """State point, N, physical parameters and simulation step of a snapshot source: ``phi``,
    ``stress``, ``n_particles``, ``params`` (physical), ``numerics`` (rheograph.io.snapshots) and the
    space dimension ``dim`` (2 or 3)."""
    if source_kind(path) == "rheograph":
        try:
            stored = read_params(path)  # the parameters only: no snapshot is read
            return {
                "phi": float(stored["phi"]),
                "stress": float(stored["stress"]),
                "n_particles": int(stored["n_particles"]),
                "params": {k: stored[k] for k in PHYSICAL_PARAMS if k in stored},
                "numerics": {k: stored[k] for k in SOLVE_NUMERICS if k in stored},
                "dim": int(stored.get("dim", 2)),
            }
        except (OSError, KeyError, ValueError, TypeError):
            pass  # held by a running simulation, or without readable root params: the reader says what
    snaps = read_snapshots(path, lfdem_params)
    return {
        "phi": snaps.phi,
        "stress": snaps.stress,
        "n_particles": snaps.n_particles,
        "params": snaps.params,
        "numerics": snaps.numerics,
        "dim": snaps.dim,
    }


def trajectory_param(path: str, key: str, lfdem_params=None) -> float:
    """``phi``, ``stress``, ``n_particles`` or a physical parameter of a snapshot source."""
    summary = source_summary(path, lfdem_params)
    value = summary[key] if key in summary else summary["params"].get(key)
    if value is None:
        raise InputError(f"{path}: does not record its parameter {key}")
    return float(value)


def suspension_record(files, lfdem_params=None) -> dict:
    """What a model trained on ``files`` needs a snapshot to match, and how its one-solve input was
    computed: ``physical_params`` (PHYSICAL_PARAMS, one value each: files of different suspensions are
    refused, a model has no input for them) and ``solve_numerics``, per area fraction and N the step
    (``disp_max``, ``dt_max``, ``lagged_step_control``) the one-solve input of its graphs used, and the
    space dimension ``dim`` of its snapshots (2 or 3; 2D and 3D files are refused together)."""
    physical, numerics, dims = {}, {}, set()
    defaults = SimParams.defaults()
    for path in files:
        summary = source_summary(path, lfdem_params)
        dims.add(summary["dim"])
        for key in PHYSICAL_PARAMS:
            if key not in summary["params"]:
                raise InputError(f"{path}: does not record the physical parameter {key}")
            physical.setdefault(key, set()).add(round(float(summary["params"][key]), 9))
        step = {k: summary["numerics"].get(k, defaults[k]) for k in SOLVE_NUMERICS}
        key = (round(summary["phi"], 6), summary["n_particles"])
        numerics.setdefault(key, set()).add(tuple(step.items()))
    if len(dims) > 1:
        raise InputError(
            "data.files mixes 2D and 3D snapshots: a model is 2D or 3D; train one model per dimension"
        )
    mixed = {k: sorted(v) for k, v in physical.items() if len(v) > 1}
    if mixed:
        raise InputError(
            f"data.files mixes suspensions ({mixed}): a model has no input for these parameters; train one "
            "model per suspension"
        )
    solve = []
    for (phi, n), steps in sorted(numerics.items()):
        if len(steps) > 1:
            raise InputError(
                f"data.files: the runs at phi = {phi:g}, N = {n} were made with different steps "
                f"{sorted(steps)}: their one-solve inputs would not be computed alike"
            )
        solve.append({"phi": phi, "n_particles": n, **dict(next(iter(steps)))})
    return {
        "physical_params": {k: next(iter(v)) for k, v in physical.items()},
        "solve_numerics": solve,
        "dim": dims.pop() if dims else 2,
    }


def split_files(split: dict, root: str | Path = ".") -> list[str]:
    """The trajectory files a fold's split record lists, found in this clone: the record holds the
    absolute paths of the machine that trained, so a path that does not exist here is looked up under
    ``root`` by its part from ``data/`` on."""
    return [
        f if Path(f).exists() or "data/" not in f else str(Path(root) / f[f.index("data/") :])
        for f in split["files"]
    ]


def expand_files(files) -> list[str]:
    """Expand glob patterns and sweep indexes (``*.json`` from ``rheograph.runs.sweep_index``) into a
    sorted list."""
    patterns = [files] if isinstance(files, str) else list(files)
    out = set()
    for pattern in patterns:
        if str(pattern).endswith(".json") and Path(pattern).is_file():
            out.update(index_files(pattern))
        else:
            out.update(glob.glob(str(pattern), recursive=True))
    out = sorted(out)
    if not out:
        raise InputError(f"data.files={patterns} matches no trajectory file")
    return out
