"""Device-agnostic training and prediction, tested on the CPU: device-resident batches equal PyG's
collation, batched and multi-process predictions equal the per-snapshot path, GPU requests without a GPU
are refused in one line."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import train_tiny_fold
from hydra import compose, initialize_config_dir
from torch_geometric.data import Batch, Data
from torch_geometric.loader import DataLoader

from rheograph.errors import InputError
from rheograph.learn.device_batch import DeviceGraphSet, device_loader

ROOT = Path(__file__).resolve().parents[1]
NO_GPU = pytest.mark.skipif(torch.cuda.is_available(), reason="tests the refusal on a machine without a GPU")


def random_graphs(count: int, seed: int = 0) -> list[Data]:
    """Graphs of different node and edge counts with the field kinds of a snapshot graph: node rows
    (float32, float64), edges (``edge_index`` incremented, attributes), graph rows (float, bool, int,
    NaN)."""
    gen = torch.Generator().manual_seed(seed)
    graphs = []
    for k in range(count):
        nodes = int(torch.randint(3, 9, (1,), generator=gen))
        edges = int(torch.randint(1, 15, (1,), generator=gen))
        graphs.append(
            Data(
                x=torch.randn(nodes, 3, generator=gen),
                pos=torch.randn(nodes, 2, generator=gen).double(),
                edge_index=torch.randint(0, nodes, (2, edges), generator=gen),
                edge_attr=torch.randn(edges, 4, generator=gen),
                y=torch.randn(1, 3, generator=gen),
                u=torch.randn(1, 2, generator=gen),
                stress=torch.tensor([float(k)], dtype=torch.float64),
                relaxed_strain=torch.tensor([np.nan], dtype=torch.float64),
                jammed=torch.tensor([k % 3 == 0]),
                run_id=torch.tensor([k // 2]),
            )
        )
    return graphs


def assert_same_batch(built: Batch, collated: Batch) -> None:
    """Same fields in the same order, equal values (NaN where NaN) and dtypes, and the same slice and
    increment records (what ``to_data_list`` and ``get_example`` read)."""
    assert list(built._store.keys()) == list(collated._store.keys())
    for key in collated.keys():
        mine, theirs = built[key], collated[key]
        assert mine.dtype == theirs.dtype and mine.shape == theirs.shape, key
        if mine.is_floating_point():
            assert torch.equal(mine.isnan(), theirs.isnan()), key
            mine, theirs = mine.nan_to_num(), theirs.nan_to_num()
        assert torch.equal(mine, theirs), key
    assert built.num_graphs == collated.num_graphs
    for record in ("_slice_dict", "_inc_dict"):
        mine, theirs = getattr(built, record), getattr(collated, record)
        assert list(mine) == list(theirs), record
        for key in theirs:
            assert torch.equal(mine[key], torch.as_tensor(theirs[key])), (record, key)


@pytest.mark.parametrize("ids", [[0], [4, 1, 1, 7, 0], list(range(9)), [8, 7, 6, 5, 4, 3, 2, 1, 0]])
def test_device_batches_equal_pyg_collation(ids):
    graphs = random_graphs(9)
    built = DeviceGraphSet(graphs).batch(ids)
    assert_same_batch(built, Batch.from_data_list([graphs[k] for k in ids]))
    # edge_index points into the batch's own nodes: each graph comes back whole
    for k, graph in zip(ids, built.to_data_list()):
        assert torch.equal(graph.edge_index, graphs[k].edge_index)
        assert torch.equal(graph.x, graphs[k].x)


def test_device_loader_yields_the_pyg_loaders_batches_in_its_order():
    """Same ids per batch for the same torch seed (shuffled over two epochs, and in order), so that the
    device-resident path trains on what the per-batch loader would have given."""
    graphs = random_graphs(11)
    graph_set = DeviceGraphSet(graphs)
    for shuffle in (True, False):
        torch.manual_seed(3)
        expected = [b for _ in range(2) for b in DataLoader(graphs, batch_size=4, shuffle=shuffle)]
        torch.manual_seed(3)
        got = [b for _ in range(2) for b in device_loader(graph_set, batch_size=4, shuffle=shuffle)]
        assert len(got) == len(expected) == 6
        for mine, theirs in zip(got, expected):
            assert_same_batch(mine, theirs)


def test_device_resident_training_equals_the_per_batch_loader(tiny_files, tmp_path):
    """Through Lightning (shuffled batches, validation, checkpoint choice, test predictions): the trained
    fold is the same, bit for bit, with the graph sets kept collated as with PyG's loader."""
    runs = {}
    for resident in ("true", "false"):
        run = train_tiny_fold(tiny_files, tmp_path / resident, f"data.device_resident={resident}")
        runs[resident] = np.load(run / "test_predictions.npz")["pred"]
        weights = torch.load(run / "fold0.pt", weights_only=True)["state_dict"]
        runs[resident + "_weights"] = weights
    assert runs["true"].shape[0] > 0
    np.testing.assert_array_equal(runs["true"], runs["false"])
    for key, value in runs["false_weights"].items():
        assert torch.equal(runs["true_weights"][key], value), key


