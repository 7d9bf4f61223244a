"""The edges of the entry points: an output folder that cannot be written, two runs of one state point
started at the same moment, rejected settings (no run directory, no study database), a report not
written, files left out of a training set and unknown keys of a bare snapshot file: each one line or one
warning that names it, nothing lost."""

import fcntl
import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rheograph.errors import InputError
from rheograph.io.hdf5 import TrajectoryFileError
from rheograph.io.snapshots import read_snapshots, write_bare

ROOT = Path(__file__).resolve().parents[1]
# subprocesses import this checkout's package whatever their working directory
ENV = {**os.environ, "PYTHONPATH": str(ROOT / "src")}


def run(program, args, cwd):
    done = subprocess.run(
        [sys.executable, str(ROOT / program), *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=ENV,
        timeout=300,
    )
    return done.returncode, done.stdout + done.stderr


def one_error_line(code, output, program):
    assert code == 1, output[-3000:]
    assert "Traceback" not in output, output[-3000:]
    lines = [line for line in output.splitlines() if "error:" in line]
    assert len(lines) == 1, output[-3000:]
    assert lines[0].startswith(f"{program}: error: "), lines[0]
    return lines[0]


@pytest.mark.parametrize("program", ["simulate.py", "train.py"])
def test_an_output_folder_that_cannot_be_made_is_one_line(tmp_path, program):
    """The run directory under a file (NotADirectoryError: what a read-only folder gives as
    PermissionError, reproducible as root too): one line naming it, not Hydra's traceback."""
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder\n")
    line = one_error_line(*run(program, ["sim=tiny" if program == "simulate.py" else "debug=tiny",
                                         f"output_root={blocker / 'out'}"], tmp_path), program)  # fmt: skip
    assert f"cannot write {blocker / 'out'}" in line and "(Not a directory)" in line, line
    assert "output_root=<dir>" in line


def test_a_run_directory_whose_log_cannot_be_written_is_one_line(tmp_path):
    """The run directory exists but its log file cannot be opened (here a folder of that name): the
    logging module's ValueError, caused by the OSError, is one line naming the file."""
    run_dir = tmp_path / "run"
    (run_dir / "simulate.log").mkdir(parents=True)
    line = one_error_line(
        *run("simulate.py", ["sim=tiny", f"hydra.run.dir={run_dir}"], tmp_path), "simulate.py"
    )
    assert f"cannot write {run_dir / 'simulate.log'}" in line, line


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_output_folder_is_one_line(tmp_path):
    read_only = tmp_path / "read_only"
    read_only.mkdir()
    read_only.chmod(0o555)
    try:
        line = one_error_line(
            *run("simulate.py", ["sim=tiny", f"output_root={read_only}"], tmp_path), "simulate.py"
        )
    finally:
        read_only.chmod(0o755)
    assert "(Permission denied)" in line, line


def tiny_params():
    from rheograph.sim.params import SimParams

    return SimParams(n_particles=64, phi=0.70, strain=0.02, integrator="implicit", disp_max=2e-3)


def test_a_state_point_being_created_by_another_process_is_refused_by_name(tmp_path):
    """Two runs of one state point started at the same moment: the second to create the file is refused
    in one line (not an HDF5 traceback on the first one's half-made file), the first runs on."""
    from rheograph.runs.runner import run_state_point

    path = tmp_path / "trajectory.h5"
    with open(tmp_path / "trajectory.h5.creating", "a") as held:  # the other process, creating it
        fcntl.flock(held, fcntl.LOCK_EX)
        with pytest.raises(TrajectoryFileError, match="is being created by another process: is this state"):
            run_state_point(tiny_params(), path, progress=False)
    assert not path.exists() and not path.with_name("trajectory.h5.tmp").exists()
    # the lock goes with its holder: the next run creates the file and leaves no lock file
    assert run_state_point(tiny_params(), path, progress=False).status == "completed"
    assert not (tmp_path / "trajectory.h5.creating").exists()


def test_a_file_made_meanwhile_by_another_process_is_not_overwritten(tmp_path):
    from rheograph.io.hdf5 import TrajectoryFile
    from rheograph.runs.runner import run_state_point
    from rheograph.sim.integrator import Simulation

    path = tmp_path / "trajectory.h5"
    late = TrajectoryFile(path, tiny_params())  # saw no file, relaxed its start meanwhile
    state = Simulation(tiny_params()).state
    run_state_point(tiny_params(), path, progress=False)  # the other process, faster
    before = path.read_bytes()
    with pytest.raises(TrajectoryFileError, match="was created by another process meanwhile"):
        late.open_new(state)
    assert path.read_bytes() == before


@pytest.mark.slow
def test_two_simulations_started_at_the_same_moment_on_one_state_point(tmp_path):
    """Both started at once: one runs, the other ends with one line, whichever comes second to make
    the file (not an HDF5 traceback).  Which way a race goes is up to the machine: the tests above
    hold each outcome deterministically."""
    cmd = [sys.executable, str(ROOT / "simulate.py"), "sim=tiny", "sim.strain=0.1", f"output_root={tmp_path}",
           "progress=false"]  # fmt: skip
    procs = [
        subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=tmp_path, env=ENV
        )
        for _ in range(2)
    ]
    results = [(p.wait(timeout=300), p.stdout.read()) for p in procs]
    assert 0 in [code for code, _ in results], results
    for code, out in results:  # the second either refused in one line, or (started late) found it done
        assert "Traceback" not in out, out[-3000:]
        if code != 0:
            assert "another process" in one_error_line(code, out, "simulate.py")
    (path,) = tmp_path.glob("*/trajectory.h5")
    from rheograph.io.hdf5 import read_run_info

    assert read_run_info(path)["status"] == "completed"


