"""PyG dataset of snapshot graphs built from trajectory files, cached under a settings hash."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import os
import shutil
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch_geometric.data import Data, InMemoryDataset

from rheograph.errors import InputError
from rheograph.graphs.batched_solve import DenseBatchSolver, physics_solver_device
from rheograph.graphs.features import (
    COMPUTED_GRAPH_INPUTS,
    EDGE_FEATURES,
    GRAPH_INPUTS,
    HISTORY_EDGE_FEATURES,
    PAPER_EDGE_FEATURES,
    RELAXED_GRAPH_INPUTS,
    SHELL_INPUTS,
    SHELL_WIDTHS,
    STRESS_EDGE_FEATURES,
    check_separations,
    forward_transform,
    node_features,
    one_solve_viscosity,
    relax_positions,
    relax_simulations,
    shell_inputs,
    snapshot_descriptors,
    snapshot_edges,
    snapshot_simulation,
    solve_viscosity,
)
from rheograph.graphs.features3d import (
    EDGE_FEATURES_3D_ONLY,
    check_separations3d,
    relax_positions3d,
    snapshot_edges3d,
    snapshot_simulation3d,
    solve_viscosity3d,
    step_pressure3d,
)
from rheograph.graphs.targets import TargetSpec
from rheograph.io.configurations import Snapshots, wrap_into_box, wrap_into_box3d
from rheograph.io.hdf5 import SCHEMA_VERSION
from rheograph.io.snapshots import read_snapshots
from rheograph.resources import check_memory, graph_bytes
from rheograph.sim.integrator import particle_pressure, solve_configurations
from rheograph.sim.solver import DeferredAnalysis, make_solver

TARGETS = ("viscosity", "pressure", "z_mu")
# the step settings of the one-solve input (rheograph.graphs.features.solve_viscosity): numerics of the
# model, recorded in its bundle, not of the snapshot
SOLVE_NUMERICS = ("disp_max", "dt_max", "lagged_step_control")
AXES = ("x", "y", "z")  # flow, gradient, vorticity
# snapshots whose simulations are stepped together in dense batches (``_solved_together``): batches of
# this many problems for the device, and the memory their simulations hold at once bounded
SOLVED_TOGETHER = 64
log = logging.getLogger("rheograph.graphs")


@dataclass(frozen=True)
class GraphSettings:
    """Everything that determines a graph and its targets (hashed into the cache directory name, except
    what the targets are learned relative to, and Pi per stress: how the model reads the targets)."""

    cutoff: float = 0.5  # edge if surface gap < cutoff * a (small radius)
    edge_features: tuple = PAPER_EDGE_FEATURES
    # graph-level inputs: log_stress, phi (known conditions of the snapshot), solve_viscosity and
    # frictional_coordination (computed from its positions and the imposed stress; see
    # rheograph.graphs.features.GRAPH_INPUTS)
    graph_inputs: tuple = ()
    min_strain: float = 1.0  # snapshots before this strain (start-up transient) are skipped
    # > 1: only every k-th of a trajectory's training snapshots (after min_strain): consecutive snapshots
    # of a large box are strongly correlated, and each costs a relaxation when relax_strain is set
    snapshot_every: int = 1
    # each target's transform (asinh scale, also of the graph inputs that are transformed like it), the
    # graph input it is learned relative to, and Pi per imposed stress (rheograph.graphs.targets)
    targets: TargetSpec = field(default_factory=TargetSpec)
    # training on imprecise positions: (eps_min, eps_max) [a], each training graph rebuilt every epoch
    # from its positions plus fresh Gaussian noise of eps per coordinate, eps log-uniform in the range
    # (validation and test graphs: one fixed draw each); empty: exact positions (NoisyGraphs)
    noise_range: tuple = ()
    # > 0: instead of new noise every epoch, this many noisy copies of every snapshot (eps log-uniform in
    # noise_range, seeded) built once into the cache — for inputs too costly to recompute each epoch
    # (the one-solve, relax_strain)
    noise_copies: int = 0
    # 3D, confocal-grade positions: (eps_min, eps_max) [a] of the noise along the optical axis, drawn
    # log-uniform independently of the in-plane eps of noise_range (which it needs); empty: isotropic
    axial_noise_range: tuple = ()
    # the microscope's optical axis in the flow frame (x flow, y gradient, z vorticity): y where a shear
    # cell is imaged through its plate, as in rheo-confocal microscopy
    optical_axis: str = "y"
    # > 0: every snapshot's positions are first sheared by this strain under the simulator's dynamics at
    # its imposed stress (rheograph.graphs.features.relax_positions: repairs the overlaps that imprecise
    # positions make), in training and in prediction alike
    relax_strain: float = 0.0
    # false: a positions-only model, for snapshots whose imposed stress is unknown: no input may use it,
    # and Pi is learned per stress (Pi / sigma = 1 / mu_eff, what positions determine when k_n is
    # proportional to sigma; Pi in sigma0 is not identifiable from positions)
    stress_known: bool = True

    def __post_init__(self):
        object.__setattr__(self, "targets", TargetSpec.from_config(self.targets))
        if not 0.0 < self.cutoff <= 5.0:
            raise InputError(f"graph.cutoff={self.cutoff} is invalid: allowed 0 < cutoff <= 5 (units of a)")
        unknown = set(self.edge_features) - set(EDGE_FEATURES) - set(EDGE_FEATURES_3D_ONLY)
        if unknown or not self.edge_features:
            raise InputError(
                f"graph.edge_features={list(self.edge_features)}: allowed a non-empty subset "
                f"of {list(EDGE_FEATURES)} (3D snapshots also {list(EDGE_FEATURES_3D_ONLY)})"
            )
        unknown = set(self.graph_inputs) - set(GRAPH_INPUTS)
        if unknown:
            raise InputError(
                f"graph.graph_inputs={list(self.graph_inputs)}: allowed a subset of {list(GRAPH_INPUTS)}"
            )
        computed = [
            name for name in self.graph_inputs if name in COMPUTED_GRAPH_INPUTS + RELAXED_GRAPH_INPUTS
        ]
        if computed and "log_stress" not in self.graph_inputs:
            raise InputError(
                f"graph.graph_inputs: {computed} are computed at the imposed stress, which the model "
                f"must then be given too: add log_stress (now {list(self.graph_inputs)})"
            )
        self.targets.columns(self.graph_inputs)  # every reference among the inputs
        relaxed_inputs = [name for name in self.graph_inputs if name in RELAXED_GRAPH_INPUTS]
        if relaxed_inputs and not self.relax_strain:
            raise InputError(
                f"graph.graph_inputs: {relaxed_inputs} are measured while relaxing the snapshot: set "
                "graph.relax_strain > 0 (e.g. 0.01) or drop them"
            )
        if self.noise_range:
            low, high = (tuple(self.noise_range) + (None, None))[:2]
            if len(self.noise_range) != 2 or not (0.0 < low <= high <= 1.0):
                raise InputError(
                    f"graph.noise_range={list(self.noise_range)} is invalid: allowed [eps_min, eps_max] "
                    "with 0 < eps_min <= eps_max <= 1 (units of a)"
                )
            if ("solve_viscosity" in self.graph_inputs or self.relax_strain) and not self.noise_copies:
                raise InputError(
                    "graph.noise_range rebuilds every training graph from re-noised positions each epoch; "
                    "the one-solve input and relax_strain would cost a resistance solve or a stretch of "
                    "simulation per graph and epoch: set graph.noise_copies (noisy copies built once) or "
                    "drop solve_viscosity from graph.graph_inputs"
                )
            if set(self.edge_features) & set(HISTORY_EDGE_FEATURES):
                raise InputError(
                    "graph.noise_range: re-noised positions have no contact history; drop "
                    f"{sorted(set(self.edge_features) & set(HISTORY_EDGE_FEATURES))} from graph.edge_features"
                )
        if self.axial_noise_range:
            low, high = (tuple(self.axial_noise_range) + (None, None))[:2]
            if len(self.axial_noise_range) != 2 or not (0.0 < low <= high <= 1.0) or not self.noise_range:
                raise InputError(
                    f"graph.axial_noise_range={list(self.axial_noise_range)} is invalid: allowed "
                    "[eps_min, eps_max] with 0 < eps_min <= eps_max <= 1 (units of a), beside the in-plane "
                    "graph.noise_range"
                )
        if "axial_noise" in self.graph_inputs and not self.axial_noise_range:
            raise InputError(
                "graph.graph_inputs: axial_noise (the precision along the optical axis) needs "
                "graph.axial_noise_range, the axial noise the model is trained on"
            )
        if self.optical_axis not in AXES:
            raise InputError(
                f"graph.optical_axis={self.optical_axis!r} is invalid: allowed one of {list(AXES)}"
            )
        if isinstance(self.snapshot_every, bool) or not (
            isinstance(self.snapshot_every, int) and self.snapshot_every >= 1
        ):
            raise InputError(
                f"graph.snapshot_every={self.snapshot_every!r} is invalid: allowed an integer >= 1"
            )
        if self.noise_copies < 0 or (self.noise_copies and not self.noise_range):
            raise InputError(
                f"graph.noise_copies={self.noise_copies} is invalid: allowed 0, or >= 1 with "
                "graph.noise_range set"
            )
        if not (math.isfinite(self.relax_strain) and 0.0 <= self.relax_strain <= 0.2):
            raise InputError(
                f"graph.relax_strain={self.relax_strain} is invalid: allowed 0 <= relax_strain <= 0.2"
            )
        if set(self.graph_inputs) & set(SHELL_INPUTS) and self.cutoff < max(SHELL_WIDTHS):
            raise InputError(
                f"graph.cutoff={self.cutoff} is below the widest gap shell of the shell inputs "
                f"({max(SHELL_WIDTHS)} a): raise it or drop the shell_* graph inputs"
            )
        if not self.stress_known:
            uses = [
                x
                for x in self.graph_inputs
                if x in ("log_stress", "solve_viscosity", "frictional_coordination")
            ]
            uses += [x for x in self.edge_features if x in STRESS_EDGE_FEATURES]
            if uses or self.relax_strain:
                raise InputError(
                    "graph.stress_known=false (a positions-only model): "
                    f"{uses + (['relax_strain'] if self.relax_strain else [])} need the imposed stress; "
                    "drop them"
                )
        self.targets.check_inputs(self.graph_inputs, self.stress_known)

    def transform_targets(self, eta, pressure, z_mu) -> np.ndarray:
        return np.stack(
            [
                forward_transform(eta, self.targets.viscosity_scale),
                forward_transform(pressure, self.targets.pressure_scale),
                np.asarray(z_mu, dtype=np.float64),
            ],
            axis=-1,
        )


def snapshot_graphs(
    source,
    settings: GraphSettings,
    run_id: int,
    solve_numerics: dict | None = None,
    training: bool = True,
    workers: int = 1,
    solve_device: torch.device | None = None,
) -> list[Data]:
    """Graphs of the snapshots of one source (a path of any kind ``rheograph.io.snapshots`` reads, or a
    ``Snapshots``).

    ``training``: only snapshots with strain >= ``settings.min_strain`` (or arrested) and finite targets,
    as a training set needs; otherwise every snapshot, targets NaN where unknown (prediction).
    ``solve_numerics``: the step settings of the one-solve input (``disp_max``, ``dt_max``,
    ``lagged_step_control``) — a model's own, from its bundle; None takes the source's (how the training
    graphs of its simulation are built). ``workers`` > 1: the snapshots (their one solve, relaxation and
    edges) are split between that many processes; the graphs are the same.  ``solve_device``: the
    resistance problems of those solves and relaxations solved together on that torch device, in dense
    batches (``rheograph.graphs.batched_solve``; None: the sparse solver, one snapshot after the other);
    the graphs differ by round-off."""
    snaps = source if isinstance(source, Snapshots) else read_snapshots(source)
    path = snaps.source
    if snaps.radii_nominal:
        raise InputError(
            f"{path}: its radii are declared nominal (radii_nominal): graphs read each particle's own "
            "radius; estimate them from the configurations (predict.py --radii estimated-mean, "
            "model.predict_with_estimated_radii; docs/imaging.md)"
        )
    three_d = snaps.dim == 3
    only_3d = [name for name in settings.edge_features if name in EDGE_FEATURES_3D_ONLY]
    if only_3d and not three_d:
        raise InputError(
            f"{path}: a 2D snapshot, and graph.edge_features has the 3D-only feature(s) {only_3d}"
        )
    params = snaps.graph_params()
    needed = [
        k
        for k in ("delta", "kn_coefficient", "kt_ratio", "mu", "lub_max_gap", "size_ratio")
        if k not in params
    ]
    if needed:
        raise InputError(
            f"{path}: its physical parameter(s) {needed} are not given; graph features depend on them "
            "(name them as the sim.* keys in the file, or pass LF_DEM's parameter file)"
        )
    numerics = solve_numerics if solve_numerics is not None else snaps.numerics
    # the physics-only row needs the solve too, but a source without a step only loses that row
    if "solve_viscosity" in settings.graph_inputs and "disp_max" not in numerics:
        raise InputError(
            f"{path}: the one-solve input (solve_viscosity) needs the step disp_max, which this source does "
            "not record: add disp_max to the file"
        )
    if settings.stress_known and not np.isfinite(snaps.stress):
        raise InputError(
            f"{path}: the imposed stress (key stress, sigma/sigma0) is not given; this model reads it "
            "(a positions-only model, graph.stress_known=false, does not)"
        )
    if (settings.axial_noise_range or "axial_noise" in settings.graph_inputs) and not three_d:
        raise InputError(
            f"{path}: a 2D snapshot has no optical axis; this model (graph.axial_noise_range, input "
            "axial_noise) reads 3D confocal snapshots"
        )
    if "position_noise" in settings.graph_inputs and snaps.position_noise is None:
        raise InputError(
            f"{path}: the model reads the positions' precision (position_noise, RMS per coordinate in "
            "units of a), which this source does not state: add the key position_noise to the file, "
            "pass predict.py --position-noise EPS, or position_noise= to model.predict"
        )
    finite = np.isfinite(snaps.targets).all(axis=1)
    if training:
        strain = np.nan_to_num(snaps.strain, nan=-np.inf)
        # an arrested packing is a state of its own, not a start-up transient: kept at any strain
        keep = np.flatnonzero(((strain >= settings.min_strain) | snaps.jammed) & finite)
        keep = keep[:: settings.snapshot_every]
    else:
        keep = np.arange(len(snaps))
    check_memory(
        graph_bytes(
            snaps.n_particles, keep.size, snaps.phi, settings.cutoff, params["size_ratio"], snaps.dim
        ),
        f"{path}: the graphs of {keep.size} snapshot(s) of {snaps.n_particles} particles",
        "give fewer snapshots or particles per file (or a shorter graph.cutoff)",
    )
    contacts = [None] * keep.size
    if set(settings.edge_features) & set(HISTORY_EDGE_FEATURES):
        if snaps.contacts is None:
            raise InputError(
                f"{path}: graph.edge_features has history features {list(HISTORY_EDGE_FEATURES)}, "
                "which need the contact states a rheograph trajectory records per snapshot; this "
                "source has none: use features computed from positions"
            )
        contacts = [snaps.contacts[k] for k in keep]
    lx, ly, radii = snaps.lx, snaps.ly, snaps.radii
    # the box's edges: (lx, ly) in 2D, (lx, ly, lz) in 3D
    edges = (lx, ly, snaps.lz) if three_d else (lx, ly)
    check_edge_reach(lx, ly, radii, settings.cutoff, path, lz=snaps.lz)
    solve_params = {**params, **{k: v for k, v in numerics.items() if k in SOLVE_NUMERICS}}
    # a noisy copy (noisy_copy) states one eps per snapshot, a source one for all
    noise = np.broadcast_to(np.nan_to_num(np.asarray(snaps.position_noise, dtype=np.float64)), (len(snaps),))
    stated_axial = snaps.position_noise if snaps.axial_noise is None else snaps.axial_noise
    axial = np.broadcast_to(np.nan_to_num(np.asarray(stated_axial, dtype=np.float64)), (len(snaps),))
    coarsest = np.maximum(noise, axial)  # how close imprecise positions may bring two centres
    for idx in keep:
        where = f"{path}, snapshot {idx}"
        if three_d:
            check_separations3d(
                where, snaps.positions[idx], radii, (*edges, snaps.le_offset[idx]), coarsest[idx]
            )
        else:
            check_separations(where, snaps.positions[idx], radii, lx, ly, snaps.le_offset[idx], coarsest[idx])
    if settings.relax_strain and "disp_max" not in solve_params:
        raise InputError(
            f"{path}: graph.relax_strain shears the snapshots under the simulator's dynamics, which "
            "needs the step disp_max: add disp_max to the file"
        )
    jobs = [
        {
            "positions": snaps.positions[idx],
            "le_offset": float(snaps.le_offset[idx]),
            "position_noise": float(noise[idx]),
            "axial_noise": float(axial[idx]),
            "contacts": contacts[k],
            "targets": snaps.targets[idx],
            "jammed": bool(snaps.jammed[idx]),
            "strain": float(snaps.strain[idx]),
        }
        for k, idx in enumerate(keep)
    ]
    shared = (radii, edges, solve_params, settings, snaps.phi, run_id, solve_device)
    workers = min(int(workers), len(jobs))
    if workers <= 1:
        return _graphs_of_snapshots(shared, jobs)
    # contiguous chunks, one per worker, returned in order: the same graphs as in this process
    bounds = np.linspace(0, len(jobs), workers + 1).round().astype(int)
    chunks = [jobs[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
    pool = _graph_pool(workers)
    parts = pool.map(_graph_arrays_of_snapshots, [shared] * workers, chunks)
    return [
        Data(**{key: torch.from_numpy(value) for key, value in g.items()}) for part in parts for g in part
    ]


_graph_pools: dict = {}


def _graph_pool(workers: int):
    """A process pool of ``workers`` (spawned, one thread each) kept for later calls: its start-up
    (imports, compiled kernels loaded) is paid once per process, not per source."""
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    if workers not in _graph_pools:
        _graph_pools[workers] = ProcessPoolExecutor(
            max_workers=workers, mp_context=get_context("spawn"), initializer=_one_thread
        )
    return _graph_pools[workers]


def _one_thread() -> None:
    torch.set_num_threads(1)


def _graph_arrays_of_snapshots(shared: tuple, jobs: list[dict]) -> list[dict]:
    """``_graphs_of_snapshots`` in a pool process: each graph's fields as numpy arrays (in their order),
    sent back by value — torch would send each tensor as a shared-memory file descriptor, thousands of
    them for a thousand graphs."""
    return [{key: value.numpy() for key, value in g.items()} for g in _graphs_of_snapshots(shared, jobs)]


def _graphs_of_snapshots(shared: tuple, jobs: list[dict]) -> list[Data]:
    """The graphs of ``jobs`` (one snapshot's positions, offset, noise, contacts, targets, ... each) of
    one source whose ``shared`` values are (radii, the box's edges (lx, ly) or (lx, ly, lz), solve
    parameters, settings, phi, run_id, solve device): relaxed first where ``settings.relax_strain``, then
    its one solve, edges and inputs."""
    radii, edges, solve_params, settings, phi, run_id, solve_device = shared
    if solve_device is not None:
        solved = []
        for start in range(0, len(jobs), SOLVED_TOGETHER):
            chunk = jobs[start : start + SOLVED_TOGETHER]
            solved += _solved_together(chunk, radii, edges, solve_params, settings, solve_device)
    else:
        solved = [_solved_alone(job, radii, edges, solve_params, settings) for job in jobs]
    graphs = []
    for job, (positions, offset, relaxed, relaxation, eta) in zip(jobs, solved):
        graphs.append(
            snapshot_graph(
                positions,
                radii,
                (*edges, offset),
                solve_params,
                settings,
                {"phi": phi, "position_noise": job["position_noise"], "axial_noise": job["axial_noise"]},
                contacts=job["contacts"],
                targets=job["targets"],
                jammed=job["jammed"],
                strain=job["strain"],
                run_id=run_id,
                relaxed_strain=float(relaxed),
                relaxation=relaxation,
                eta=eta,
            )
        )
    return graphs


def _solved_alone(job: dict, radii, edges, solve_params, settings) -> tuple:
    """(positions, le_offset, relaxed strain, relaxation, None) of one snapshot: relaxed where
    ``settings.relax_strain`` (the strain it was relaxed by; NaN: not relaxed; short of relax_strain for a
    packing that arrested within the step budget, which predictions flag); its one solve is left to
    ``snapshot_graph``."""
    positions, offset = job["positions"], job["le_offset"]
    if not settings.relax_strain:
        return positions, offset, np.nan, None, None
    if len(edges) == 3:
        relaxation = relax_positions3d(
            positions.copy(), radii, (*edges, offset), solve_params, settings.relax_strain
        )
    else:
        relaxation = relax_positions(
            positions.copy(), radii, *edges, offset, solve_params, settings.relax_strain
        )
    return relaxation.positions, relaxation.le_offset, relaxation.strain, relaxation, None


def _solved_together(jobs: list[dict], radii, edges, solve_params, settings, device) -> list[tuple]:
    """What ``_solved_alone`` gives for each of ``jobs``, with the one solve's eta_r: the simulations of
    all snapshots stepped together, their problems solved on ``device`` in dense batches."""
    solve_batch = DenseBatchSolver(device)

    def simulation(positions, offset):
        # the sparse solver analyses a pattern only where a problem falls back to it
        solver = DeferredAnalysis(make_solver("auto"))
        if len(edges) == 3:
            return snapshot_simulation3d(positions, radii, (*edges, offset), solve_params, solver)
        return snapshot_simulation(positions, radii, (*edges, offset), solve_params, solver)

    states = [(job["positions"], job["le_offset"], np.nan, None) for job in jobs]
    if settings.relax_strain:
        pressure = step_pressure3d if len(edges) == 3 else particle_pressure
        sims = [simulation(positions, offset)[1] for positions, offset, *_ in states]
        relaxations = relax_simulations(sims, settings.relax_strain, None, pressure, solve_batch)
        states = [(r.positions, r.le_offset, r.strain, r) for r in relaxations]
    etas = [None] * len(jobs)
    if "disp_max" in solve_params and np.isfinite(float(solve_params["stress"])):
        made = [simulation(positions, offset) for positions, offset, *_ in states]
        results = solve_configurations([sim for _, sim in made], solve_batch=solve_batch)
        etas = [one_solve_viscosity(sim_params, result) for (sim_params, _), result in zip(made, results)]
    return [(*state, eta) for state, eta in zip(states, etas)]


def snapshot_graph(
    positions,
    radii,
    box,
    params: dict,
    settings: GraphSettings,
    conditions: dict,
    contacts=None,
    targets=(np.nan, np.nan, np.nan),
    jammed: bool = False,
    strain: float = np.nan,
    run_id: int = 0,
    relaxed_strain: float = np.nan,
    relaxation=None,
    eta: float | None = None,
) -> Data:
    """The graph of one snapshot: positions (N, 2) [a], radii (N,) [a], box = (lx, ly, le_offset) [a]
    (a 3D snapshot: positions (N, 3), box = (lx, ly, lz, le_offset), ``rheograph.graphs.features3d``);
    ``params`` the run's parameter mapping (imposed ``stress`` included; with ``disp_max`` the one-solve
    is computed, else its input and physics row are NaN), ``conditions`` the snapshot's known ``phi``
    and ``position_noise`` [a], ``targets`` (eta_r, Pi [sigma0], Z_mu) (NaN where unknown),
    ``relaxation`` the ``rheograph.graphs.features.Relaxation`` that produced ``positions`` (its
    observables are the RELAXED_GRAPH_INPUTS), ``eta`` its one solve's eta_r where already computed
    (``rheograph.graphs.batched_solve``)."""
    stress = float(params["stress"])
    # one resistance solve per snapshot: an input where the graph has it, and the physics-only row
    solvable = "disp_max" in params and np.isfinite(stress)
    if len(box) == 4:  # 3D: the box's volume takes the place of the area
        size = box[0] * box[1] * box[2]
        if eta is None:
            eta = solve_viscosity3d(positions, radii, box, params) if solvable else np.nan
        edge_index, feats, pairs = snapshot_edges3d(positions, radii, box, settings.cutoff, params, contacts)
    else:
        lx, ly, le_offset = box
        size = lx * ly
        if eta is None:
            eta = solve_viscosity(positions, radii, lx, ly, le_offset, params) if solvable else np.nan
        edge_index, feats, pairs = snapshot_edges(
            positions, radii, lx, ly, le_offset, settings.cutoff, params, contacts
        )
    known = {"log_stress": np.log(stress), **conditions}
    known["solve_viscosity"] = float(forward_transform(eta, settings.targets.viscosity_scale))
    known["frictional_coordination"] = 2.0 * feats["frictional"][: pairs["i"].size].sum() / radii.size
    descriptors = snapshot_descriptors(pairs, radii.size, size)
    # the physics-only estimates (rheograph.learn.baselines.physics_rows): the one-solve eta_r, the
    # contact-spring pressure (2 pi sigma / A) sum r a_bar overlap [sigma0] (overlap in delta_sigma),
    # and the counted frictional contacts
    physics = [eta, 2.0 * np.pi * stress * descriptors[3], known["frictional_coordination"]]
    known["spring_pressure"] = float(
        forward_transform(2.0 * np.pi * descriptors[3], settings.targets.pressure_scale)
    )
    if set(settings.graph_inputs) & set(SHELL_INPUTS):
        known.update(shell_inputs(pairs, radii.size))
    if relaxation is not None:
        known["relaxed_viscosity"] = float(
            forward_transform(relaxation.viscosity, settings.targets.viscosity_scale)
        )
        known["relaxed_viscosity_early"] = float(
            forward_transform(relaxation.viscosity_early, settings.targets.viscosity_scale)
        )
        known["relaxed_pressure"] = float(
            forward_transform(relaxation.pressure / stress, settings.targets.pressure_scale)
        )
        known["relaxed_coordination"] = relaxation.z_mu
    elif set(settings.graph_inputs) & set(RELAXED_GRAPH_INPUTS):
        raise InputError(
            f"graph inputs {sorted(set(settings.graph_inputs) & set(RELAXED_GRAPH_INPUTS))} are "
            "measured while relaxing a snapshot, and this one was not relaxed (graph.relax_strain)"
        )
    u = torch.tensor([[known[name] for name in settings.graph_inputs]], dtype=torch.float32)
    edge_attr = np.stack([feats[name] for name in settings.edge_features], axis=1)
    raw = np.asarray(targets, dtype=np.float64)
    y = settings.transform_targets(*raw)
    return Data(
        x=torch.from_numpy(node_features(radii, params["size_ratio"])),
        pos=torch.from_numpy(np.asarray(positions, dtype=np.float64)),
        radius=torch.from_numpy(np.asarray(radii, dtype=np.float64)),
        box=torch.tensor([list(box)], dtype=torch.float64),
        edge_index=torch.from_numpy(edge_index).long(),
        edge_attr=torch.from_numpy(edge_attr).float(),
        y=torch.from_numpy(y).float().view(1, 3),
        y_raw=torch.from_numpy(raw).double().view(1, 3),
        u=u,
        area=torch.tensor([size], dtype=torch.float32),
        descriptors=torch.from_numpy(descriptors).view(1, -1),
        physics=torch.tensor([physics], dtype=torch.float64),
        n_particles=torch.tensor([radii.size]),
        jammed=torch.tensor([jammed]),
        phi=torch.tensor([conditions["phi"]], dtype=torch.float64),
        stress=torch.tensor([stress], dtype=torch.float64),
        strain=torch.tensor([strain], dtype=torch.float64),
        relaxed_strain=torch.tensor([relaxed_strain], dtype=torch.float64),
        run_id=torch.tensor([run_id]),
    )


def noise_scales(eps: float, eps_axial: float | None, dim: int, optical_axis: str) -> float | np.ndarray:
    """The RMS noise per coordinate [a]: ``eps`` on every axis, or in 3D ``eps_axial`` along
    ``optical_axis`` (one of ``AXES``) and ``eps`` across it, a (3,) vector."""
    if eps_axial is None:
        return eps
    scales = np.full(dim, eps)
    scales[AXES.index(optical_axis)] = eps_axial
    return scales


def noisy_copy(snaps: Snapshots, noise_range, seed, axial_noise_range=(), optical_axis="y") -> Snapshots:
    """``snaps`` with Gaussian noise on every snapshot's positions, eps log-uniform in ``noise_range``
    drawn per snapshot (``position_noise`` then holds the (S,) draws); with ``axial_noise_range`` (3D),
    the noise along ``optical_axis`` is drawn apart, log-uniform in that range (``axial_noise``, (S,));
    ``seed`` seeds the draws."""
    if axial_noise_range and snaps.lz is None:
        raise InputError(f"{snaps.source}: axial noise (graph.axial_noise_range) needs a 3D snapshot")
    rng = np.random.default_rng(seed)
    eps = np.exp(rng.uniform(*np.log(np.asarray(noise_range, dtype=np.float64)), len(snaps)))
    axial = [None] * len(snaps)
    if axial_noise_range:
        axial = np.exp(rng.uniform(*np.log(np.asarray(axial_noise_range, dtype=np.float64)), len(snaps)))
    box = (snaps.lx, snaps.ly) if snaps.lz is None else (snaps.lx, snaps.ly, snaps.lz)
    wrap = wrap_into_box if snaps.lz is None else wrap_into_box3d
    positions = np.stack(
        [
            wrap(p + rng.normal(0.0, noise_scales(e, ea, snaps.dim, optical_axis), p.shape), *box, o)
            for p, e, ea, o in zip(snaps.positions, eps, axial, snaps.le_offset)
        ]
    )
    return dataclasses.replace(
        snaps,
        positions=positions,
        contacts=None,
        position_noise=eps,
        axial_noise=axial if axial_noise_range else None,
    )


class NoisyGraphs(torch.utils.data.Dataset):
    """Graphs rebuilt from their positions plus Gaussian noise of eps per coordinate, eps drawn
    log-uniformly in ``settings.noise_range`` (an imaging-grade snapshot: the tracking error of a
    microscope is ~0.01-0.03 a).  ``graphs``: exact graphs of ``snapshot_graphs`` (with ``pos``, ``box``);
    ``run_params``: {run_id: the run's parameter mapping}.  ``fresh``: a new draw at every access (the
    training set: new noise each epoch); otherwise one fixed draw per graph, seeded by ``seed`` and its
    position (validation, test).  The graph's ``position_noise`` input is the drawn eps combined with
    the source's own precision."""

    def __init__(self, graphs, settings: GraphSettings, run_params: dict, fresh: bool, seed: int = 0):
        self.graphs, self.settings, self.run_params = graphs, settings, run_params
        self.fresh, self.seed = fresh, seed
        self.log_range = np.log(np.asarray(settings.noise_range, dtype=np.float64))
        self.log_axial_range = (
            np.log(np.asarray(settings.axial_noise_range, dtype=np.float64))
            if settings.axial_noise_range
            else None
        )

    def __len__(self) -> int:
        return len(self.graphs)

    def __getitem__(self, k: int) -> Data:
        g = self.graphs[k]
        if self.fresh:  # torch's generator: seeded by Lightning's seed_everything, per worker
            rng = np.random.default_rng(int(torch.randint(0, 2**62, (1,))))
        else:
            rng = np.random.default_rng([self.seed, k])
        eps = float(np.exp(rng.uniform(*self.log_range)))
        eps_axial = (
            None if self.log_axial_range is None else float(np.exp(rng.uniform(*self.log_axial_range)))
        )
        return self.noisy(g, eps, rng, eps_axial)

    def noisy(self, g: Data, eps: float, rng: np.random.Generator, eps_axial: float | None = None) -> Data:
        """``g`` rebuilt from its positions plus noise of ``eps`` [a] per coordinate (3D, with
        ``eps_axial``: that along the optical axis instead)."""
        params = self.run_params[int(g.run_id)]
        radii = g.radius.numpy()  # each particle's own: a polydisperse sample's are not the species' sizes
        pos = g.pos.numpy().astype(np.float64)
        box = tuple(float(v) for v in g.box[0])  # (lx, ly, le_offset), 3D (lx, ly, lz, le_offset)
        noisy = pos + rng.normal(
            0.0, noise_scales(eps, eps_axial, pos.shape[1], self.settings.optical_axis), pos.shape
        )
        wrapped = wrap_into_box3d(noisy, *box) if len(box) == 4 else wrap_into_box(noisy, *box)
        inputs = self.settings.graph_inputs
        source_noise = float(g.u[0, inputs.index("position_noise")]) if "position_noise" in inputs else 0.0
        source_axial = float(g.u[0, inputs.index("axial_noise")]) if "axial_noise" in inputs else source_noise
        axial = eps if eps_axial is None else eps_axial
        return snapshot_graph(
            wrapped,
            radii,
            box,
            {**params, "stress": float(g.stress)},
            self.settings,
            {
                "phi": float(g.phi),
                "position_noise": float(np.hypot(eps, source_noise)),
                "axial_noise": float(np.hypot(axial, source_axial)),
            },
            targets=g.y_raw[0].numpy(),
            jammed=bool(g.jammed),
            strain=float(g.strain),
            run_id=int(g.run_id),
        )