def compose_train(overrides):
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        return compose(config_name="train", overrides=overrides)


def test_how_batches_are_assembled_is_not_part_of_the_run_fingerprint():
    """A run trained with the device-resident sets resumes and reports with the per-batch loader (the
    same batches), while a batch size of its own is another configuration."""
    from rheograph.learn.train import config_fingerprint

    base = config_fingerprint(compose_train(["~logger"]))
    assert config_fingerprint(compose_train(["~logger", "data.device_resident=false"])) == base
    assert config_fingerprint(compose_train(["~logger", "data.batch_size=7"])) != base


@NO_GPU
def test_gpu_trainer_without_a_gpu_is_refused_in_one_line():
    from rheograph.learn.train import check_run_settings

    for trainer in ("gpu", "ddp_gpu"):
        with pytest.raises(InputError, match=r"trainer.accelerator=gpu: no CUDA GPU .* trainer=cpu") as err:
            check_run_settings(compose_train([f"trainer={trainer}"]))
        assert "\n" not in str(err.value)
    check_run_settings(compose_train(["trainer=ddp"]))  # CPU data-parallel: unchanged


def test_fold_processes_with_a_data_parallel_trainer_are_refused():
    from rheograph.learn.train import check_run_settings

    with pytest.raises(InputError, match="fold_workers=2 with trainer.strategy=ddp_spawn"):
        check_run_settings(compose_train(["trainer=ddp", "fold_workers=2"]))
    check_run_settings(compose_train(["trainer=ddp", "fold_workers=2", "fold=0"]))  # one fold: in-process


def test_fold_processes_take_one_gpu_each_in_turn(monkeypatch):
    from rheograph.learn.train import fold_process_devices

    monkeypatch.setattr(torch.cuda, "device_count", lambda: 3)
    assert fold_process_devices(compose_train(["trainer=gpu"]), 4) == [0, 1, 2, 0]
    assert fold_process_devices(compose_train(["trainer=gpu"]), 2) == [0, 1]
    assert fold_process_devices(compose_train([]), 4) is None  # the CPU trainer: no pinning


@NO_GPU
def test_a_cuda_device_without_a_gpu_is_refused_in_one_line():
    from rheograph.learn.predict import load_model, resolve_device

    with pytest.raises(InputError, match=r"^--device=cuda: no CUDA GPU .* use cpu, or auto"):
        resolve_device("cuda", "--device")
    with pytest.raises(InputError, match="device=cuda:1: no CUDA GPU"):
        load_model("N400_phi0.76", device="cuda:1")
    with pytest.raises(InputError, match=r"device='tpu' is invalid"):
        resolve_device("tpu")
    assert resolve_device("auto") == torch.device("cpu")


def few_snapshots(count: int):
    from rheograph.io.snapshots import read_snapshots

    snaps = read_snapshots(
        str(ROOT / "data/paper/multirun/N400_phi0.76_s10_seed1_d0.002_implicit/trajectory.h5")
    )
    return dataclasses.replace(snaps.select(slice(len(snaps) - count, len(snaps))), contacts=None)


