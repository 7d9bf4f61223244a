"""Baselines scored on the same folds as the graph network, so every report shows what it adds.

* ``stress_mean``: the training mean of each target at the snapshot's (phi, sigma) (knowing the imposed
  stress and nothing else; its R^2 is the share of the variance that lies between state points).
* ``descriptors``: gradient-boosted trees on the eight per-snapshot physics descriptors of
  ``rheograph.graphs.features.DESCRIPTORS`` plus log(sigma/sigma0) (and phi when it varies) — a model
  without message passing.
* ``descriptors_solve``: the same trees given the computed graph inputs too, when the network is given
  them (``graph.graph_inputs`` with solve_viscosity, frictional_coordination): what they bring without
  message passing.
* ``descriptors_ridge``: ridge regression on the descriptors alone (positions only, the seed paper's
  information).
* physics only, nothing learned but one number per state point (``physics_rows``): ``physics_solve``,
  the one-solve η_r, the contact-spring pressure and the counted frictional contacts (parameter-free);
  ``physics_offset``, the same with the one-solve η_r shifted by the mean log offset of the training
  snapshots at the same (φ, σ).

All fit the transformed targets (asinh eta_r, asinh Pi, Z_mu) and return physical (G, 3) predictions.
"""

from __future__ import annotations

import numpy as np

from rheograph.graphs.dataset import SnapshotGraphDataset
from rheograph.graphs.features import COMPUTED_GRAPH_INPUTS, inverse_transform
from rheograph.learn.bundle import bundle_graph_settings, read_bundle
from rheograph.learn.datamodule import split_files
from rheograph.learn.module import fold_metrics, physical_targets
from rheograph.naming import state_point_key


def stress_mean(train: dict, test: dict) -> np.ndarray:
    """Transformed prediction (G, 3): the training mean at the same (phi, sigma); a state point absent
    from training takes the mean of the nearest log(sigma) at the same phi (else the global mean)."""
    keys = state_point_key(train["phi"], train["stress"])
    out = np.empty((len(test["stress"]), train["y"].shape[1]))
    for g, (phi, sigma) in enumerate(zip(test["phi"], test["stress"])):
        same = keys == state_point_key(phi, sigma)
        if not same.any():
            at_phi = np.isclose(train["phi"], phi)
            if at_phi.any():
                dist = np.abs(np.log(train["stress"][at_phi]) - np.log(sigma))
                nearest = train["stress"][at_phi][np.argmin(dist)]
                same = at_phi & np.isclose(train["stress"], nearest)
            else:
                same = np.ones_like(keys, dtype=bool)
        out[g] = train["y"][same].mean(axis=0)
    return out


def _inputs(data: dict, with_conditions: bool, vary_phi: bool, with_solve: bool = False) -> np.ndarray:
    columns = [data["descriptors"]]
    if with_conditions:
        columns.append(np.log(data["stress"])[:, None])
        if vary_phi:
            columns.append(np.asarray(data["phi"])[:, None])
    if with_solve:
        columns.append(np.asarray(data["computed_inputs"]))
    return np.concatenate(columns, axis=1)


def descriptor_trees(train: dict, test: dict, seed: int = 0, with_solve: bool = False) -> np.ndarray:
    from sklearn.ensemble import HistGradientBoostingRegressor

    vary_phi = np.unique(np.round(train["phi"], 6)).size > 1
    x_train = _inputs(train, True, vary_phi, with_solve)
    x_test = _inputs(test, True, vary_phi, with_solve)
    out = np.empty((x_test.shape[0], train["y"].shape[1]))
    for k in range(train["y"].shape[1]):
        model = HistGradientBoostingRegressor(max_iter=300, learning_rate=0.05, random_state=seed)
        out[:, k] = model.fit(x_train, train["y"][:, k]).predict(x_test)
    return out


def descriptor_ridge(train: dict, test: dict, alpha: float = 1e-3) -> np.ndarray:
    x_train, x_test = _inputs(train, False, False), _inputs(test, False, False)
    mean, std = x_train.mean(axis=0), x_train.std(axis=0) + 1e-12
    a = np.c_[(x_train - mean) / std, np.ones(len(x_train))]
    b = np.c_[(x_test - mean) / std, np.ones(len(x_test))]
    reg = alpha * len(a) * np.eye(a.shape[1])
    reg[-1, -1] = 0.0  # the intercept is not penalised
    coef = np.linalg.solve(a.T @ a + reg, a.T @ train["y"])
    return b @ coef


