"""The published surrogate numbers are guarded: committed model bundles (exact and imaging), run on the
committed dataset, reproduce the held-out predictions committed beside them (to float round-off), so that a
change in the features, the relaxation, the graph builder or the model code cannot move the docs' R²
without a test failing."""

import json
from pathlib import Path

import numpy as np
import pytest

from rheograph.learn.datamodule import split_files

ROOT = Path(__file__).resolve().parents[1]


def _first_test_run(run_dir: Path, k: int):
    split = json.loads((run_dir / f"fold{k}_split.json").read_text())
    saved = np.load(run_dir / f"fold{k}_predictions.npz")
    run = int(saved["run_id"][0])
    return (
        Path(split_files(split, ROOT)[run]),
        saved["pred"][saved["run_id"] == run],
        saved["true"][saved["run_id"] == run],
    )


def _shipped(name: str) -> tuple[str, str]:
    """(training run directory, fold-0 bundle) of a shipped model, from its card."""
    from rheograph.learn.registry import MODELS_DIR

    card = json.loads((MODELS_DIR / name / "card.json").read_text())
    return card["trained_from"], str(MODELS_DIR / name / "fold0.pt")


@pytest.mark.parametrize(
    "run_dir, bundle",
    [
        # the default inputs (graph=physics_solve), through the shipped models' bundles
        _shipped("N400_phi0.76"),
        _shipped("N400_phi0.70"),
        # positions-only physics features (graph=physics_positions), the run's own bundle
        ("docs/results/surrogate_study/physics_positions_grouped", None),
    ],
)
def test_committed_bundle_reproduces_its_committed_test_predictions(run_dir, bundle):
    from rheograph.graphs.dataset import snapshot_graphs
    from rheograph.learn.bundle import load_bundle, predict_dataset

    run_dir = ROOT / run_dir
    path, expected, truth = _first_test_run(run_dir, 0)
    module, settings, _ = load_bundle(bundle if bundle else run_dir / "fold0.pt")
    graphs = snapshot_graphs(path, settings, run_id=0)  # the training selection: strain >= min_strain
    pred, true, _ = predict_dataset(module, graphs)
    np.testing.assert_array_equal(true, truth)  # the same snapshots, in the same order
    np.testing.assert_allclose(pred, expected, rtol=1e-5, atol=1e-7)


def test_shipped_model_is_its_training_runs_bundles():
    """A shipped model's weights are the training run's, bit for bit (shipping only adds records)."""
    import torch

    run_dir, bundle = _shipped("N400_phi0.76")
    from rheograph.learn.bundle import read_bundle

    shipped = read_bundle(Path(bundle).with_name("fold3.pt"))
    trained = read_bundle(ROOT / run_dir / "fold3.pt")  # format 2, upgraded as it is read
    for key, value in trained["state_dict"].items():
        assert torch.equal(shipped["state_dict"][key], value), key
    assert shipped["graph"] == trained["graph"]
    assert shipped["hyper_parameters"] == trained["hyper_parameters"]


@pytest.mark.parametrize(
    "name",
    [
        # 5-17 s each (relaxations of noisy snapshots): the per-phi models in the long tests
        pytest.param("N400_phi0.70_imaging", marks=pytest.mark.slow),
        pytest.param("N400_phi0.76_imaging", marks=pytest.mark.slow),
        pytest.param("N400_phi0.80_imaging", marks=pytest.mark.slow),
        "pooled_N400_imaging",
    ],
)
def test_shipped_imaging_model_reproduces_its_committed_noisy_test_predictions(name):
    """The imaging models' published scores are guarded the same way: the seeded noisy copies of a
    test trajectory, relaxed and read as in training, give the committed predictions."""
    from rheograph.graphs.dataset import noisy_copy, snapshot_graphs
    from rheograph.io.snapshots import read_snapshots
    from rheograph.learn.bundle import load_bundle, predict_dataset

    run_dir, bundle = _shipped(name)
    run_dir = ROOT / run_dir
    split = json.loads((run_dir / "fold0_split.json").read_text())
    saved = np.load(run_dir / "fold0_predictions.npz")
    run = int(saved["run_id"][0])
    module, settings, _ = load_bundle(bundle)
    assert settings.noise_copies and settings.relax_strain  # noisy copies, relaxed before reading
    snaps = read_snapshots(split_files(split, ROOT)[run])
    graphs = [
        g
        for copy_id in range(settings.noise_copies)  # seeded per (trajectory, copy), as the cache builds them
        for g in snapshot_graphs(noisy_copy(snaps, settings.noise_range, [run, copy_id]), settings, run)
    ]
    pred, true, _ = predict_dataset(module, graphs)
    mine = saved["run_id"] == run
    np.testing.assert_array_equal(true, saved["true"][mine])
    # a relaxation is ~50-2000 implicit steps: round-off may grow past the one-solve's 1e-5
    np.testing.assert_allclose(pred, saved["pred"][mine], rtol=1e-4, atol=1e-7)
