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
