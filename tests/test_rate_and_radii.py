"""Rate control in 2D and any radii (bidisperse, polydisperse, from a file) in 2D and 3D: the imposed rate
is held and the stress measured, a rate-controlled step at the rate stress control chose is that step,
the default path's files are what they were, drawn radii have their spread and phi, radii files are
read or refused in one line, and simulate.py runs with these settings."""

import copy
import json
import math
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from rheograph.errors import InputError
from rheograph.io.hdf5 import read_params, read_run_info, read_timeseries
from rheograph.io.snapshots import read_snapshots
from rheograph.naming import run_name
from rheograph.runs.runner import run_state_point
from rheograph.sim import SimParams, Simulation
from rheograph.sim.params import ParameterError
from rheograph.sim.params3d import SimParams3D, params_from_mapping
from rheograph.sim.radii import TRUNCATION

ROOT = Path(__file__).resolve().parents[1]
TINY = dict(
    n_particles=64, phi=0.74, stress=5.0, strain=0.05, output_interval=0.01, snapshot_interval=0.03,
    steady_state_strain=0.02, disp_max=2e-3, integrator="implicit",
)  # fmt: skip
# the stored params of TINY as every 2D file wrote them before rate control and radii existed
STORED_2D = (
    '{"n_particles": 64, "phi": 0.74, "stress": 5.0, "seed": 1, "strain": 0.05, "size_ratio": 1.4, "mu": '
    '0.5, "critical_load": 1.0, "lub_max_gap": 0.5, "delta": 0.001, "kn_coefficient": 20000.0, '
    '"kt_ratio": 0.5, "disp_max": 0.002, "integrator": "implicit", "lagged_step_control": false, "dt_max": '
    '1.0, "neighbour_skin": 0.4, "output_interval": 0.01, "snapshot_interval": 0.03, '
    '"steady_state_strain": 0.02, "jam_viscosity": 100000.0, "jam_intervals": 10, "max_wall_seconds": '
    '0.0, "checkpoint_wall_seconds": 60.0, "relax_tolerance": 0.0001, "initial_min_gap": 0.01}'
)


def test_a_default_2d_run_stores_its_params_as_before(tmp_path):
    path = tmp_path / "run.h5"
    run_state_point(SimParams(**TINY), path, progress=False, solver="qdldl")
    with h5py.File(path) as h5:
        assert h5.attrs["params"] == STORED_2D
        params_attrs = {k for k in h5.attrs if k.startswith("param_")}
    assert params_attrs == {f"param_{k}" for k in json.loads(STORED_2D)}
    # extended (a resume rewrites the params): still the old layout, the new strain in it
    run_state_point(SimParams(**{**TINY, "strain": 0.06}), path, progress=False, solver="qdldl")
    assert read_params(path) == {**json.loads(STORED_2D), "strain": 0.06}
    with h5py.File(path) as h5:
        assert list(json.loads(h5.attrs["params"])) == list(json.loads(STORED_2D))
        assert {k for k in h5.attrs if k.startswith("param_")} == params_attrs
    assert run_name(SimParams(**TINY)) == "N64_phi0.74_s5_seed1_d0.002_implicit"
    # and a file of the old layout names the same state point (the new keys read as their defaults)
    assert params_from_mapping(json.loads(STORED_2D)) == SimParams(**TINY)


