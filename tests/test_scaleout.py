"""Multirun launchers (joblib, submitit local) and the collect step."""

import json
import subprocess
import sys
from pathlib import Path

from rheograph.io.hdf5 import read_run_info
from rheograph.io.index import build_index, index_files, write_index
from rheograph.learn.datamodule import expand_files

ROOT = Path(__file__).resolve().parents[1]


def simulate_sweep(tmp_path, *overrides: str) -> subprocess.CompletedProcess:
    """``simulate.py -m sim=tiny <overrides>`` into ``tmp_path`` (no progress bar), its output captured."""
    cmd = [sys.executable, str(ROOT / "simulate.py"), "-m", "sim=tiny", *overrides]
    cmd += [f"output_root={tmp_path}", "progress=false"]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path)


def test_joblib_multirun_runs_jobs_in_parallel_and_collect_indexes_them(tmp_path):
    done = simulate_sweep(
        tmp_path,
        "hydra/launcher=joblib",
        "hydra.launcher.n_jobs=2",
        "sim.stress=1,20",
        "sim.strain=0.06",
        "sim.snapshot_interval=0.02",
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "Joblib.Parallel(n_jobs=2" in done.stdout + done.stderr
    files = sorted(tmp_path.glob("multirun/*/trajectory.h5"))
    assert len(files) == 2 and {f.parent.name.split("_")[2] for f in files} == {"s1", "s20"}
    (tmp_path / "junk.h5").write_bytes(b"junk")
    index = build_index([tmp_path])
    assert len(index["runs"]) == 2 and len(index["skipped"]) == 1
    assert all(e["status"] == "completed" and e["snapshots"] == 3 for e in index["runs"])
    path = tmp_path / "index.json"
    write_index(index, path)
    # stored relative to the index (a committed index stays valid in any clone), read back absolute
    assert all(not Path(e["path"]).is_absolute() for e in json.loads(path.read_text())["runs"])
    assert index_files(path) == [str(f.resolve()) for f in files]
    assert expand_files(str(path)) == sorted(str(f.resolve()) for f in files)


def test_a_sweep_runs_past_a_state_point_that_cannot_start_and_lists_it_at_the_end(tmp_path):
    """phi = 0.86 has no overlap-free start for 16 particles: that point fails with its reason, the
    sweep still runs phi = 0.5 (in another worker), then ends non-zero naming the failed point only."""
    done = simulate_sweep(
        tmp_path,
        "hydra/launcher=joblib",
        "hydra.launcher.n_jobs=2",
        "sim.n_particles=16",
        "sim.phi=0.86,0.5",
        "sim.strain=0.03",
    )
    assert done.returncode == 1, done.stderr[-2000:]
    tail = done.stderr.strip().splitlines()[-2:]
    assert tail[0].startswith("simulate.py: 1 state point(s) of this sweep could not run")
    assert "N16_phi0.86_" in tail[1] and "sim.relax_tolerance" in tail[1]
    (finished,) = tmp_path.glob("multirun/*/trajectory.h5")
    assert finished.parent.name.startswith("N16_phi0.5_")
    assert read_run_info(finished)["status"] == "completed"
    assert not (finished.parent / "failed.txt").exists()


def test_submitit_local_launcher_runs_a_simulation(tmp_path):
    done = simulate_sweep(
        tmp_path,
        "hydra/launcher=submitit_local",
        "hydra.launcher.timeout_min=10",
        "sim.stress=3",
        "sim.strain=0.03",
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert len(list(tmp_path.glob("multirun/*/trajectory.h5"))) == 1


def test_slurm_launcher_config_composes():
    from hydra import compose, initialize_config_dir

    from rheograph.cli.hydra_apps import register_resolvers

    register_resolvers()
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["hydra/launcher=slurm"], return_hydra_config=True)
    launcher = cfg.hydra.launcher
    assert launcher._target_.endswith("SlurmLauncher") and launcher.cpus_per_task == 1
