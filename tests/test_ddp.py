"""Data-parallel training with 2 CPU processes agrees with one process."""

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import tiny_training_overrides
from hydra import compose, initialize_config_dir

from rheograph.learn.train import train_folds

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow  # 20 s: two spawned training processes
def test_ddp_two_processes_matches_one_process(tiny_files, tmp_path):
    """Real weight updates: with each process's half of the training set as its one batch, the
    all-reduced gradient of two processes is the full-batch gradient of one, so five epochs of Adam give
    the same model (to float round-off: summation order) — and a model far from the untrained one, so the
    gradient exchange is what is tested.  Test snapshots are predicted once whatever the process count.
    Every run builds its batches from the device-resident graph sets (each DDP process from its own
    shard of graph ids); a run through PyG's per-batch loader trains the very same model."""
    base = [
        *tiny_training_overrides(tiny_files, tmp_path),
        "data.split=random",  # three runs in three grouped folds would train on one stress only
        "fold=0",
        "~logger",
        "report=false",
        "model.net.dropout=0.0",
        # no batch normalisation: each DDP process would keep running statistics of its own half of the
        # batches, a difference of normalisation, not of the gradient exchange this test is about
        "model.net.norm=layer",
        "model.net.edge_readout=false",
        "trainer.enable_progress_bar=false",
        "data.batch_size=1000",  # the whole training fold (one process) or its half (each of two): one step
        "callbacks.early_stopping.patience=1000",
        # the last epoch's weights, not the best validation epoch's: two epochs whose validation losses
        # differ by round-off could otherwise be picked differently by the two runs
        "~callbacks.model_checkpoint",
    ]
    runs = {
        "untrained": ["trainer.max_epochs=1", "model.optimizer.lr=1e-12"],
        "single": ["trainer.max_epochs=5"],
        "ddp": ["trainer.max_epochs=5", "trainer=ddp", "trainer.devices=2"],
        "loader": ["trainer.max_epochs=5", "data.device_resident=false"],
    }
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        for name, extra in runs.items():
            cfg = compose(config_name="train", overrides=base + extra)
            train_folds(cfg, tmp_path / name)
    split = json.loads((tmp_path / "single" / "fold0_split.json").read_text())
    assert len(split["train"]) % 2 == 0  # two equal halves: no padded (repeated) graph in either shard
    pred = {name: np.load(tmp_path / name / "test_predictions.npz")["pred"] for name in runs}
    assert pred["ddp"].shape == pred["single"].shape and pred["single"].shape[0] > 0
    moved = np.abs(pred["single"] - pred["untrained"]).max(axis=0)
    agree = np.abs(pred["ddp"] - pred["single"]).max(axis=0)
    assert np.all(agree < 1e-3 * moved), (agree, moved)
    np.testing.assert_array_equal(pred["loader"], pred["single"])
    metrics = {n: json.loads((tmp_path / n / "metrics.json").read_text())["folds"][0] for n in runs}
    for key in ("test/r2_eta", "test/r2_pressure", "test/r2_z_mu"):
        assert metrics["ddp"][key] == pytest.approx(metrics["single"][key], abs=1e-4), key
