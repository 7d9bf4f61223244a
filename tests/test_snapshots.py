"""Snapshots from anywhere: bare files, LF_DEM runs, rheograph trajectories (finished, running, stripped),
the Python API, shipped models, and one line for every bad input."""

import gzip
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from rheograph.errors import InputError
from rheograph.io.snapshots import read_snapshots, write_bare

ROOT = Path(__file__).resolve().parents[1]
LFDEM = ROOT / "tests" / "data" / "lfdem_run_small"
PAR = LFDEM / "par_conf_params_stress10cl_shear.dat"
PHYSICAL = dict(mu=0.5, kn_coefficient=2e4, kt_ratio=0.5, delta=1e-3, lub_max_gap=0.5)


@pytest.fixture(scope="module")
def model():
    import rheograph

    return rheograph.load_model("N400_phi0.76")


def _bare_values(path):
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


# ---- readers ---------------------------------------------------------------------------------------
def test_bare_file_round_trips_a_trajectory(tiny_files, tmp_path):
    snaps = read_snapshots(tiny_files[1])
    write_bare(tmp_path / "s.npz", snaps)
    bare = read_snapshots(tmp_path / "s.npz")
    assert bare.kind == "bare" and len(bare) == len(snaps)
    np.testing.assert_array_equal(bare.positions, snaps.positions)
    np.testing.assert_array_equal(bare.targets, snaps.targets)
    assert bare.params == snaps.params and bare.stress == snaps.stress
    # the same keys in HDF5 read the same
    with h5py.File(tmp_path / "s.h5", "w") as h5:
        for key, value in _bare_values(tmp_path / "s.npz").items():
            if np.ndim(value):
                h5[key] = value
            else:
                h5.attrs[key] = value
    from_h5 = read_snapshots(tmp_path / "s.h5")
    np.testing.assert_array_equal(from_h5.positions, snaps.positions)


def test_bare_positions_anywhere_are_wrapped_with_the_lees_edwards_images(tiny_files, tmp_path):
    """A periodic image of a particle (one box up: x shifted by the offset) is the same configuration."""
    from rheograph.graphs.features import snapshot_pairs

    snaps = read_snapshots(tiny_files[2])
    values = {
        "positions": snaps.positions[-1].copy(),
        "radii": snaps.radii,
        "box": [snaps.lx, snaps.ly],
        "le_offset": snaps.le_offset[-1],
        "stress": snaps.stress,
        "phi": snaps.phi,
        **PHYSICAL,
    }
    values["positions"][::3] += [snaps.le_offset[-1], snaps.ly]  # image above
    values["positions"][1::3] += [3 * snaps.lx, 0.0]
    np.savez(tmp_path / "moved.npz", **values)
    moved = read_snapshots(tmp_path / "moved.npz")
    p = snaps.graph_params()
    a = snapshot_pairs(snaps.positions[-1], snaps.radii, snaps.lx, snaps.ly, snaps.le_offset[-1], 0.5, p)
    b = snapshot_pairs(moved.positions[0], moved.radii, moved.lx, moved.ly, moved.le_offset[0], 0.5, p)
    order_a, order_b = np.lexsort((a["j"], a["i"])), np.lexsort((b["j"], b["i"]))
    np.testing.assert_array_equal(a["i"][order_a], b["i"][order_b])
    np.testing.assert_allclose(a["xi"][order_a], b["xi"][order_b], atol=1e-9)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda v: v.pop("mu"), r"missing key\(s\) \['mu'\]"),
        (lambda v: v.pop("box"), r"missing key\(s\) \['box'\]"),
        (lambda v: v.update(phi=0.7), "area fraction"),
        (lambda v: v.update(radii=v["radii"] * 2), "units of the small radius"),
        (lambda v: v.update(positions=v["positions"][:, :10]), "positions must be"),
        (lambda v: v.update(stress=-1.0), "stress"),
        (lambda v: v.update(eta_r=np.ones(3)), "'eta_r' needs one value per snapshot"),
        (lambda v: v.update(critical_load=2.0), "critical_load"),
    ],
)
def test_bare_file_errors_name_the_key(tiny_files, tmp_path, change, message):
    write_bare(tmp_path / "s.npz", read_snapshots(tiny_files[0]))
    values = _bare_values(tmp_path / "s.npz")
    change(values)
    np.savez(tmp_path / "bad.npz", **values)
    with pytest.raises(InputError, match=message):
        read_snapshots(tmp_path / "bad.npz")