def check_edge_reach(
    lx: float, ly: float, radii: np.ndarray, cutoff: float, where, lz: float | None = None
) -> None:
    """Edges join pairs within ``cutoff`` (surface gap, units of a): the longest, two of the largest
    particles, must be shorter than half the box (lx x ly [a], x lz in 3D), or minimum images stop being
    unique and edges are lost silently.  Refused by name for the file ``where``."""
    reach = 2.0 * float(np.max(radii)) + cutoff
    sides = (lx, ly) if lz is None else (lx, ly, lz)
    if min(sides) <= 2.0 * reach:
        box = " x ".join(f"{side:.3g}" for side in sides)
        raise InputError(
            f"graph.cutoff={cutoff} is too large for {where}: its box ({box} a) must "
            f"exceed twice the longest edge ({reach:.3g} a)"
        )


def _files_fingerprint(files) -> list:
    return [(str(Path(f).resolve()), os.path.getsize(f), int(os.path.getmtime(f))) for f in files]


GRAPH_CACHE_FORMAT = "rheograph-graphs-1"


def _save_atomically(contents: dict, path) -> None:
    """``contents`` (tensors and plain values) to ``path`` through a temporary file: a killed write leaves
    no part-written file under the final name."""
    tmp = Path(path).with_suffix(".tmp")
    torch.save(contents, tmp)
    tmp.replace(path)


