"""Bad input at every entry point ends with one line naming the problem, a non-zero status and no
traceback; corrupt files are recognised as such and never modified; a corrupt graph cache is rebuilt."""

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from conftest import tiny_training_overrides

from rheograph.graphs.dataset import GraphSettings, SnapshotGraphDataset

ROOT = Path(__file__).resolve().parents[1]


def run(args, cwd):
    done = subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=cwd, timeout=300)
    return done.returncode, done.stdout + done.stderr


def assert_one_line_error(code, output, *needles):
    assert code != 0, output
    assert "Traceback" not in output, output[-3000:]
    error_lines = [line for line in output.splitlines() if "error:" in line]
    assert len(error_lines) == 1, output[-3000:]
    for needle in needles:
        assert needle in error_lines[0], error_lines[0]


def digest(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def test_train_with_a_glob_matching_nothing(tmp_path):
    code, out = run(
        [str(ROOT / "train.py"), f"data.files={tmp_path}/nothing*.h5", f"output_root={tmp_path}", "~logger"],
        tmp_path,
    )
    assert_one_line_error(code, out, "train.py: error:", "data.files")


def test_train_with_an_invalid_option_names_the_key(tmp_path, tiny_files):
    code, out = run(
        [
            str(ROOT / "train.py"),
            f"data.files={Path(tiny_files[0]).parent}/*.h5",
            "data.phi=null",
            "data.n_particles=null",
            "data.split=alphabetical",
            f"output_root={tmp_path}",
            "~logger",
        ],
        tmp_path,
    )
    assert_one_line_error(code, out, "data.split", "random")


def test_train_on_a_truncated_trajectory_says_so_and_leaves_it_alone(tmp_path, tiny_files):
    data = tmp_path / "data"
    data.mkdir()
    for f in tiny_files:
        shutil.copy(f, data)
    victim = data / Path(tiny_files[1]).name
    victim.write_bytes(victim.read_bytes()[:20000])
    before = digest(victim)
    code, out = run(
        [
            str(ROOT / "train.py"),
            f"data.files={data}/*.h5",
            "data.phi=null",
            "data.n_particles=null",
            f"data.cache_dir={tmp_path / 'cache'}",
            f"output_root={tmp_path}",
            "~logger",
        ],
        tmp_path,
    )
    assert_one_line_error(code, out, victim.name, "truncated or corrupt", "move it aside")
    assert digest(victim) == before


def test_predict_on_a_file_that_is_not_hdf5(tmp_path):
    """With a real model (a shipped one), the input file itself is what is refused, by name."""
    garbage = tmp_path / "notes.h5"
    garbage.write_text("this is not a trajectory")
    code, out = run(
        [str(ROOT / "predict.py"), "--models", "N400_phi0.76", "--input", str(garbage), "--out", "x.csv"],
        tmp_path,
    )
    assert_one_line_error(code, out, "predict.py: error:", "notes.h5", "not a snapshot source")
    assert garbage.read_text() == "this is not a trajectory"
    assert not (tmp_path / "x.csv").exists()


def test_collect_and_flowcurve_refuse_missing_directories(tmp_path):
    code, out = run(
        ["-m", "rheograph.runs.sweep_index", str(tmp_path / "absent"), "--out", "i.json"], tmp_path
    )
    assert_one_line_error(code, out, "absent", "does not exist")
    code, out = run(
        ["-m", "rheograph.analysis.dataset_card", str(tmp_path / "absent"), "--out", "d"], tmp_path
    )
    assert_one_line_error(code, out, "absent", "does not exist")
    (tmp_path / "empty").mkdir()
    code, out = run(["-m", "rheograph.analysis.flow_curves", str(tmp_path / "empty"), "--out", "f"], tmp_path)
    assert_one_line_error(code, out, "no rheograph trajectory")


def test_a_corrupt_graph_cache_entry_is_rebuilt(tiny_files, tmp_path, caplog):
    settings = GraphSettings(min_strain=0.05)
    first = SnapshotGraphDataset(tiny_files, settings, tmp_path)
    cached = Path(first.processed_paths[0])
    cached.write_bytes(cached.read_bytes()[:100])  # e.g. a build killed mid-write
    with caplog.at_level("WARNING", logger="rheograph.graphs"):
        again = SnapshotGraphDataset(tiny_files, settings, tmp_path)
    assert len(again) == len(first)
    assert (again[0].edge_attr == first[0].edge_attr).all()
    assert any("unreadable" in r.message and "rebuilding" in r.message for r in caplog.records)


def test_a_killed_graph_build_resumes_from_the_files_it_finished(tiny_files, tmp_path, monkeypatch):
    """A build killed after its first file (one part written, one half-written) rebuilds only what it
    had not finished, and the set is the same graphs as an uninterrupted build's."""
    settings = GraphSettings(min_strain=0.05)
    whole = SnapshotGraphDataset(tiny_files, settings, tmp_path / "whole")
    built = []
    original = SnapshotGraphDataset._file_graphs

    def killed_after_the_first(self, run_id, path):
        built.append(run_id)
        if run_id == 1:
            Path(self.root, "parts", "1.pt").write_bytes(b"half a part")
            raise KeyboardInterrupt
        return original(self, run_id, path)

    monkeypatch.setattr(SnapshotGraphDataset, "_file_graphs", killed_after_the_first)
    with pytest.raises(KeyboardInterrupt):
        SnapshotGraphDataset(tiny_files, settings, tmp_path / "killed")
    assert built == [0, 1]
    built.clear()
    monkeypatch.setattr(
        SnapshotGraphDataset,
        "_file_graphs",
        lambda self, run_id, path: built.append(run_id) or original(self, run_id, path),
    )
    resumed = SnapshotGraphDataset(tiny_files, settings, tmp_path / "killed")
    assert built == list(range(1, len(tiny_files)))
    assert len(resumed) == len(whole) and not Path(resumed.root, "parts").exists()
    for a, b in zip(resumed, whole):
        assert torch.equal(a.edge_attr, b.edge_attr) and int(a.run_id) == int(b.run_id)


@pytest.mark.parametrize(
    "script, override, needles",
    [
        ("simulate.py", "sim.phii=0.76", ["sim.phii: no such setting", "did you mean sim.phi?"]),
        ("train.py", "data.phii=0.7", ["data.phii: no such setting", "did you mean data.phi?"]),
        ("simulate.py", "sim=n4000", ["sim/n4000", "the options are: 3d, lfdem, n2000, n400, tiny"]),
        ("train.py", "model=resgcnn", ["model/resgcnn", "resgcn, resgcn_physics"]),
        ("simulate.py", "sim.phi=[1,2", ["sim.phi=[1,2:"]),
        ("simulate.py", "--cfg=hydra -m", ["Only one of --run, --multirun, --cfg"]),
        pytest.param(
            "tune.py",
            "train_overrides=['data.phii=0.7']",
            ["tune.train_overrides: data.phii: no such setting"],
            marks=pytest.mark.slow,  # 7-11 s: a study's composition of every trial's overrides
        ),
    ],
)
def test_a_misspelled_override_is_one_line_naming_it(tmp_path, script, override, needles):
    code, out = run(
        [str(ROOT / script), *override.split(), f"hydra.run.dir={tmp_path}", f"output_root={tmp_path}"],
        tmp_path,
    )
    assert_one_line_error(code, out, f"{script}: error:", *needles)
    assert "+sim" not in out and "HYDRA_FULL_ERROR" not in out  # no advice to add the misspelled key


def test_an_omegaconf_error_inside_a_task_keeps_its_traceback(tmp_path):
    """Only the command line's composition errors become one line: the same error raised by code inside
    the task (a bug, not a misspelled override) keeps its traceback."""
    app = tmp_path / "app.py"
    app.write_text(
        "import hydra\n"
        "from rheograph.errors import one_line_errors, run_hydra_app\n"
        f"@hydra.main(version_base='1.3', config_path={str(ROOT / 'conf')!r}, config_name='train')\n"
        "def main(cfg):\n"
        "    with one_line_errors('app.py'):\n"
        "        return cfg.graph.cutof\n"
        "run_hydra_app(main, 'app.py')\n"
    )
    code, out = run([str(app), f"hydra.run.dir={tmp_path}"], tmp_path)
    assert code != 0 and "Traceback" in out and "cutof" in out and "app.py: error" not in out


def test_hydra_full_error_still_shows_a_composition_traceback(tmp_path):
    env = {**os.environ, "HYDRA_FULL_ERROR": "1"}
    done = subprocess.run(
        [sys.executable, str(ROOT / "simulate.py"), "sim.phii=0.76", f"hydra.run.dir={tmp_path}"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=env,
        timeout=120,
    )
    assert done.returncode != 0 and "Traceback" in done.stderr and "sim.phii" in done.stderr


def test_debug_flag_shows_the_traceback(tmp_path):
    import os

    env = {**os.environ, "RHEOGRAPH_DEBUG": "1"}
    done = subprocess.run(
        [sys.executable, "-m", "rheograph.runs.sweep_index", str(tmp_path / "absent"), "--out", "i.json"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=env,
        timeout=120,
    )
    assert done.returncode != 0 and "Traceback" in done.stderr


def tiny_run_command(root) -> list[str]:
    """simulate.py on the tiny preset: ~6 s of stepping, a checkpoint every 0.3 s of wall time."""
    return [
        sys.executable,
        str(ROOT / "simulate.py"),
        "sim=tiny",
        "sim.phi=0.76",
        "sim.stress=20",
        "sim.strain=2.0",
        "sim.checkpoint_wall_seconds=0.3",
        f"output_root={root}",
        "progress=false",
    ]


def assert_same_trajectory(ref_file, other_file):
    """Time series and snapshots equal bit for bit."""
    import h5py
    import numpy as np

    from rheograph.io.hdf5 import read_timeseries

    a, b = read_timeseries(ref_file), read_timeseries(other_file)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    with h5py.File(ref_file) as h1, h5py.File(other_file) as h2:
        for key in ("positions", "contact_pairs", "contact_stretch", "viscosity"):
            np.testing.assert_array_equal(h1["snapshots"][key][()], h2["snapshots"][key][()], err_msg=key)


def start_stepping(root, timeout=120.0):
    """simulate.py started and stepping (its trajectory file exists: imports and numba cache, 2-3 s, are
    behind it)."""
    import time

    proc = subprocess.Popen(tiny_run_command(root), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + timeout
    while proc.poll() is None and not list(Path(root).glob("*/trajectory.h5")):
        assert time.monotonic() < deadline, "simulate.py did not start stepping within 120 s"
        time.sleep(0.05)
    return proc


@pytest.fixture(scope="module")
def tiny_reference(tmp_path_factory):
    """The uninterrupted run of ``tiny_run_command``, shared by the interruption tests."""
    root = tmp_path_factory.mktemp("reference")
    reference = subprocess.run(tiny_run_command(root), capture_output=True, text=True, timeout=300)
    assert reference.returncode == 0, reference.stderr[-2000:]
    return next(root.glob("*/trajectory.h5"))


@pytest.mark.slow  # 14 s; test_runner.py resumes after SIGTERM in 3 s
def test_simulate_killed_with_sigkill_at_random_moments_resumes_to_the_uninterrupted_run(
    tiny_reference, tmp_path
):
    """SIGKILL (no handler, no final checkpoint) three times at seeded random moments, then run to the
    end: the time series and snapshots equal those of a run never interrupted, bit for bit."""
    import signal
    import time

    import numpy as np

    rng = np.random.default_rng(7)
    killed = 0
    for _ in range(3):
        proc = start_stepping(tmp_path / "cut")
        time.sleep(rng.uniform(0.2, 1.5))  # a random moment between checkpoints
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
            killed += 1
        proc.wait()
    final = subprocess.run(tiny_run_command(tmp_path / "cut"), capture_output=True, text=True, timeout=300)
    assert final.returncode == 0, final.stderr[-2000:]
    assert killed >= 1  # the run must really have been killed mid-way at least once
    assert_same_trajectory(tiny_reference, next((tmp_path / "cut").glob("*/trajectory.h5")))


def test_a_write_failing_for_lack_of_space_stops_with_one_line_and_the_run_resumes_whole(
    tiny_reference, tmp_path
):
    """A file-size limit hit mid-run (RLIMIT_FSIZE: what a full disk or a quota does to a write; before,
    the half-flushed HDF5 metadata left the trajectory unreadable and the run lost): simulate.py stops
    with one error line naming the file and what to do; the same command, with room again, resumes —
    from the copy as of the last checkpoint where the file itself was damaged — and ends bit for bit at
    the uninterrupted run, leaving no copy behind."""
    import resource
    import signal

    def at_most_100_kb_per_file():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a failing write (EFBIG), not a killed process
        resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))

    limited = subprocess.run(
        tiny_run_command(tmp_path / "cut"),
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=at_most_100_kb_per_file,
    )
    # status 1, not a crash: the HDF5 library's own flush of the failed file at exit had ended it in a
    # SIGSEGV; and no traceback: h5py's reports of the objects it cannot release are dropped
    assert limited.returncode == 1, limited.stderr[-3000:]
    assert "Traceback" not in limited.stderr, limited.stderr[-3000:]
    errors = [line for line in limited.stderr.splitlines() if line.startswith("simulate.py: error:")]
    assert len(errors) == 1, limited.stderr[-3000:]
    assert "trajectory.h5 failed" in errors[0] and "free space and rerun" in errors[0], errors[0]
    final = subprocess.run(tiny_run_command(tmp_path / "cut"), capture_output=True, text=True, timeout=300)
    assert final.returncode == 0, final.stderr[-2000:]
    cut_file = next((tmp_path / "cut").glob("*/trajectory.h5"))
    assert_same_trajectory(tiny_reference, cut_file)
    assert not list((tmp_path / "cut").glob("*/*.last-checkpoint*"))


def test_a_trajectory_damaged_mid_write_resumes_from_its_last_checkpoint_copy(tiny_reference, tmp_path):
    """Killed while HDF5 rewrote its metadata (emulated: SIGKILL, then the file cut short): the rerun
    sets the damaged file aside (kept as .damaged), resumes from the copy as of the last checkpoint with a
    warning, and ends bit for bit at the uninterrupted run."""
    import signal
    import time

    proc = start_stepping(tmp_path / "cut")
    cut_file = next((tmp_path / "cut").glob("*/trajectory.h5"))
    # killed once a checkpoint has been copied (waited for, not timed: a loaded machine steps slower)
    deadline = time.monotonic() + 120.0
    while not cut_file.with_name("trajectory.h5.last-checkpoint").exists():
        assert proc.poll() is None and time.monotonic() < deadline, "no checkpoint copy within 120 s"
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert cut_file.with_name("trajectory.h5.last-checkpoint").exists()
    # cut to its first 4 kB: below the end-of-file address its superblock last recorded, which a cut at
    # half the size need not be (HDF5 then opens the file as of that flush and nothing looks damaged)
    cut_file.write_bytes(cut_file.read_bytes()[:4096])
    final = subprocess.run(tiny_run_command(tmp_path / "cut"), capture_output=True, text=True, timeout=300)
    assert final.returncode == 0, final.stderr[-2000:]
    assert "resuming from its copy as of the last checkpoint" in final.stdout + final.stderr
    assert_same_trajectory(tiny_reference, cut_file)
    assert cut_file.with_name("trajectory.h5.damaged").exists()
    assert not cut_file.with_name("trajectory.h5.last-checkpoint").exists()


def test_tune_with_bad_fixed_overrides_stops_before_the_first_trial(tmp_path):
    code, out = run(
        [
            str(ROOT / "tune.py"),
            f"train_overrides=['data.files={tmp_path}/nothing*.h5']",
            "tune.n_trials=2",
            f"output_root={tmp_path}",
        ],
        tmp_path,
    )
    assert_one_line_error(code, out, "tune.py: error:", "data.files")


@pytest.mark.slow  # 15 s; test_learning.py's killed fold resumes in 3 s
def test_train_killed_with_sigkill_resumes_keeping_finished_folds(tiny_files, tmp_path):
    """SIGKILL train.py once its first fold has finished; the same command into the same run directory
    keeps that fold (its bundle untouched) and trains the others."""
    import json
    import signal
    import time

    run_dir = tmp_path / "run"
    cmd = [
        sys.executable,
        str(ROOT / "train.py"),
        f"data.files={Path(tiny_files[0]).parent}/*.h5",
        "data.phi=null",
        "data.n_particles=null",
        "data.split=random",
        "data.num_folds=3",
        f"data.cache_dir={tmp_path / 'cache'}",
        "graph.min_strain=0.05",
        "trainer.max_epochs=40",
        "trainer.enable_progress_bar=false",
        "model.net.hidden=8",
        "~logger",
        "report=false",
        f"hydra.run.dir={run_dir}",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path)
    deadline = time.time() + 240
    while not (run_dir / "fold0_result.json").exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    assert (run_dir / "fold0_result.json").exists() and proc.poll() is None, "fold 0 did not finish first"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (run_dir / "metrics.json").exists()
    kept = (run_dir / "fold0.pt").read_bytes()
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "fold 0 was finished by an earlier run" in done.stdout + done.stderr
    assert (run_dir / "fold0.pt").read_bytes() == kept
    folds = json.loads((run_dir / "metrics.json").read_text())["folds"]
    assert [f["fold"] for f in folds] == [0, 1, 2]


@pytest.mark.slow  # 7 s; test_tune_with_bad_fixed_overrides_stops_before_the_first_trial covers the same path
def test_tune_with_a_bad_fixed_model_option_stops_before_the_first_trial(tmp_path, tiny_files):
    overrides = [*tiny_training_overrides(tiny_files, tmp_path), "model.net.aggr=sum"]
    code, out = run(
        [
            str(ROOT / "tune.py"),
            "train_overrides=[" + ",".join(f"'{o}'" for o in overrides) + "]",
            "tune.n_trials=2",
            f"tune.storage=sqlite:///{tmp_path}/study.db",
            f"output_root={tmp_path}",
        ],
        tmp_path,
    )
    assert_one_line_error(code, out, "tune.py: error:", "model.net.aggr='sum' is invalid")


def test_a_write_finding_no_room_ends_any_entry_point_with_one_line():
    """Disk full, quota reached or a file-size limit (ENOSPC, EDQUOT, EFBIG: what torch.save or a report
    meets under train.py, measured with RLIMIT_FSIZE) end the program with one line saying so — also
    when wrapped as the cause of another error; any other OSError keeps its traceback (a bug or a
    missing file is not a full disk)."""
    import errno

    from rheograph.errors import one_line_errors

    for code in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        with pytest.raises(SystemExit) as stop:
            with one_line_errors("train.py"):
                try:
                    raise OSError(code, os.strerror(code), "/runs/x/fold0.pt")
                except OSError as exc:
                    raise RuntimeError("saving the bundle failed") from exc
        message = str(stop.value)
        assert message.startswith("train.py: error: no room to write /runs/x/fold0.pt"), message
        assert "rerun the same command" in message
    with pytest.raises(FileNotFoundError):
        with one_line_errors("train.py"):
            raise FileNotFoundError(errno.ENOENT, "No such file or directory", "/runs/x")


@pytest.mark.slow  # 8 s: an Optuna storage connection attempt
def test_tune_with_a_bad_storage_url_is_one_line(tmp_path):
    code, out = run([str(ROOT / "tune.py"), "tune.storage=notadb://x", f"output_root={tmp_path}"], tmp_path)
    assert_one_line_error(code, out, "tune.py: error:", "tune.storage='notadb://x'", "database URL")