def test_foreign_and_missing_files_are_refused_by_name(tmp_path):
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(InputError, match="not a snapshot source"):
        read_snapshots(tmp_path / "notes.txt")
    (tmp_path / "fake.npz").write_text("not a zip")
    with pytest.raises(InputError, match="not a readable .npz"):
        read_snapshots(tmp_path / "fake.npz")
    with h5py.File(tmp_path / "other.h5", "w") as h5:
        h5["data"] = np.zeros(3)
    with pytest.raises(InputError, match="missing key"):
        read_snapshots(tmp_path / "other.h5")
    with pytest.raises(InputError, match="no such file"):
        read_snapshots(tmp_path / "absent.h5")


def test_trajectory_without_time_series_or_parameters(tiny_files, tmp_path):
    stripped = tmp_path / "stripped.h5"
    shutil.copy(tiny_files[1], stripped)
    with h5py.File(stripped, "r+") as h5:
        del h5["timeseries"]
        params = json.loads(h5.attrs["params"])
        del params["kn_coefficient"]
        h5.attrs["params"] = json.dumps(params)
    snaps = read_snapshots(stripped)
    assert len(snaps) == len(read_snapshots(tiny_files[1])) and not snaps.jammed.any()
    assert "kn_coefficient" in snaps.missing_params()


def test_running_trajectory_is_read_from_its_last_checkpoint_copy(tiny_files, tmp_path):
    """A simulation holds its file (HDF5 lock): the reader takes the copy as of the last checkpoint."""
    from rheograph.io.hdf5 import last_checkpoint_copy

    running = tmp_path / "trajectory.h5"
    shutil.copy(tiny_files[1], running)
    shutil.copy(tiny_files[1], last_checkpoint_copy(running))
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"import h5py, time; f = h5py.File({str(running)!r}, 'r+'); print(1, flush=True); time.sleep(60)",
        ],
        stdout=subprocess.PIPE,
    )
    try:
        holder.stdout.readline()
        with pytest.raises(OSError):
            h5py.File(running, "r")  # locked: the test is meaningful
        snaps = read_snapshots(running)
    finally:
        holder.kill()
    assert len(snaps) == len(read_snapshots(tiny_files[1]))


# ---- LF_DEM -------------------------------------------------------------------------------------------
def test_lfdem_run_is_read_in_rheograph_conventions(tmp_path):
    from rheograph.graphs.features import snapshot_pairs
    from rheograph.io.lfdem import _data_table

    snaps = read_snapshots(PAR)
    assert snaps.kind == "lfdem" and len(snaps) == 7 and snaps.n_particles == 100
    assert snaps.stress == 10.0 and snaps.phi == pytest.approx(0.76, abs=1e-6)
    # parameters from the copy LF_DEM keeps in input_*.dat; kn checked against the data file's column
    assert snaps.params == {**PHYSICAL, "critical_load": 1.0, "size_ratio": 1.4}
    assert snaps.numerics == {"disp_max": 1e-3}
    np.testing.assert_allclose(snaps.strain, np.arange(7) * 0.05, atol=1e-12)
    # the shear displacement is the Lees-Edwards offset gamma * Ly (wrapped)
    np.testing.assert_allclose(
        snaps.le_offset,
        snaps.strain * snaps.ly - snaps.lx * np.round(snaps.strain * snaps.ly / snaps.lx),
        atol=1e-4,
    )
    columns, table = _data_table(LFDEM / "data_conf_params_stress10cl_shear.dat")
    rows = [int(np.argmin(np.abs(table[:, 1] - g))) for g in snaps.strain]
    # eta_r = sigma / shear rate of the configuration: LF_DEM's own viscosity column, both from 6-digit
    # numbers (rounding up to 5e-6 each)
    np.testing.assert_allclose(snaps.targets[:, 0], table[rows, columns["viscosity"]], rtol=1e-5)
    np.testing.assert_allclose(snaps.targets[:, 1], table[rows, columns["particle pressure"]], rtol=1e-12)
    # Z_mu counted from int_*.dat's contact states equals LF_DEM's frictional contact number
    np.testing.assert_allclose(
        snaps.targets[:, 2], table[rows, columns["frictional contact number"]], atol=1e-9
    )
    for k in range(len(snaps)):
        pairs = snapshot_pairs(
            snaps.positions[k], snaps.radii, snaps.lx, snaps.ly, snaps.le_offset[k], 0.5, snaps.graph_params()
        )
        # a wrong Lees-Edwards sign or box would put O(1) overlaps across the boundary; 6-digit
        # positions move a contact count by a few
        assert pairs["xi"].min() > -0.005
        contacts = 2 * (pairs["xi"] < 0).sum() / snaps.n_particles
        assert contacts == pytest.approx(table[rows[k], columns["contact number"]], abs=0.05)
    assert 0 < snaps.position_noise < 3e-5