@pytest.mark.parametrize("override", ["sim.phi=2", "sim.phi=abc", "sim.jam_intervals=2.5", "solver=umfpack"])
def test_rejected_simulation_settings_leave_no_run_directory(tmp_path, override):
    out = tmp_path / "out"
    one_error_line(*run("simulate.py", ["sim=tiny", override, f"output_root={out}"], tmp_path), "simulate.py")
    assert not out.exists()


def test_a_rejected_job_of_a_sweep_leaves_no_run_directory(tmp_path):
    """In a sweep Hydra makes each job's directory before the job starts: a rejected job removes its own
    (holding only what Hydra wrote into it)."""
    out = tmp_path / "out"
    args = ["-m", "sim=tiny", "sim.phi=2", f"output_root={out}", "hydra/launcher=basic"]
    one_error_line(*run("simulate.py", args, tmp_path), "simulate.py")
    assert [p.name for p in (out / "multirun").iterdir()] == ["multirun.yaml"]


@pytest.mark.parametrize(
    "value,shown",
    [("-1", "-1"), pytest.param("abc", "'abc'", marks=pytest.mark.slow)],  # 5 s each: tune.py in a process
)
def test_tune_n_trials_is_checked_before_any_state_is_created(tmp_path, value, shown):
    """Neither clipped to 0 without a word (-1) nor a traceback once the study database exists (abc)."""
    out = tmp_path / "out"
    line = one_error_line(
        *run("tune.py", [f"tune.n_trials={value}", f"output_root={out}"], tmp_path), "tune.py"
    )
    assert f"tune.n_trials={shown} is invalid: an integer >= 1" in line, line
    assert not out.exists()  # neither the run directory nor optuna.db


def test_run_study_checks_its_numbers_before_opening_the_storage(tmp_path):
    from hydra import compose, initialize_config_module

    from rheograph.learn.tune import run_study

    with initialize_config_module("rheograph.conf", version_base="1.3"):
        cfg = compose(config_name="tune", overrides=[f"output_root={tmp_path}", "tune.heartbeat_seconds=0"])
    with pytest.raises(InputError, match=r"tune.heartbeat_seconds=0 is invalid"):
        run_study(cfg, tmp_path)
    assert not (tmp_path / "optuna.db").exists()


