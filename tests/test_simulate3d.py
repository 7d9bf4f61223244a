"""3D state points through the application: simulate.py sim=3d, the trajectory file's 3D layout, resume
after SIGKILL, rate control, 2D files unchanged, flow curves that never pool 2D and 3D, refusals."""

import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from rheograph.errors import InputError
from rheograph.io.hdf5 import read_checkpoint, read_run_info, read_timeseries
from rheograph.io.snapshots import read_snapshots
from rheograph.runs.runner import run_state_point
from rheograph.sim.integrator3d import SimState3D
from rheograph.sim.params import ParameterError, SimParams
from rheograph.sim.params3d import SimParams3D, params_from_mapping

ROOT = Path(__file__).resolve().parents[1]
# the smallest 3D system whose cube holds twice the interaction cut-off at phi 0.5 with margin (L = 8.5 a)
TINY_3D = dict(
    n_particles=50,
    phi=0.5,
    stress=10.0,
    strain=0.06,
    output_interval=0.01,
    snapshot_interval=0.03,
    steady_state_strain=0.0,
    integrator="implicit",
    disp_max=2e-3,
)


@pytest.fixture(scope="module")
def trajectory_3d(tmp_path_factory):
    path = tmp_path_factory.mktemp("three_d") / "trajectory.h5"
    outcome = run_state_point(SimParams3D(**TINY_3D), path, progress=False)
    assert outcome.status == "completed"
    return path


def simulate_3d_command(root, strain):
    return [
        sys.executable,
        str(ROOT / "simulate.py"),
        "sim=3d",
        "sim.n_particles=50",
        f"sim.strain={strain}",
        "sim.snapshot_interval=0.05",
        "sim.steady_state_strain=0.1",
        "sim.checkpoint_wall_seconds=0.2",
        f"output_root={root}",
        "progress=false",
    ]


def checkpointed_strain(root: Path) -> float:
    """The strain of a running simulation's last checkpoint under ``root`` (its copy as of that
    checkpoint; 0 before the first)."""
    copies = list(root.glob("*/trajectory.h5.last-checkpoint"))
    try:
        return read_run_info(copies[0])["strain"] if copies else 0.0
    except (OSError, KeyError):  # the copy being replaced at this moment
        return 0.0