def test_lfdem_gzip_and_explicit_parameter_file_read_alike(tmp_path):
    for f in LFDEM.glob("*_conf_params_stress10cl_shear.dat"):
        if f.name.startswith(("par_", "int_")):
            with gzip.open(tmp_path / (f.name + ".gz"), "wt") as out:
                out.write(f.read_text())
        elif not f.name.startswith("input_"):
            shutil.copy(f, tmp_path / f.name)
    par = tmp_path / (PAR.name + ".gz")
    with pytest.raises(InputError, match="LF_DEM's parameters are needed"):
        read_snapshots(par)  # no input_*.dat beside and no parameter file
    snaps = read_snapshots(par, LFDEM / "params.txt")
    np.testing.assert_array_equal(snaps.positions, read_snapshots(PAR).positions)
    np.testing.assert_array_equal(snaps.targets, read_snapshots(PAR).targets)
    other = tmp_path / "params.txt"
    other.write_text((LFDEM / "params.txt").read_text().replace("friction_model = 2", "friction_model = 5"))
    with pytest.raises(InputError, match="friction_model = 5"):
        read_snapshots(par, other)
    other.write_text((LFDEM / "params.txt").read_text().replace("kn = 20000s", "kn = 30000s"))
    with pytest.raises(InputError, match="is this the parameter file of this run"):
        read_snapshots(par, other)


def test_lfdem_par_file_still_being_written_drops_its_partial_block(tmp_path):
    lines = PAR.read_text().splitlines()
    (tmp_path / PAR.name).write_text("\n".join(lines[: len(lines) - 30]) + "\n")
    shutil.copy(LFDEM / "input_conf_params_stress10cl_shear.dat", tmp_path)
    assert len(read_snapshots(tmp_path / PAR.name)) == 6


def test_graph_dataset_and_suspension_record_take_lfdem_runs(tmp_path):
    from rheograph.graphs.dataset import GraphSettings, SnapshotGraphDataset
    from rheograph.graphs.features import PHYSICS_EDGE_FEATURES
    from rheograph.learn.datamodule import suspension_record

    settings = GraphSettings(edge_features=PHYSICS_EDGE_FEATURES, min_strain=0.05)
    dataset = SnapshotGraphDataset([PAR], settings, tmp_path / "cache")
    snaps = read_snapshots(PAR)
    assert len(dataset) == 6  # strain >= 0.05
    np.testing.assert_allclose(dataset.y_raw.numpy(), snaps.targets[1:])
    record = suspension_record([str(PAR)])
    assert record["physical_params"]["kn_coefficient"] == 2e4
    assert record["solve_numerics"] == [
        {"phi": 0.76, "n_particles": 100, "disp_max": 1e-3, "dt_max": 1.0, "lagged_step_control": False}
    ]


# ---- models and the Python API --------------------------------------------------------------------
def test_shipped_models_are_listed_with_cards():
    import rheograph

    names = rheograph.list_models()
    for name in ("N400_phi0.76", "N2000_phi0.80", "pooled_N400"):
        assert name in names
    from rheograph.learn.registry import MODELS_DIR

    card = json.loads((MODELS_DIR / "N400_phi0.76" / "card.json").read_text())
    assert card["physical_params"]["mu"] == 0.5 and card["solve_numerics"][0]["disp_max"] == 2e-3
    assert "graph network" in [row["model"] for row in card["held_out_r2"]]


def test_prediction_of_a_trajectory_equals_that_of_its_bare_copy(model, tiny_files, tmp_path):
    snaps = read_snapshots(tiny_files[2])
    write_bare(tmp_path / "s.npz", snaps)
    a = model.predict_snapshots(snaps)
    b = model.predict_snapshots(read_snapshots(tmp_path / "s.npz"))
    for column in ("eta_pred", "pressure_pred", "z_mu_pred", "eta_sim", "in_domain"):
        np.testing.assert_array_equal(a[column], b[column])
    # the tiny runs have N = 64 and phi = 0.72: predicted, and flagged with the reason
    assert not a["in_domain"].any() and "N = 64" in a["notes"][0] and "phi = 0.72" in a["notes"][0]


