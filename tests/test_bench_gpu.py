"""bench/gpu_report.py: the tables of bench/gpu.py's JSON, GPU and CPU side by side."""

from conftest import load_bench_script


def test_gpu_report_puts_each_measurement_in_its_row_and_column():
    report = load_bench_script("gpu_report")
    meta = {
        "device": "cuda",
        "device_name": "H200",
        "cpu_count": 16,
        "torch": "2",
        "lightning": "2",
        "torch_geometric": "2",
        "scikit_sparse": False,
        "repeats": 3,
        "cpu_side_threads": 2,
    }
    epoch = [
        {"batch_size": 32, "loader": "PyG per batch", "seconds_per_epoch": 0.38, "train_graphs": 360},
        {"batch_size": 32, "loader": "device-resident", "seconds_per_epoch": 0.077, "train_graphs": 360},
    ]
    cpu_epoch = [dict(r, seconds_per_epoch=s) for r, s in zip(epoch, (0.61, 0.55))]
    fold = {"settings": "demo_gpu", "batch_size": 128, "lr": 0.01, "epochs": 60, "fold": 3}
    fold |= {"wall_seconds": 4.25, "r2_log_eta": 0.98761, "r2_log_pressure": 0.99991, "r2_z_mu": 0.99993}
    text = report.render(
        {
            "meta": meta,
            "parts": {
                "cache": {"seconds": 19.5, "graphs": 600},
                "a": {"cuda": epoch, "cpu": cpu_epoch},
                "b": {"cuda": [fold]},
            },
        }
    )
    assert "| 32 | PyG per batch | 380 | 610 |" in text
    assert "| 32 | device-resident | 77 | 550 |" in text
    assert "| cuda | demo_gpu (128, 0.01) | 3 | 4.2 | 0.9876 | 0.9999 | 0.9999 |" in text
    assert "600 graphs, one process): 19.5 s" in text and "absent: qdldl" in text
    assert "Prediction" not in text  # part d not measured: no empty table


def test_gpu_report_names_the_physics_solver_and_the_crossover():
    """Part d's rows say how the physics inputs were solved (rows written before the option: sparse);
    part f's rows give both solvers per problem and their ratio."""
    report = load_bench_script("gpu_report")
    meta = {"device": "cuda", "device_name": "H100", "cpu_count": 16, "torch": "2", "lightning": "2"}
    meta |= {"torch_geometric": "2", "scikit_sparse": True, "repeats": 3, "cpu_side_threads": 2}
    row = {"case": "N = 400", "model": "N400_phi0.76", "snapshots": 1000, "fold_models": 5, "workers": 8}
    row |= {"physics_seconds": 1.5, "forward_seconds": 0.2, "predict_snapshots_seconds": 1.8}
    dense = dict(row, physics_solver="dense batches, cuda")
    crossover = {"dim": 3, "n_particles": 500, "n_dof": 3000, "nonzeros": 250000, "sparse_ms": 24.0}
    crossover |= {"dense_batch": 16, "dense_ms_per_problem": 3.0, "device": "cuda"}
    text = report.render({"meta": meta, "parts": {"d": {"cuda": [dense], "cpu": [row]}, "f": [crossover]}})
    assert (
        "| 1000 × N = 400 | N400_phi0.76 (5) | cuda | 8 | dense batches, cuda | 1.50 | 0.200 | 1.80 |" in text
    )
    assert "| 1000 × N = 400 | N400_phi0.76 (5) | cpu | 8 | sparse, CPU | 1.50 |" in text
    assert "| 3D | 500 | 3000 | 250000 | 24.00 | 3.00 (16, cuda) | 8.00 |" in text