def test_simulate_sim_3d_writes_a_3d_trajectory_and_resumes_after_sigkill_to_the_same_run(tmp_path):
    """simulate.py sim=3d, killed (SIGKILL: no handler, no last checkpoint) mid-run and run again, ends
    with the time series and snapshots of a run never interrupted, bit for bit."""
    strain = 1.0  # long enough that the run is still going after its first checkpoint on a fast machine
    reference = subprocess.Popen(
        simulate_3d_command(tmp_path / "ref", strain), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    cut = subprocess.Popen(
        simulate_3d_command(tmp_path / "cut", strain), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    deadline = time.monotonic() + 120
    while cut.poll() is None and checkpointed_strain(tmp_path / "cut") <= 0:
        # past a checkpoint beyond the start (on a loaded machine the first ones come at strain 0)
        assert time.monotonic() < deadline, "simulate.py sim=3d did not checkpoint within 120 s"
        time.sleep(0.05)
    time.sleep(0.1)  # between two checkpoints
    cut.send_signal(signal.SIGKILL)
    cut.wait()
    killed = next((tmp_path / "cut").glob("*/trajectory.h5"))
    assert killed.parent.name == "N50_phi0.5_s10_seed1_d0.002_implicit_3d"
    info = read_run_info(killed)
    assert info["status"] == "running" and 0 < info["strain"] < strain  # really killed mid-run
    final = subprocess.run(
        simulate_3d_command(tmp_path / "cut", strain), capture_output=True, text=True, timeout=300
    )
    assert final.returncode == 0, final.stderr[-2000:]
    assert reference.wait(timeout=300) == 0, reference.stderr.read()[-2000:]
    original = next((tmp_path / "ref").glob("*/trajectory.h5"))
    with h5py.File(original) as h5:
        assert h5.attrs["dim"] == 3 and h5.attrs["lz"] == h5.attrs["lx"] == h5.attrs["ly"]
        assert h5.attrs["status"] == "completed"
        rows, snaps = h5["timeseries/time"].shape[0], h5["snapshots/time"].shape[0]
        assert h5["snapshots/positions"].shape == (snaps, 50, 3)
        assert h5["snapshots/contact_stretch"].shape[1:] == (3,)
        assert h5["timeseries/stress"].shape == (rows, 6)
        stress = h5["timeseries/stress"][()]
        np.testing.assert_allclose(stress[:, 1], 10.0, rtol=1e-9)  # stress control
        np.testing.assert_allclose(h5["timeseries/n1"][()], stress[:, 0] - stress[:, 3], rtol=1e-12)
        np.testing.assert_allclose(h5["timeseries/n2"][()], stress[:, 3] - stress[:, 5], rtol=1e-12)
        np.testing.assert_allclose(
            h5["timeseries/pressure"][()], -stress[:, [0, 3, 5]].sum(1) / 3, rtol=1e-12
        )
    a, b = read_timeseries(original), read_timeseries(killed)
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    with h5py.File(original) as h1, h5py.File(killed) as h2:
        for key in ("positions", "contact_pairs", "contact_stretch", "viscosity"):
            np.testing.assert_array_equal(h1["snapshots"][key][()], h2["snapshots"][key][()], err_msg=key)


def test_a_3d_file_reads_back_as_3d_snapshots_and_checkpoint(trajectory_3d):
    snaps = read_snapshots(trajectory_3d)
    assert snaps.dim == 3 and snaps.positions.shape == (2, 50, 3)
    assert snaps.lz == pytest.approx(SimParams3D(**TINY_3D).box_length())
    assert all(stretch.shape[1:] == (3,) for _, _, stretch in snaps.contacts)
    params, state = read_checkpoint(trajectory_3d)
    assert params == SimParams3D(**TINY_3D) and isinstance(state, SimState3D)
    assert state.positions.shape == (50, 3) and state.lz == snaps.lz
    assert read_run_info(trajectory_3d)["dim"] == 3


def test_committed_2d_files_read_as_before_without_a_dim():
    path = ROOT / "data/paper/multirun/N400_phi0.8_s200_seed3_d0.001_implicit/trajectory.h5"
    with h5py.File(path) as h5:
        assert "dim" not in h5.attrs  # written before 3D existed
    snaps = read_snapshots(path)
    assert snaps.dim == 2 and snaps.lz is None and snaps.positions.shape[1:] == (400, 2)
    assert read_run_info(path)["dim"] == 2
    assert type(read_checkpoint(path)[0]) is SimParams


# the layout of a 2D run's file, as written before 3D existed (dataset: shape, dtype)
LAYOUT_2D = {
    "checkpoint/contact_state": ((173,), "int8"),
    "checkpoint/displacement": ((64, 2), "float64"),
    "checkpoint/pair_i": ((173,), "int64"),
    "checkpoint/pair_j": ((173,), "int64"),
    "checkpoint/positions": ((64, 2), "float64"),
    "checkpoint/radii": ((64,), "float64"),
    "checkpoint/stretch": ((173, 2), "float64"),
    "radii": ((64,), "float64"),
    "snapshots/contact_offset": ((5,), "int64"),
    "snapshots/contact_pairs": ((15, 2), "int32"),
    "snapshots/contact_state": ((15,), "int8"),
    "snapshots/contact_stretch": ((15, 2), "float32"),
    "snapshots/positions": ((4, 64, 2), "float64"),
    **{
        f"snapshots/{k}": ((4,), "float64") for k in ("le_offset", "pressure", "shear_rate", "strain", "time")
    },
    **{f"snapshots/{k}": ((4,), "float64") for k in ("viscosity", "z", "z_mu")},
    "timeseries/jammed": ((12,), "bool"),
    "timeseries/steps": ((12,), "int64"),
    **{
        f"timeseries/{k}": ((12,), "float64")
        for k in ("dt", "max_overlap", "max_stretch", "pressure", "shear_rate", "strain", "time")
    },
    **{f"timeseries/{k}": ((12,), "float64") for k in ("viscosity", "z", "z_mu")},
    **{
        f"timeseries/{k}": ((12, 3), "float64")
        for k in ("stress", "stress_contact", "stress_lubrication", "stress_solvent")
    },
}


def test_a_2d_run_writes_the_file_it_wrote_before_3d_existed(tmp_path):
    """Dataset names, shapes and dtypes, root attributes and a regression value of a tiny 2D run, as
    written before the 3D wiring (same solver, same numbers)."""
    params = SimParams(
        n_particles=64, phi=0.74, stress=5.0, strain=0.12, output_interval=0.01, snapshot_interval=0.03,
        steady_state_strain=0.02, disp_max=2e-3, integrator="implicit",
    )  # fmt: skip
    path = tmp_path / "run.h5"
    run_state_point(params, path, progress=False, solver="qdldl")
    layout = {}
    with h5py.File(path) as h5:
        h5.visititems(
            lambda name, obj: (
                layout.update({name: (obj.shape, str(obj.dtype))}) if isinstance(obj, h5py.Dataset) else None
            )
        )
        attrs = set(h5.attrs)
        assert h5["timeseries"].attrs["tensor_components"] == "xx, xy, yy (sigma_zz = 0); stresses in sigma0"
        strain, viscosity = h5["timeseries/strain"][-1], h5["summary"].attrs["viscosity"]
        steps = int(h5["checkpoint"].attrs["steps"])
    assert layout == LAYOUT_2D
    params_attrs = {f"param_{k}" for k in SimParams().stored_dict()}  # the keys of SimParams before 3D
    assert attrs == {"lx", "ly", "params", "producer", "schema_version", "solver", "status", *params_attrs}
    assert steps == 243
    assert strain == pytest.approx(0.11015268131251751, rel=1e-9)
    assert viscosity == pytest.approx(38.387481060276, rel=1e-7)


def test_rate_control_holds_the_imposed_rate_in_the_written_series(tmp_path):
    # an apparent viscosity sigma / rate = 33 far above jam_viscosity: an imposed rate still never stalls
    rate = {"control": "rate", "shear_rate": 0.3, "jam_viscosity": 2.0}
    params = SimParams3D(**{**TINY_3D, "strain": 0.1, **rate})
    path = tmp_path / "rate.h5"
    assert run_state_point(params, path, progress=False).status == "completed"
    ts = read_timeseries(path)
    assert np.all(ts["shear_rate"] == 0.3)
    np.testing.assert_allclose(ts["viscosity"], ts["stress"][:, 1] / 0.3, rtol=1e-12)
    np.testing.assert_allclose(np.diff(ts["strain"]), 0.3 * np.diff(ts["time"]), rtol=1e-9)
    assert not ts["jammed"].any()
    # the steady viscosity is the series' strain-weighted mean, not sigma / <rate> of stress control
    summary = read_run_info(path)["summary"]
    w = np.diff(ts["strain"], append=ts["strain"][-1] + np.median(np.diff(ts["strain"])))
    assert summary["viscosity"] == pytest.approx(np.average(ts["viscosity"], weights=w), rel=1e-12)
    assert "n1" in summary and "n2" in summary


def test_a_run_by_the_iterative_solver_matches_the_direct_one_and_says_which_solved_it(
    tmp_path, trajectory_3d
):
    """solver=amg writes the run the direct solver writes, to its tolerance (1e-6 relative residual), and
    the file names the solver and counts the solves it had to redo exactly (none here)."""
    path = tmp_path / "amg.h5"
    assert run_state_point(SimParams3D(**TINY_3D), path, progress=False, solver="amg").status == "completed"
    info, direct = read_run_info(path), read_run_info(trajectory_3d)
    assert info["solver"] == "amg" and direct["solver"] in ("cholmod", "qdldl")
    assert info["summary"]["solver_fallbacks"] == 0 and "solver_fallbacks" not in direct["summary"]
    ours, theirs = read_timeseries(path), read_timeseries(trajectory_3d)
    np.testing.assert_allclose(ours["strain"], theirs["strain"], rtol=1e-5)
    np.testing.assert_allclose(ours["viscosity"], theirs["viscosity"], rtol=1e-4)


@pytest.mark.parametrize(
    "override,message",
    [
        ("sim.phi=0.66", "sim.phi=0.66 is invalid: allowed 0 < phi <= 0.64 (random close packing"),
        ("sim.n_particles=30", "sim.n_particles=30 is too small for the interaction cut-off"),
        ("sim.control=strain", "sim.control='strain' is invalid: allowed one of ('stress', 'rate')"),
    ],
)
def test_bad_3d_input_is_one_line_and_leaves_no_run_directory(tmp_path, override, message):
    cmd = [sys.executable, str(ROOT / "simulate.py"), "sim=3d", override, f"output_root={tmp_path}/out"]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path)
    lines = done.stderr.strip().splitlines()
    assert done.returncode != 0 and "Traceback" not in done.stderr
    assert len(lines) == 1 and lines[0].startswith(f"simulate.py: error: {message}")
    assert not (tmp_path / "out").exists()


def test_a_3d_file_handed_to_predict_is_refused_in_one_line(trajectory_3d, tmp_path):
    out = tmp_path / "p.csv"
    cmd = [
        sys.executable, str(ROOT / "predict.py"), "--models", "N400_phi0.76", "--input", str(trajectory_3d),
        "--out", str(out),
    ]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert done.returncode != 0
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr
    assert lines[0].startswith(
        f"predict.py: error: {trajectory_3d}: 3D snapshots, but model N400_phi0.76 is a 2D model"
    )
    assert not out.exists()


def test_a_3d_model_refuses_a_2d_snapshot_in_one_line(trajectory_3d):
    """A model's bundle records the dimension of its training snapshots (absent in bundles made before
    3D: 2D); a 3D model refuses 2D snapshots, as a 2D model refuses 3D ones."""
    import dataclasses

    import rheograph

    model = rheograph.load_model("N400_phi0.76")
    model.domain = {**model.domain, "dim": 3}
    snaps = read_snapshots(trajectory_3d)
    flat = dataclasses.replace(snaps, positions=snaps.positions[:, :, :2], lz=None)
    with pytest.raises(InputError, match=r"2D snapshots, but model N400_phi0.76 is a 3D model") as info:
        model.predict_snapshots(flat)
    assert "\n" not in str(info.value)


def test_flow_curves_never_pool_2d_and_3d_runs(trajectory_3d, tmp_path):
    from rheograph.analysis.flow_curves import markdown_table, state_points

    three_d = SimParams3D(**TINY_3D)
    two_d = SimParams(**{k: v for k, v in TINY_3D.items() if k != "phi"}, phi=0.7)
    (tmp_path / "a").mkdir()
    Path(tmp_path / "a" / "3d.h5").write_bytes(trajectory_3d.read_bytes())
    run_state_point(two_d, tmp_path / "a" / "2d.h5", progress=False)
    points = state_points([tmp_path / "a"])
    assert sorted(p["dim"] for p in points) == [2, 3]
    table = markdown_table(points).splitlines()
    row_3d = next(line for line in table if line.startswith(f"| {three_d.n_particles} (3D) | 0.5 |"))
    assert "| – |" in row_3d  # no 2D pressure convention for spheres
    assert any(line.startswith("| 50 | 0.7 |") for line in table)


def test_dim_is_2_or_3_and_rate_control_holds_in_both():
    assert type(params_from_mapping({"phi": 0.7})) is SimParams
    assert type(params_from_mapping({"dim": 2, "phi": 0.7})) is SimParams
    assert params_from_mapping({"dim": 3, "control": "rate", "shear_rate": 0.2}).shear_rate == 0.2
    assert params_from_mapping({"control": "rate", "shear_rate": 0.2}) == SimParams(
        control="rate", shear_rate=0.2
    )
    with pytest.raises(ParameterError, match=r"sim.dim=4 is invalid: allowed one of \(2, 3\)"):
        params_from_mapping({"dim": 4})


def test_run_names_tag_3d_runs_and_imposed_rates_only():
    from rheograph.naming import run_name

    assert run_name(SimParams()) == "N400_phi0.76_s10_seed1_d0.001_euler"
    assert run_name(SimParams3D(n_particles=500, phi=0.5)) == "N500_phi0.5_s10_seed1_d0.001_euler_3d"
    rate = SimParams3D(n_particles=500, phi=0.5, control="rate", shear_rate=0.1)
    assert run_name(rate) == "N500_phi0.5_s10_rate0.1_seed1_d0.001_euler_3d"
    assert (
        run_name(SimParams(control="rate", shear_rate=0.1)) == "N400_phi0.76_s10_rate0.1_seed1_d0.001_euler"
    )


def test_the_memory_estimate_of_a_3d_run_is_its_own(monkeypatch):
    from rheograph.resources import check_simulation_memory, simulation_bytes

    # measured: 51 kB per particle at N = 500, 70 kB at 2000 (2D: under 6 kB)
    assert simulation_bytes(2000, dim=3) >= 1.5 * 70e3 * 2000 > 10 * simulation_bytes(2000)
    assert simulation_bytes(16000, dim=3) == pytest.approx(2 * 8 * simulation_bytes(2000, dim=3))
    monkeypatch.setenv("RHEOGRAPH_MEMORY_LIMIT_GB", "1")
    check_simulation_memory(20_000)  # 2D: 0.18 GB
    with pytest.raises(InputError, match="a 3D simulation of sim.n_particles=20000 needs about 4.52 GB"):
        check_simulation_memory(20_000, dim=3)
    # the multigrid solver keeps no factor: memory linear in N (measured 34-39 kB per particle)
    assert simulation_bytes(16000, dim=3, iterative=True) == pytest.approx(1.5 * 40e3 * 16000)
    check_simulation_memory(16_000, dim=3, iterative=True)  # 0.96 GB
    with pytest.raises(InputError, match="a 3D simulation of sim.n_particles=20000 needs about 1.2"):
        check_simulation_memory(20_000, dim=3, iterative=True)


def test_a_large_3d_simulation_is_sized_for_the_solver_auto_picks(monkeypatch):
    """solver=auto takes the multigrid solver for 3D systems from N = 2000, so the memory check before a
    run counts its memory, not a sparse factor's; a forced direct solver is counted as one."""
    from rheograph.sim.integrator3d import Simulation3D

    monkeypatch.setenv("RHEOGRAPH_MEMORY_LIMIT_GB", "1")
    with pytest.raises(InputError, match="needs about 1.2"):
        Simulation3D(SimParams3D(n_particles=20_000, phi=0.5))
    with pytest.raises(InputError, match="needs about 4.52 GB"):
        Simulation3D(SimParams3D(n_particles=20_000, phi=0.5), solver="qdldl")


def test_the_3d_preset_sets_every_3d_parameter_with_the_2d_physics():
    from hydra import compose, initialize_config_dir

    from rheograph.cli.hydra_apps import register_resolvers

    register_resolvers()
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=["sim=3d"])
    assert set(cfg.sim) == set(SimParams3D().to_dict())
    params = params_from_mapping(dict(cfg.sim))
    assert params == SimParams3D(
        n_particles=500, phi=0.5, integrator="implicit", disp_max=2e-3, snapshot_interval=0.1
    )
    two_d = SimParams(integrator="implicit", disp_max=2e-3, snapshot_interval=0.1).to_dict()
    assert {k: v for k, v in params.to_dict().items() if k in two_d and k not in ("n_particles", "phi")} == {
        k: v for k, v in two_d.items() if k not in ("n_particles", "phi")
    }
    n_small, n_large = params.species_counts()  # bidisperse 1 : 1.4 with equal volumes of both
    assert (n_small, n_large) == (366, 134) and n_small == pytest.approx(1.4**3 * n_large, rel=0.01)


def test_a_3d_run_never_resumes_a_2d_file(tmp_path):
    from rheograph.io.hdf5 import TrajectoryFileError

    path = tmp_path / "run.h5"
    two_d = SimParams(**{**TINY_3D, "phi": 0.7, "strain": 0.02})
    run_state_point(two_d, path, progress=False)
    three_d = SimParams3D(**{**TINY_3D, "seed": two_d.seed})
    with pytest.raises(TrajectoryFileError, match=r"another state point \(dim: file 2 vs requested 3"):
        run_state_point(three_d, path, progress=False)