def test_snapshot_without_targets_and_parameter_checks(model, tiny_files, tmp_path):
    snaps = read_snapshots(tiny_files[2])
    bare = {
        "positions": snaps.positions,
        "radii": snaps.radii,
        "box": [snaps.lx, snaps.ly],
        "le_offset": snaps.le_offset,
        "stress": snaps.stress,
        "phi": snaps.phi,
    }
    table = model.predict(**bare, **PHYSICAL)
    assert np.isnan(table["eta_sim"]).all() and np.isfinite(table["eta_pred"]).all()
    assert len(table["eta_pred"]) == len(snaps)
    with pytest.raises(InputError, match=r"\['kt_ratio'\] are not given.*kt_ratio=0.5"):
        model.predict_snapshots(read_snapshots_without(tmp_path, snaps, "kt_ratio"))
    with pytest.raises(InputError, match=r"mu = 1 \(model: 0.5\)"):
        model.predict(**bare, **{**PHYSICAL, "mu": 1.0})
    accepted = model.predict(**bare, **{**PHYSICAL, "mu": 1.0}, accept_mismatch=True)
    assert not accepted["in_domain"].any() and "accepted parameter mismatch: mu = 1" in accepted["notes"][0]
    with pytest.raises(InputError, match="unknown keyword"):
        model.predict(**bare, **PHYSICAL, colour=1)


def read_snapshots_without(tmp_path, snaps, key):
    """A trajectory-layout file of ``snaps`` whose params lack ``key``."""
    path = tmp_path / f"without_{key}.h5"
    with h5py.File(path, "w") as h5:
        params = {**snaps.params, "stress": snaps.stress, "phi": snaps.phi}
        del params[key]
        h5.attrs["params"] = json.dumps(params)
        h5.attrs["lx"], h5.attrs["ly"] = snaps.lx, snaps.ly
        h5["radii"] = snaps.radii
        h5["snapshots/positions"] = snaps.positions
        h5["snapshots/le_offset"] = snaps.le_offset
    return read_snapshots(path)


def test_readme_python_example_runs(monkeypatch):
    """The README's Python example, as written (between its python-example markers), from the root."""
    monkeypatch.chdir(ROOT)
    text = (ROOT / "README.md").read_text()
    match = re.search(r"<!-- python-example -->\s*```python\n(.*?)```", text, flags=re.S)
    assert match, "README lost its python-example block"
    namespace = {}
    exec(compile(match.group(1), "README.md", "exec"), namespace)
    table = namespace["table"]
    assert np.isfinite(table["eta_pred"]).all() and len(table["eta_pred"]) >= 1