def test_train_with_report_false_names_no_report(tmp_path, monkeypatch, caplog):
    """train.py report=false logged the path of the report it did not write; now it names metrics.json."""
    from hydra import compose, initialize_config_module

    import rheograph.learn.train
    from rheograph.cli.hydra_apps import train_main

    summary = {"val/loss": 0.1, **{f"test/r2_{k}": 0.9 for k in ("log_eta", "log_pressure", "z_mu")}}
    monkeypatch.setattr(rheograph.learn.train, "train_folds", lambda cfg, run_dir: summary)
    monkeypatch.chdir(tmp_path)
    for report, named, not_named in ((False, "metrics.json", "report.md"), (True, "report.md", None)):
        with initialize_config_module("rheograph.conf", version_base="1.3"):
            cfg = compose(config_name="train", overrides=[f"report={str(report).lower()}"])
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="rheograph"):
            train_main(cfg)
        text = caplog.text
        assert named in text
        if not_named:
            assert not_named not in text and "report=false" in text


def test_files_of_another_phi_or_n_are_named_when_left_out_of_a_training_set(monkeypatch, caplog, tmp_path):
    import rheograph.learn.datamodule as datamodule

    stored = {
        "a.h5": {"phi": 0.76, "n_particles": 400},
        "b.h5": {"phi": 0.70, "n_particles": 400},
        "c.h5": {"phi": 0.76, "n_particles": 2000},
    }
    files = [str(tmp_path / name) for name in stored]
    for f in files:
        Path(f).touch()
    monkeypatch.setattr(datamodule, "trajectory_param", lambda f, key, lfdem: stored[Path(f).name][key])
    module = datamodule.SnapshotDataModule(files, phi=0.76, n_particles=400)
    with caplog.at_level(logging.WARNING, logger="rheograph"):
        assert module.selected_files() == [files[0]]
    (phi_warning, n_warning) = [r.getMessage() for r in caplog.records]
    assert "data.phi=0.76: 1 file(s) of data.files at another phi left out" in phi_warning
    assert f"{files[1]} (phi 0.7)" in phi_warning and "a.h5" not in phi_warning
    assert f"{files[2]} (n_particles 2000)" in n_warning
    with pytest.raises(InputError, match=r"data.phi=0.8: no trajectory .* \(they hold phi = 0.7, 0.76\)"):
        datamodule.SnapshotDataModule(files, phi=0.8).selected_files()


def test_unknown_keys_of_a_bare_snapshot_file_are_named_with_the_closest_known_key(
    tiny_files, tmp_path, caplog
):
    write_bare(tmp_path / "s.npz", read_snapshots(tiny_files[0]))
    with caplog.at_level(logging.WARNING, logger="rheograph"):
        clean = read_snapshots(tmp_path / "s.npz")
    assert not caplog.records  # what write_bare writes is all known
    with np.load(tmp_path / "s.npz") as data:
        values = {key: data[key] for key in data.files}
    values["postion_noise"] = np.float64(0.01)  # a misspelt optional key: read as exact positions
    values["colour"] = np.zeros(3)
    np.savez(tmp_path / "t.npz", **values)
    with caplog.at_level(logging.WARNING, logger="rheograph"):
        misspelt = read_snapshots(tmp_path / "t.npz")
    (record,) = caplog.records
    message = record.getMessage()
    assert str(tmp_path / "t.npz") in message
    assert "'postion_noise' (did you mean 'position_noise'?)" in message and "'colour'" in message
    assert misspelt.position_noise == clean.position_noise == 0.0  # the file's own key, not the misspelt one
    assert np.array_equal(misspelt.positions, clean.positions)