def baseline_predictions(train: dict, test: dict, targets) -> dict:
    """Physical predictions (G_test, 3) of every baseline.  ``train``/``test``: dicts of arrays
    ``y`` (transformed targets, (G, 3)), ``descriptors`` (G, 8), ``stress`` (G,), ``phi`` (G,);
    ``targets``: their transforms (rheograph.graphs.targets.TargetSpec)."""
    raw = {
        "stress_mean": stress_mean(train, test),
        "descriptors": descriptor_trees(train, test),
        "descriptors_ridge": descriptor_ridge(train, test),
    }
    if "computed_inputs" in train:
        raw["descriptors_solve"] = descriptor_trees(train, test, with_solve=True)
    out = {name: physical_targets(pred, targets) for name, pred in raw.items()}
    if np.isfinite(test["physics"][:, 0]).all():  # every snapshot had its solve
        out.update(physics_rows(train, test, targets.viscosity_scale))
    return out


def physics_rows(train: dict, test: dict, viscosity_scale: float) -> dict:
    """Physical predictions (G_test, 3) of the physics-only rows (module docstring) from ``physics``
    (G, 3): one-solve η_r, contact-spring Π [σ0], counted Z_μ."""
    solve = test["physics"].copy()
    eta_true = inverse_transform(train["y"][:, 0], viscosity_scale)
    ok = (eta_true > 0) & (train["physics"][:, 0] > 0)
    log_offset = np.log(np.where(ok, eta_true, 1.0)) - np.log(np.where(ok, train["physics"][:, 0], 1.0))
    # the mean log offset at the same (phi, sigma): stress_mean on a table whose first column is it
    table = {**train, "y": np.where(ok, log_offset, np.nan)[:, None]}
    table = {k: (v[ok] if isinstance(v, np.ndarray) and len(v) == len(ok) else v) for k, v in table.items()}
    offset = stress_mean(table, test)[:, 0]
    shifted = solve.copy()
    with np.errstate(invalid="ignore"):
        shifted[:, 0] = np.where(solve[:, 0] > 0, solve[:, 0] * np.exp(offset), solve[:, 0])
    return {"physics_solve": solve, "physics_offset": shifted}


def dataset_arrays(dataset, index) -> dict:
    """The arrays baselines need, for graphs ``index`` of a SnapshotGraphDataset."""
    import torch

    index = torch.as_tensor(np.asarray(index))
    arrays = {
        "y": dataset.y[index].double().numpy(),
        "descriptors": dataset.descriptors[index].numpy(),
        "stress": dataset.stress[index].numpy(),
        "phi": dataset.phi[index].numpy(),
        "physics": dataset.physics[index].numpy(),
    }
    inputs = list(dataset.settings.graph_inputs)
    computed = [inputs.index(name) for name in inputs if name in COMPUTED_GRAPH_INPUTS]
    if computed:  # the graph inputs computed from positions and sigma, (G, k)
        arrays["computed_inputs"] = dataset.u[index][:, computed].double().numpy()
    return arrays


def physics_fold_metrics(run_dir, k: int, cache_dir) -> dict:
    """Metrics (``fold_metrics``) of the physics-only rows on the test fold ``k`` of a finished training run
    ``run_dir``, its graphs rebuilt from the fold's split file (the same files and graph settings: the
    same order as in training); for runs made before the rows were part of every report."""
    import json
    from pathlib import Path

    run_dir = Path(run_dir)
    split = json.loads((run_dir / f"fold{k}_split.json").read_text())
    settings = bundle_graph_settings(read_bundle(run_dir / f"fold{k}.pt"))  # no network needed
    dataset = SnapshotGraphDataset(split_files(split), settings, cache_dir)
    fitted = np.r_[split["train"], split["val"]]  # as the baselines: no early stopping to hold out for
    test = np.asarray(split["test"])
    rows = physics_rows(
        dataset_arrays(dataset, fitted), dataset_arrays(dataset, test), settings.targets.viscosity_scale
    )
    true = dataset.y_raw[test].numpy()
    groups = state_point_key(dataset.phi[test].numpy(), dataset.stress[test].numpy())
    jammed = dataset.jammed[test].numpy()
    return {name: fold_metrics(pred, true, groups, jammed) for name, pred in rows.items()}