def test_predict_cli_reads_all_kinds_and_names_bad_input(tiny_files, tmp_path):
    write_bare(tmp_path / "s.npz", read_snapshots(tiny_files[0]))
    out = tmp_path / "p.csv"
    cmd = [sys.executable, str(ROOT / "predict.py"), "--models", "N400_phi0.76", "--out", str(out), "--input"]
    done = subprocess.run(
        [*cmd, tiny_files[0], str(tmp_path / "s.npz"), str(PAR)], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    lines = [line for line in out.read_text().splitlines() if not line.startswith("#")]
    header = lines[0].split(",")
    for column in (
        "strain",
        "stress",
        "phi",
        "in_domain",
        "eta_pred",
        "pressure_pred",
        "z_mu_pred",
        "eta_pred_std",
        "eta_pred_err",
        "eta_sim",
    ):
        assert column in header
    n = len(read_snapshots(tiny_files[0]))
    assert len(lines) - 1 == 2 * n + 7
    # bad input names itself (in process: the one-line exit of predict.py is tests/test_faults.py's)
    import h5py

    from rheograph.learn.predict import main

    # HDF5 output, with a source path that is not ASCII
    odd = tmp_path / "φ0.72 snapshot.npz"
    shutil.copy(tmp_path / "s.npz", odd)
    main(["--models", "N400_phi0.76", "--out", str(tmp_path / "p.h5"), "--input", str(odd)])
    with h5py.File(tmp_path / "p.h5") as h5:
        assert h5["source"].asstr()[0] == str(odd) and h5["eta_pred"].shape == (n,)
        assert h5.attrs["model"] == "N400_phi0.76"

    (tmp_path / "notes.txt").write_text("x")
    for argv, message in (
        ([str(tmp_path / "notes.txt")], "not a snapshot source"),
        ([str(PAR), "--param", "colour=1"], "--param colour=1: expected KEY=VALUE"),
        ([str(PAR), "--param", "mu=1"], r"mu = 1 \(model: 0.5\)"),
    ):
        with pytest.raises(InputError, match=message):
            main(["--models", "N400_phi0.76", "--out", str(tmp_path / "x.csv"), "--input", *argv])
    with pytest.raises(InputError, match="neither a shipped model"):
        main(["--models", "nonesuch", "--out", str(tmp_path / "x.csv"), "--input", str(PAR)])
    assert not (tmp_path / "x.csv").exists()

    # a bare file without one physical parameter: refused, pointing to --param; given that way, the
    # predictions are those of the complete file
    with np.load(tmp_path / "s.npz") as data:
        np.savez(tmp_path / "no_kn.npz", **{k: data[k] for k in data.files if k != "kn_coefficient"})
    with pytest.raises(InputError, match=r"missing key\(s\) \['kn_coefficient'\].*--param KEY=VALUE"):
        main(
            [
                "--models",
                "N400_phi0.76",
                "--out",
                str(tmp_path / "x.csv"),
                "--input",
                str(tmp_path / "no_kn.npz"),
            ]
        )
    kn = float(np.load(tmp_path / "s.npz")["kn_coefficient"])
    for name, extra in (("full", []), ("given", ["--param", f"kn_coefficient={kn!r}"])):
        source = tmp_path / ("s.npz" if name == "full" else "no_kn.npz")
        main(
            [
                "--models",
                "N400_phi0.76",
                "--out",
                str(tmp_path / f"{name}.h5"),
                "--input",
                str(source),
                *extra,
            ]
        )
    with h5py.File(tmp_path / "full.h5") as full, h5py.File(tmp_path / "given.h5") as given:
        np.testing.assert_array_equal(full["eta_pred"][()], given["eta_pred"][()])


def test_train_py_trains_on_lfdem_runs(tmp_path):
    """data.files takes LF_DEM par files: a model of LF_DEM's own output, whose bundle records the
    suspension read from LF_DEM's parameters."""
    import torch

    for k in (1, 2):  # two copies of the fixture run: two trajectories for a 3-fold random split
        (tmp_path / f"r{k}").mkdir()
        for f in LFDEM.glob("*_conf_params_stress10cl_shear.dat"):
            shutil.copy(f, tmp_path / f"r{k}" / f.name)
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "train.py"),
            f"data.files={tmp_path}/r*/par_*.dat",
            f"data.cache_dir={tmp_path / 'cache'}",
            "data.phi=null",
            "data.n_particles=null",
            "data.num_folds=3",
            "data.split=random",
            "graph.min_strain=0.05",
            "trainer.max_epochs=2",
            "~logger",
            "fold=0",
            "trainer.enable_progress_bar=false",
            f"hydra.run.dir={tmp_path / 'run'}",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "run" / "report.md").exists()
    bundle = torch.load(tmp_path / "run" / "fold0.pt", weights_only=True)
    assert bundle["domain"]["physical_params"]["kn_coefficient"] == 2e4
    assert bundle["domain"]["solve_numerics"][0]["disp_max"] == 1e-3


def test_spring_pressure_row_is_the_simulators_contact_spring_virial():
    """The physics-only Π, (2π σ / A) Σ r ā δ / δ_σ from positions, is the trace of the simulator's own
    contact-spring stress (rheograph.sim.stress.spring_stress) at that configuration: tangential springs
    carry no trace, so positions alone fix it."""
    from conftest import sheared_frictional_problem

    from rheograph.graphs.dataset import GraphSettings, snapshot_graphs
    from rheograph.io.snapshots import snapshots_from_values
    from rheograph.sim import contacts
    from rheograph.sim.stress import spring_stress

    sim, lp, _ = sheared_frictional_problem()
    s, p = sim.state, sim.params
    state = s.contact_state.copy()
    contacts.critical_load_update(
        s.radii, s.pair_i, s.pair_j, lp.nvec, lp.xi, s.stretch.copy(), state, p.kn, p.kt, p.mu, 1.0
    )
    virial = spring_stress(s.pair_i, lp.nvec, lp.r, lp.f_on_i, state, True)
    expected = -sim.stress_factor * (virial[0] + virial[2]) / 3.0
    snaps = snapshots_from_values(
        {
            "positions": s.positions, "radii": s.radii, "box": [s.lx, s.ly], "le_offset": s.le_offset,
            "stress": p.stress, "phi": p.phi, "disp_max": p.disp_max,
            **{k: getattr(p, k) for k in ("mu", "kn_coefficient", "kt_ratio", "delta", "lub_max_gap")},
        },
        "test",
    )  # fmt: skip
    (graph,) = snapshot_graphs(snaps, GraphSettings(), 0, training=False)
    assert expected > 0 and (state != contacts.NONE).sum() > 20
    assert graph.physics[0, 1].item() == pytest.approx(expected, rel=1e-10)