def test_2d_rate_control_holds_the_rate_and_measures_the_stress(tmp_path):
    rate = {"control": "rate", "shear_rate": 0.2, "jam_viscosity": 2.0}  # sigma / rate >> jam viscosity
    params = SimParams(**{**TINY, "strain": 0.15, **rate})
    assert run_name(params) == "N64_phi0.74_s5_rate0.2_seed1_d0.002_implicit"
    path = tmp_path / "rate.h5"
    assert run_state_point(params, path, progress=False).status == "completed"
    stored = read_params(path)
    assert stored["control"] == "rate" and stored["shear_rate"] == 0.2
    assert params_from_mapping(stored) == params
    ts = read_timeseries(path)
    assert ts["shear_rate"].size > 3 and np.all(ts["shear_rate"] == 0.2)
    np.testing.assert_allclose(ts["viscosity"], ts["stress"][:, 1] / 0.2, rtol=1e-12)
    np.testing.assert_allclose(np.diff(ts["strain"]), 0.2 * np.diff(ts["time"]), rtol=1e-9)
    assert not ts["jammed"].any()
    summary = read_run_info(path)["summary"]  # the strain-weighted mean viscosity, as in 3D
    steady = ts["strain"] >= params.steady_state_strain
    s = ts["strain"][steady]
    w = np.diff(s, append=s[-1] + np.median(np.diff(s)))
    assert summary["viscosity"] == pytest.approx(np.average(ts["viscosity"][steady], weights=w), rel=1e-12)


@pytest.fixture(scope="module")
def sheared():
    sim = Simulation(SimParams(n_particles=100, phi=0.78, stress=20.0, integrator="implicit", disp_max=2e-3))
    for _ in range(200):
        sim.step()
    return sim


def test_a_2d_rate_controlled_step_at_the_rate_stress_control_chose_is_that_step(sheared):
    stress_sim = Simulation(sheared.params, copy.deepcopy(sheared.state))
    r_stress = stress_sim.step(record=True)
    assert r_stress.n_contacts > 0
    rate = r_stress.shear_rate
    rate_params = SimParams(**{**sheared.params.to_dict(), "control": "rate", "shear_rate": rate})
    rate_sim = Simulation(rate_params, copy.deepcopy(sheared.state))
    r_rate = rate_sim.step(record=True)
    assert r_rate.shear_rate == rate and r_rate.dt == r_stress.dt
    assert r_rate.stress[1] == pytest.approx(20.0, rel=1e-10)  # the stress stress control imposed
    np.testing.assert_allclose(rate_sim.state.positions, stress_sim.state.positions, rtol=0, atol=1e-12)
    for _ in range(20):
        assert rate_sim.step().shear_rate == rate


@pytest.mark.parametrize("cls,kw", [(SimParams, {}), (SimParams3D, {"n_particles": 400, "phi": 0.5})])
def test_polydisperse_radii_have_the_requested_spread_and_phi(cls, kw):
    params = cls(radii="polydisperse", polydispersity=0.05, n_particles=kw.get("n_particles", 2000),
                 phi=kw.get("phi", 0.7), seed=3)  # fmt: skip
    radii = params.particle_radii()
    n_small, _ = params.species_counts()
    for species, mean in ((radii[:n_small], 1.0), (radii[n_small:], params.size_ratio)):
        rel = species / mean - 1.0
        assert np.abs(rel).max() <= TRUNCATION * 0.05 + 1e-15
        # a normal truncated at 2 sigma has standard deviation 0.880 sigma
        assert rel.std() == pytest.approx(0.880 * 0.05, rel=0.15) and abs(rel.mean()) < 0.01
    np.testing.assert_array_equal(radii, cls(**{**params.to_dict()}).particle_radii())  # seeded
    assert not np.array_equal(radii, cls(**{**params.to_dict(), "seed": 4}).particle_radii())
    box = params.box_length()
    dim = params.DIM
    filled = math.pi * np.sum(radii**2) if dim == 2 else 4.0 * math.pi / 3.0 * np.sum(radii**3)
    assert filled / box**dim == pytest.approx(params.phi, rel=1e-12)