def test_batched_prediction_equals_the_per_snapshot_path():
    """The forward passes over every snapshot at once (on the CPU device) give each snapshot's prediction
    alone, to float32 round-off, and predict_snapshots' columns are these."""
    from rheograph.graphs.dataset import snapshot_graphs
    from rheograph.learn.bundle import predict_dataset
    from rheograph.learn.predict import load_model

    snaps = few_snapshots(5)
    model = load_model("N400_phi0.76", device="cpu")
    numerics = model.solve_numerics(snaps.phi, snaps.n_particles)
    alone = snapshot_graphs(snaps, model.settings, 0, numerics, training=False)
    table = model.predict_snapshots(snaps)
    per_snapshot = np.stack([predict_dataset(m, alone, batch_size=1)[0] for m, _, _ in model.models])
    batched = np.stack([predict_dataset(m, alone, batch_size=5, device="cpu")[0] for m, _, _ in model.models])
    np.testing.assert_allclose(batched, per_snapshot, rtol=1e-5)
    for k, name in enumerate(("eta", "pressure", "z_mu")):
        np.testing.assert_allclose(table[f"{name}_pred"], per_snapshot[:, :, k].mean(axis=0), rtol=1e-5)
    physics = np.concatenate([g.physics.numpy() for g in alone])
    np.testing.assert_array_equal(table["eta_solve"], physics[:, 0])
    assert len(set(np.round(table["eta_pred"], 6))) == 5  # five different snapshots, not one repeated


@pytest.mark.slow
def test_graphs_built_in_processes_equal_those_built_here():
    """Physics inputs (one solve, edges, counts) of snapshots split between two processes: the graphs of
    this process, field by field, in order; and the model's predictions through them the same."""
    from rheograph.graphs.dataset import snapshot_graphs
    from rheograph.learn.predict import load_model

    snaps = few_snapshots(5)
    model = load_model("N400_phi0.76", workers=2)
    numerics = model.solve_numerics(snaps.phi, snaps.n_particles)
    alone = snapshot_graphs(snaps, model.settings, 0, numerics, training=False)
    pooled = snapshot_graphs(snaps, model.settings, 0, numerics, training=False, workers=2)
    assert len(pooled) == len(alone) == 5
    for mine, theirs in zip(pooled, alone):
        assert_same_batch(Batch.from_data_list([mine]), Batch.from_data_list([theirs]))
    in_processes = model.predict_snapshots(snaps)
    here = load_model("N400_phi0.76").predict_snapshots(snaps)
    for column in ("eta_pred", "pressure_pred", "z_mu_pred", "eta_solve", "pressure_spring"):
        np.testing.assert_array_equal(in_processes[column], here[column])


def test_predict_py_runs_on_the_cpu_device(tmp_path, capsys):
    from rheograph.learn.predict import main

    path = ROOT / "data/paper/multirun/N400_phi0.76_s10_seed1_d0.002_implicit/trajectory.h5"
    out = tmp_path / "p.csv"
    main(["--models", "N400_phi0.76", "--input", str(path), "--out", str(out), "--device", "cpu"])
    assert out.exists() and "snapshots" in capsys.readouterr().out
    with pytest.raises(InputError, match="--workers 0"):
        main(["--models", "N400_phi0.76", "--input", str(path), "--out", str(out), "--workers", "0"])


@pytest.mark.slow  # 10 s: two tiny training runs
def test_baselines_fitted_alongside_a_gpu_fold_equal_those_fitted_after(tiny_files, tmp_path, monkeypatch):
    """On a GPU a fold's descriptor baselines are fitted in a thread while the network trains; forced
    here on the CPU, they run outside the main thread and give the baselines of the sequential path."""
    import threading

    import rheograph.learn.train as train

    after = train.read_fold_predictions(train_tiny_fold(tiny_files, tmp_path / "after"), 0)["baselines"]
    threads = []
    original = train.baseline_predictions

    def recorded(*args):
        threads.append(threading.current_thread() is threading.main_thread())
        return original(*args)

    monkeypatch.setattr(train, "baselines_alongside", lambda trainer: True)
    monkeypatch.setattr(train, "baseline_predictions", recorded)
    run = train_tiny_fold(tiny_files, tmp_path / "alongside")
    assert threads == [False]
    alongside = train.read_fold_predictions(run, 0)["baselines"]
    assert set(alongside) == set(after) and "descriptors" in after
    for name, values in after.items():
        np.testing.assert_array_equal(alongside[name], values)