def test_declared_position_noise_is_out_of_domain_with_the_reason(model, tiny_files):
    snaps = read_snapshots(tiny_files[2])
    values = dict(
        positions=snaps.positions[-1:], radii=snaps.radii, box=[snaps.lx, snaps.ly],
        le_offset=snaps.le_offset[-1], stress=snaps.stress, phi=snaps.phi, **PHYSICAL,
    )  # fmt: skip
    exact = model.predict(**values)
    noisy = model.predict(**values, position_noise=0.01)
    assert "positions known to" not in exact["notes"][0]
    assert noisy["in_domain"][0] == 0 and "positions known to 0.01 a" in noisy["notes"][0]


def test_damaged_sources_and_a_bad_output_path_are_refused_by_name(tmp_path):
    from rheograph.learn.predict import main

    lines = PAR.read_text().splitlines()
    lines[30] = "7 1 not-a-number 0 1.0 0 0 0 0 0 0 0 0 0 0"
    (tmp_path / PAR.name).write_text("\n".join(lines) + "\n")
    shutil.copy(LFDEM / "input_conf_params_stress10cl_shear.dat", tmp_path)
    with pytest.raises(InputError, match="cannot be read as an LF_DEM run"):
        read_snapshots(tmp_path / PAR.name)
    truncated = tmp_path / "cut.h5"  # a trajectory cut short: its HDF5 metadata is gone
    with h5py.File(truncated, "w") as h5:
        h5.create_group("snapshots")
        h5["radii"] = np.ones(4)
    data = truncated.read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="cut.h5"):
        read_snapshots(truncated)
    with pytest.raises(InputError, match="--out .*existing directory"):
        main(["--models", "N400_phi0.76", "--out", str(tmp_path / "absent" / "p.csv"), "--input", str(PAR)])


def test_start_up_snapshots_are_flagged_outside_a_steady_state_model(tmp_path):
    """Snapshots before the strain the model's training snapshots start at (1: the start-up transient)
    are predicted and flagged; the steady ones of the same run are not."""
    from rheograph.learn.predict import main

    run = ROOT / "data/lfdem_phi0.76_n400/s10/par_conf_params_stress10cl_shear.dat.gz"  # strain 0-2
    main(["--models", "N400_phi0.76", "--out", str(tmp_path / "p.h5"), "--input", str(run)])
    with h5py.File(tmp_path / "p.h5") as h5:
        strain, in_domain = h5["strain"][()], h5["in_domain"][()]
        notes = h5["notes"].asstr()[()]
    early = strain < 1.0
    assert early.any() and (~early).any()
    assert not in_domain[early].any() and all("start-up transient" in n for n in notes[early])
    assert in_domain[~early].all() and not any(notes[~early])  # the note belongs to its rows only


def test_read_snapshots_refuses_an_unknown_parameter_given_beside_the_file():
    with pytest.raises(InputError, match=r"unknown physical parameter\(s\) \['colour'\]"):
        read_snapshots(PAR, params={"colour": 1.0})


def test_predict_cli_refuses_negative_noise_and_a_file_that_is_no_model(tmp_path):
    from rheograph.learn.predict import main

    out = ["--out", str(tmp_path / "x.csv"), "--input", str(PAR)]
    with pytest.raises(InputError, match=r"--position-noise -1: an RMS precision in units of a, >= 0"):
        main(["--models", "N400_phi0.76", "--position-noise", "-1", *out])
    (tmp_path / "fake.pt").write_text("not a bundle")
    with pytest.raises(
        InputError, match=r"not a readable rheograph model bundle \(.+\); a model is a shipped"
    ) as err:
        main(["--models", str(tmp_path / "fake.pt"), *out])
    assert "\n" not in str(err.value)