def test_a_2d_run_on_polydisperse_radii_writes_them_with_the_box_of_phi(tmp_path):
    params = SimParams(**{**TINY, "strain": 0.02, "radii": "polydisperse", "polydispersity": 0.1})
    assert run_name(params) == "N64_phi0.74_s5_poly0.1_seed1_d0.002_implicit"
    path = tmp_path / "poly.h5"
    run_state_point(params, path, progress=False)
    with h5py.File(path) as h5:
        radii, lx, ly = h5["radii"][()], h5.attrs["lx"], h5.attrs["ly"]
    np.testing.assert_array_equal(radii, params.particle_radii())
    assert math.pi * np.sum(radii**2) / (lx * ly) == pytest.approx(0.74, rel=1e-12)
    assert read_params(path)["polydispersity"] == 0.1
    # its snapshots read back (the smallest drawn radius lies below the small species' nominal 1) ...
    snaps = read_snapshots(path)
    assert radii.min() < 1.0 and np.array_equal(snaps.radii, radii) and snaps.phi == 0.74
    # ... while radii in other units are still refused, below the spread's band as above it
    for factor in (0.7, 1.3):
        with h5py.File(path, "r+") as h5:
            h5["radii"][...] = radii * factor
        with pytest.raises(
            InputError, match=r"units of the small radius a \(smallest radius between 0.8 and 1,"
        ):
            read_snapshots(path)


@pytest.mark.parametrize("suffix", [".txt", ".npy"])
def test_a_radii_file_round_trips(tmp_path, suffix):
    radii = np.random.default_rng(0).uniform(1.0, 2.5, 64)
    path = tmp_path / f"r{suffix}"
    np.save(path, radii) if suffix == ".npy" else np.savetxt(path, radii, header="radii [a]")
    params = SimParams(**{**TINY, "strain": 0.02, "radii": "file", "radii_file": str(path)})
    np.testing.assert_array_equal(params.particle_radii(), radii)
    out = tmp_path / "file.h5"
    run_state_point(params, out, progress=False)
    with h5py.File(out) as h5:
        np.testing.assert_array_equal(h5["radii"][()], radii)
        assert math.pi * np.sum(radii**2) / (h5.attrs["lx"] * h5.attrs["ly"]) == pytest.approx(0.74)
    path.unlink()  # a stored state point stays readable without its radii file
    assert params_from_mapping(read_params(out)) == params
    np.testing.assert_array_equal(read_snapshots(out).radii, radii)  # its radii define a


@pytest.mark.parametrize(
    "content,message",
    [
        ("1\n" * 63 + "-1.2\n", "radius 63 is -1.2: every radius must be finite and > 0"),
        ("1\n" * 63 + "0\n", "radius 63 is 0.0: every radius must be finite and > 0"),
        ("1\n" * 63 + "nan\n", "radius 63 is nan: every radius must be finite and > 0"),
        ("1\n" * 60, "60 radii, but sim.n_particles=64"),
        ("1 2\n" * 64, "expected one column of numbers, found an array of shape (64, 2)"),
        ("1\n" * 63 + "big\n", "not a list of numbers ("),
        ("1\n" * 63 + "11\n", "largest / smallest radius 11 > 10"),
        (None, "no such file"),
    ],
)
def test_bad_radii_files_are_refused_in_one_line_naming_the_file(tmp_path, content, message):
    path = tmp_path / "bad.txt"
    if content is not None:
        path.write_text(content)
    params = SimParams(**{**TINY, "radii": "file", "radii_file": str(path)})
    with pytest.raises(ParameterError) as err:
        params.particle_radii()
    assert str(err.value).startswith(f"sim.radii_file={path}: {message}")
    assert "\n" not in str(err.value)


def test_radii_and_control_settings_are_checked():
    with pytest.raises(ParameterError, match="sim.control='strain' is invalid"):
        SimParams(control="strain")
    with pytest.raises(ParameterError, match="sim.polydispersity=0.0 is invalid: allowed 0 < polyd"):
        SimParams(radii="polydisperse")
    with pytest.raises(ParameterError, match="sim.polydispersity=0.05 is invalid"):
        SimParams(polydispersity=0.05)  # bidisperse radii: a spread would be ignored
    with pytest.raises(ParameterError, match="sim.radii_file='' is invalid"):
        SimParams(radii="file")
    with pytest.raises(ParameterError, match="sim.radii='gaussian' is invalid"):
        SimParams(radii="gaussian")
    # 3D files keep their params layout: dim and both control keys last, radii keys only off default
    stored = SimParams3D(n_particles=100, phi=0.4).stored_dict()
    assert list(stored)[-3:] == ["dim", "control", "shear_rate"] and "radii" not in stored