def _read_part(path: Path) -> list:
    """The graphs of one trajectory file saved by an unfinished build (a list of ``Data``)."""
    stored = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(stored, dict) or stored.get("format") != GRAPH_CACHE_FORMAT:
        raise ValueError(f"not a graph cache part of format {GRAPH_CACHE_FORMAT}")
    return [Data.from_dict(graph) for graph in stored["graphs"]]


def _load_failure(exc: Exception) -> str:
    """The first line of why a cache file could not be read (torch's weights-only refusal runs to many
    lines of advice on loading the file unsafely, which does not apply here)."""
    text = str(exc).strip()
    if text.startswith("Weights only load failed"):
        return "it holds objects other than tensors and plain values"
    return (text.splitlines() or [type(exc).__name__])[0][:160]


class SnapshotGraphDataset(InMemoryDataset):
    """All snapshot graphs of a list of trajectory files.

    Cached in ``cache_dir/<hash>/processed``; the hash covers every graph setting and the files' paths,
    sizes and modification times, so changing either rebuilds the cache and nothing stale is reused.
    ``files.json`` beside it lists the files in run_id order, for a person looking into the cache.
    ``physics``: (physics_solver, device) of a build (``rheograph.graphs.batched_solve``); the graphs of
    either solver differ by round-off, so the key leaves it out.
    """

    def __init__(
        self,
        files,
        settings: GraphSettings,
        cache_dir: str | Path,
        lfdem_params=None,
        physics: tuple[str, torch.device] = ("sparse", torch.device("cpu")),
    ):
        self.files = sorted(str(f) for f in files)
        self.solve_with = physics
        self.lfdem_params = None if lfdem_params is None else str(lfdem_params)
        if not self.files:
            raise InputError("no trajectory files given to the graph dataset")
        self.settings = settings
        key = json.dumps(
            {
                # how the model reads the targets, not the graphs: left out of the cache key
                # (the targets in the form of earlier versions, in which the key stays what it was: the
                # scales transform the targets and some inputs, the rest only how the model reads them)
                "settings": {
                    k: v
                    for k, v in {**asdict(settings), **settings.targets.legacy_options()}.items()
                    if k
                    not in (
                        "targets",
                        "pressure_per_stress",
                        "z_mu_on_count",
                        "viscosity_on_solve",
                        "viscosity_on_relaxed",
                        "pressure_on_spring",
                        # the cache holds the exact graphs; the noise is drawn when they are read
                        *(() if settings.noise_copies else ("noise_range",)),
                        # isotropic noise: the keys of caches made before the axial noise stay valid
                        *(
                            ()
                            if settings.noise_copies and settings.axial_noise_range
                            else ("axial_noise_range", "optical_axis")
                        ),
                    )
                },
                "files": _files_fingerprint(self.files),
                **({"lfdem_params": _files_fingerprint([self.lfdem_params])} if self.lfdem_params else {}),
                "schema": SCHEMA_VERSION,
                # 3: jammed per snapshot (after the flow stopped), kept at any strain; 4: from the first row
                # of the jam detector's window on (one row earlier than 3); 5: positions and box in each
                # graph, any snapshot source; 6: positions in float64, shell and noise inputs; 7: the
                # strain each snapshot was relaxed by; 8: tensors and plain values only (read without
                # unpickling objects), no PyG class stored; 9: each particle's radius (noisy rebuilds of
                # polydisperse snapshots read them)
                "version": 9,
            },
            sort_keys=True,
            default=list,
        )
        self.digest = hashlib.sha1(key.encode()).hexdigest()[:16]
        super().__init__(root=str(Path(cache_dir) / self.digest))
        try:
            self.load(self.processed_paths[0])
        except Exception as exc:  # truncated, corrupt (a killed build) or holding objects: rebuild it
            log.warning(
                "graph cache %s unreadable (%s): rebuilding", self.processed_paths[0], _load_failure(exc)
            )
            Path(self.processed_paths[0]).unlink(missing_ok=True)
            self.process()
            self.load(self.processed_paths[0])

    # The cache is read with torch.load(weights_only=True), never by PyG's readers: PyG's
    # InMemoryDataset.load falls back to unpickling objects when a weights-only load fails, and its
    # Dataset._process unpickles pre_transform.pt and pre_filter.pt.  A cache directory may be copied from
    # elsewhere: nothing in it may run code.
    def _process(self):
        if not Path(self.processed_paths[0]).exists():
            Path(self.processed_dir).mkdir(parents=True, exist_ok=True)
            self.process()

    def save(self, graphs, path) -> None:  # type: ignore[override]
        """All ``graphs`` collated into tensors, as a dict of tensors and plain values."""
        data, slices = self.collate(graphs)
        _save_atomically({"format": GRAPH_CACHE_FORMAT, "data": data.to_dict(), "slices": slices}, path)

    def load(self, path) -> None:  # type: ignore[override]
        stored = torch.load(path, map_location="cpu", weights_only=True)
        if not isinstance(stored, dict) or stored.get("format") != GRAPH_CACHE_FORMAT:
            raise ValueError(f"not a graph cache of format {GRAPH_CACHE_FORMAT}")
        self.data = Data.from_dict(stored["data"])
        self.slices = stored["slices"]

    @property
    def raw_file_names(self):
        return []

    @property
    def processed_file_names(self):
        return ["graphs.pt"]

    def download(self):
        pass

    def process(self):
        # one part per trajectory file, kept until the whole set is saved: a build that relaxes or
        # solves every snapshot runs for hours, and a killed one resumes from the files it finished
        parts = Path(self.root, "parts")
        parts.mkdir(parents=True, exist_ok=True)
        graphs = []
        for run_id, path in enumerate(self.files):
            part = parts / f"{run_id}.pt"
            try:
                built = _read_part(part) if part.exists() else None
            except Exception as exc:  # a part killed mid-write, or one holding objects: build it again
                log.warning("graph cache part %s unreadable (%s): rebuilding it", part, _load_failure(exc))
                built = None
            if built is None:
                built = self._file_graphs(run_id, path)
                _save_atomically(
                    {"format": GRAPH_CACHE_FORMAT, "graphs": [graph.to_dict() for graph in built]}, part
                )
            else:
                log.info("graphs of %s (%d/%d) from an earlier build", path, run_id + 1, len(self.files))
            graphs.extend(built)
        if not graphs:
            raise InputError(f"no snapshots with strain >= {self.settings.min_strain} in {self.files}")
        self.save(graphs, self.processed_paths[0])
        shutil.rmtree(parts)
        Path(self.root, "files.json").write_text(json.dumps(self.files, indent=1))

    def _file_graphs(self, run_id: int, path: str) -> list:
        """The graphs of one trajectory file (with its noisy copies when ``noise_copies`` is set)."""
        snaps = read_snapshots(path, self.lfdem_params)
        solve_device = physics_solver_device(*self.solve_with, snaps.n_particles)
        if not self.settings.noise_copies:
            return snapshot_graphs(snaps, self.settings, run_id, solve_device=solve_device)
        log.info("noisy copies of %s (%d/%d)", path, run_id + 1, len(self.files))
        graphs = []
        for copy_id in range(self.settings.noise_copies):
            noisy = noisy_copy(
                snaps,
                self.settings.noise_range,
                [run_id, copy_id],
                self.settings.axial_noise_range,
                self.settings.optical_axis,
            )
            graphs.extend(snapshot_graphs(noisy, self.settings, run_id, solve_device=solve_device))
        return graphs