def test_simulate_py_runs_2d_rate_control_on_polydisperse_radii(tmp_path):
    cmd = [
        sys.executable, str(ROOT / "simulate.py"), "sim=tiny", "sim.strain=0.03", "sim.control=rate",
        "sim.shear_rate=0.05", "sim.radii=polydisperse", "sim.polydispersity=0.05", "progress=false",
        f"output_root={tmp_path}/out",
    ]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr
    (path,) = (tmp_path / "out").glob("*/trajectory.h5")
    assert path.parent.name == "N64_phi0.7_s10_rate0.05_poly0.05_seed1_d0.002_implicit"
    assert np.all(read_timeseries(path)["shear_rate"] == 0.05)


def test_simulate_py_refuses_a_bad_radii_file_in_one_line(tmp_path):
    (tmp_path / "r.txt").write_text("1\n-1\n")
    cmd = [
        sys.executable, str(ROOT / "simulate.py"), "sim=tiny", "sim.radii=file", "sim.radii_file=r.txt",
        f"output_root={tmp_path}/out",
    ]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    lines = done.stderr.strip().splitlines()
    assert done.returncode != 0 and len(lines) == 1 and "Traceback" not in done.stderr
    assert lines[0].startswith("simulate.py: error: sim.radii_file=r.txt: 2 radii, but sim.n_particles=64")
    assert not (tmp_path / "out").exists()


def test_flow_curves_keep_runs_of_other_radii_apart(tmp_path):
    """A polydisperse run at the state point of a bidisperse one is a different suspension: its own row,
    labelled by its radii, never pooled as another seed."""
    from rheograph.analysis.flow_curves import markdown_table, state_points

    (tmp_path / "runs").mkdir()
    for name, extra in (("bi", {}), ("poly", {"radii": "polydisperse", "polydispersity": 0.1})):
        params = SimParams(**{**TINY, "strain": 0.02, **extra})
        run_state_point(params, tmp_path / "runs" / f"{name}.h5", progress=False)
    points = state_points([tmp_path / "runs"])
    assert sorted(p["radii"] for p in points) == ["", "polydisperse 0.1"]
    assert all(p["n_runs"] == 1 for p in points)
    rows = markdown_table(points).splitlines()
    assert any(row.startswith("| 64 (polydisperse 0.1) |") for row in rows)
    assert any(row.startswith("| 64 |") for row in rows)


def test_elastic_unloading_is_stored_named_and_never_resumes_a_run_without_it(tmp_path):
    """Elastic unloading is another scheme: its runs carry it in their params and name, and a file run
    without it (which stores nothing for it) is refused rather than continued with it."""
    params = SimParams(**{**TINY, "elastic_unloading": True})
    assert run_name(params) == "N64_phi0.74_s5_seed1_d0.002_implicit_unloading"
    with_it, without = tmp_path / "with.h5", tmp_path / "without.h5"
    run_state_point(params, with_it, progress=False, solver="qdldl")
    assert read_params(with_it)["elastic_unloading"] is True
    assert params_from_mapping(read_params(with_it)) == params
    run_state_point(SimParams(**TINY), without, progress=False, solver="qdldl")
    assert "elastic_unloading" not in read_params(without)
    with pytest.raises(InputError, match=r"belongs to another state point \(.*elastic_unloading"):
        extended = SimParams(**{**TINY, "strain": 0.06, "elastic_unloading": True})
        run_state_point(extended, without, progress=False)
