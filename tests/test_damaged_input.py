"""Damaged files and degenerate configurations: each is one line naming the file (and the snapshot or pair)
and what is wrong — as ``InputError`` from Python, as ``<program>: error: …`` from the entry points — or,
where a prediction can still be made, a flagged row of finite numbers."""

import gzip
import io
import json
import logging
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import h5py
import numpy as np
import pytest

from rheograph.errors import InputError
from rheograph.io.configurations import Snapshots
from rheograph.io.snapshots import read_snapshots, write_bare

ROOT = Path(__file__).resolve().parents[1]
LFDEM = ROOT / "tests" / "data" / "lfdem_run_small"
PAR = LFDEM / "par_conf_params_stress10cl_shear.dat"
MODEL = ROOT / "src" / "rheograph" / "models" / "N400_phi0.76"
RUN_N400 = ROOT / "data" / "lfdem_phi0.76_n400" / "s10" / "par_conf_params_stress10cl_shear.dat.gz"
PHYSICAL = dict(mu=0.5, kn_coefficient=2e4, kt_ratio=0.5, delta=1e-3, lub_max_gap=0.5)


def one_line_error(args, cwd) -> str:
    """The error line of an entry point that must fail with one line (and no traceback)."""
    done = subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=cwd, timeout=300)
    output = done.stdout + done.stderr
    assert done.returncode != 0 and "Traceback" not in output, output[-3000:]
    errors = [line for line in output.splitlines() if "error:" in line]
    assert len(errors) == 1, output[-3000:]
    return errors[0]


@pytest.fixture(scope="module")
def bare_file(tmp_path_factory) -> Path:
    """A valid bare snapshot file: two configurations of the small LF_DEM fixture run (N = 100)."""
    snaps = read_snapshots(PAR)
    path = tmp_path_factory.mktemp("bare") / "s.npz"
    write_bare(path, snaps)
    return path


def lfdem_copy(tmp_path: Path, text: bytes, gz: bool = False) -> Path:
    shutil.copy(LFDEM / "input_conf_params_stress10cl_shear.dat", tmp_path)
    path = tmp_path / (PAR.name + (".gz" if gz else ""))
    path.write_bytes(gzip.compress(text, mtime=0) if gz else text)
    return path


# ---- bare snapshot files ---------------------------------------------------------------------------
def _corrupt_compressed(path: Path) -> bytes:
    """A compressed copy of a bare file whose positions' deflate stream starts with a block of the
    reserved type: the zip directory is whole, decompressing fails (zlib.error)."""
    with np.load(path) as data:
        values = {key: data[key] for key in data.files}
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **values)
    raw = bytearray(buffer.getvalue())
    with zipfile.ZipFile(io.BytesIO(bytes(raw))) as archive:
        info = archive.getinfo("positions.npy")
    # the data follow the 30-byte local header, its file name and its extra field (lengths at 26, 28)
    name_length, extra_length = np.frombuffer(raw, "<u2", 2, info.header_offset + 26)
    start = info.header_offset + 30 + int(name_length) + int(extra_length)
    raw[start] = 0b111  # final block, type 3 (reserved)
    return bytes(raw)


@pytest.mark.parametrize("damage", ["empty", "cut", "bit flipped", "corrupt deflate stream"])
def test_an_empty_cut_or_corrupt_npz_is_one_line_naming_the_file(bare_file, tmp_path, damage):
    data = bare_file.read_bytes()
    damaged = {
        "empty": b"",
        "cut": data[: len(data) // 2],
        "bit flipped": data[:200] + bytes([data[200] ^ 0x10]) + data[201:],  # inside positions: CRC fails
        "corrupt deflate stream": _corrupt_compressed(bare_file) if damage.startswith("corrupt") else b"",
    }[damage]
    path = tmp_path / "damaged.npz"
    path.write_bytes(damaged)
    with pytest.raises(InputError, match="damaged.npz: cannot be read as a bare snapshot file") as err:
        read_snapshots(path)
    assert "\n" not in str(err.value)


def test_predict_and_train_on_an_empty_npz_end_with_one_line(tmp_path):
    empty = tmp_path / "data" / "empty.npz"
    empty.parent.mkdir()
    empty.touch()
    line = one_line_error(
        [str(ROOT / "predict.py"), "--models", "N400_phi0.76", "--input", str(empty), "--out", "p.csv"],
        tmp_path,
    )
    assert line.startswith("predict.py: error: ") and "empty.npz: cannot be read" in line
    line = one_line_error(
        [
            str(ROOT / "train.py"),
            f"data.files={empty.parent}/*.npz",
            "data.phi=null",
            "data.n_particles=null",
            f"data.cache_dir={tmp_path / 'cache'}",
            f"output_root={tmp_path}",
            "~logger",
        ],
        tmp_path,
    )
    assert line.startswith("train.py: error: ") and "empty.npz: cannot be read" in line


def test_complex_values_in_a_bare_file_are_refused_not_cut_to_their_real_part(bare_file, tmp_path):
    with np.load(bare_file) as data:
        values = {key: data[key] for key in data.files}
    values["positions"] = values["positions"] + 0j
    np.savez(tmp_path / "c.npz", **values)
    with pytest.raises(InputError, match="'positions' must be real numbers"):
        read_snapshots(tmp_path / "c.npz")


# ---- LF_DEM runs -----------------------------------------------------------------------------------
def test_an_lfdem_run_cut_in_its_last_row_reads_every_complete_configuration(tmp_path, caplog):
    """Cut anywhere in the last particle row — between numbers, inside one, right after the first
    column — the run keeps its six complete configurations and leaves out the seventh with a warning
    naming the file; a cut inside a number never becomes a position."""
    text = PAR.read_bytes()
    full = read_snapshots(PAR)
    last_row = text.rstrip(b"\n").rsplit(b"\n", 1)[1]
    start = len(text) - len(last_row) - 1
    for cut in range(start + 1, len(text) - 1, 9):
        path = lfdem_copy(tmp_path, text[:cut])
        with caplog.at_level(logging.WARNING, logger="rheograph.io.lfdem"):
            caplog.clear()
            snaps = read_snapshots(path)
        assert len(snaps) == 6, cut
        np.testing.assert_array_equal(snaps.positions, full.positions[:6])
        assert any(PAR.name in r.getMessage() and "left out" in r.getMessage() for r in caplog.records)
    # a row lost in the middle of the file is damage, not an unfinished end: refused by name
    lines = text.decode().splitlines(keepends=True)
    del lines[len(lines) // 2]
    with pytest.raises(
        InputError, match=rf"{PAR.name}: the configuration at strain \S+ has 99 particle rows"
    ):
        read_snapshots(lfdem_copy(tmp_path, "".join(lines).encode()))


def test_an_lfdem_run_with_a_position_that_is_no_number_is_refused_by_name(tmp_path):
    lines = PAR.read_text().splitlines(keepends=True)
    row = next(k for k, line in enumerate(lines) if line.startswith("5 "))
    words = lines[row].split()
    words[2] = "nan"  # Python reads it as a number
    lines[row] = " ".join(words) + "\n"
    with pytest.raises(InputError, match=rf"{PAR.name}: positions .* not finite numbers"):
        read_snapshots(lfdem_copy(tmp_path, "".join(lines).encode()))


def test_a_cut_gzip_lfdem_run_reads_its_complete_configurations_and_a_corrupt_one_is_one_line(
    tmp_path, caplog
):
    compressed = gzip.compress(PAR.read_bytes(), mtime=0)
    path = lfdem_copy(tmp_path, PAR.read_bytes(), gz=True)
    path.write_bytes(compressed[: len(compressed) // 2])
    with caplog.at_level(logging.WARNING, logger="rheograph.io.lfdem"):
        snaps = read_snapshots(path)
    assert any(f"{PAR.name}.gz: the gzip file is cut short" in r.getMessage() for r in caplog.records)
    assert 0 < len(snaps) < 7
    np.testing.assert_array_equal(snaps.positions, read_snapshots(PAR).positions[: len(snaps)])
    corrupt = bytearray(compressed)
    corrupt[len(corrupt) // 2] ^= 0xFF
    path.write_bytes(bytes(corrupt))
    with pytest.raises(InputError, match=rf"{PAR.name}.gz: "):
        read_snapshots(path)


# ---- trajectories ----------------------------------------------------------------------------------
def write_trajectory(path: Path, snaps: Snapshots, params) -> None:
    with h5py.File(path, "w") as h5:
        h5.attrs["params"] = params
        h5.attrs["lx"], h5.attrs["ly"] = snaps.lx, snaps.ly
        h5["radii"] = snaps.radii
        h5["snapshots/positions"] = snaps.positions
        h5["snapshots/le_offset"] = snaps.le_offset


@pytest.mark.parametrize(
    "change, message",
    [
        ("params=[1, 2]", "its root attribute 'params' is not a JSON object"),
        ("params={'mu': null}", "params: 'mu' = nan is not finite"),
        ("complex radii", "'radii' must be real numbers"),
        ("nan positions", "positions contain non-finite values"),
    ],
)
def test_a_trajectory_with_damaged_contents_is_one_line(tmp_path, change, message):
    snaps = read_snapshots(PAR)
    good = {"phi": snaps.phi, "stress": snaps.stress, **snaps.params}
    params = {"params=[1, 2]": "[1, 2]", "params={'mu': null}": json.dumps({**good, "mu": None})}
    path = tmp_path / "t.h5"
    write_trajectory(path, snaps, params.get(change, json.dumps(good)))
    with h5py.File(path, "r+") as h5:
        if change == "complex radii":
            radii = h5["radii"][()]
            del h5["radii"]
            h5["radii"] = radii + 0j
        elif change == "nan positions":
            h5["snapshots/positions"][0, 0, 0] = np.nan
    with pytest.raises(InputError, match=f"t.h5: .*{message}"):
        read_snapshots(path)


def test_train_on_a_trajectory_whose_params_are_not_json_ends_with_one_line(tiny_files, tmp_path):
    (tmp_path / "data").mkdir()
    shutil.copy(tiny_files[0], tmp_path / "data" / "t.h5")
    with h5py.File(tmp_path / "data" / "t.h5", "r+") as h5:
        h5.attrs["params"] = "not JSON {"
    line = one_line_error(
        [
            str(ROOT / "train.py"),
            f"data.files={tmp_path / 'data'}/*.h5",
            "data.phi=null",
            "data.n_particles=null",
            f"data.cache_dir={tmp_path / 'cache'}",
            f"output_root={tmp_path}",
            "~logger",
        ],
        tmp_path,
    )
    assert line.startswith("train.py: error: ") and "t.h5: cannot be read" in line


def test_flowcurve_names_a_trajectory_whose_time_series_is_damaged(tiny_files, tmp_path):
    from rheograph.analysis.flow_curves import state_points

    shutil.copy(tiny_files[0], tmp_path / "a.h5")
    with h5py.File(tmp_path / "a.h5", "r+") as h5:
        del h5["timeseries/strain"]
    with pytest.raises(InputError, match="a.h5: cannot be read as a rheograph trajectory"):
        state_points([tmp_path])


# ---- model folders -----------------------------------------------------------------------------------
ONE_POINT = {"phi": [0.76], "stress": [1.0]}
NEGATIVE_RMS = {"eta": [-0.1], "pressure": [0.1], "z_mu": [0.1]}


@pytest.mark.parametrize(
    "name, content, message",
    [
        ("card.json", "{not json", "not a readable model card"),
        ("card.json", json.dumps({"domain": {"phi": "0.76"}}), "not a model card"),
        ("error_model.json", "", "not a readable error model"),
        ("error_model.json", json.dumps({**ONE_POINT, "rms": {}}), r"not an error model \(rms must hold"),
        ("error_model.json", json.dumps({**ONE_POINT, "rms": NEGATIVE_RMS}), r"not an error .*>= 0"),
        ("error_model.json", json.dumps({"phi": [0.76], "stress": [0], "rms": {}}), r"not an error .*> 0"),
    ],
)
def test_a_damaged_card_or_error_model_is_one_line_naming_it(tmp_path, name, content, message):
    import rheograph

    folder = tmp_path / "model"
    folder.mkdir()
    for f in ("fold0.pt", "card.json", "error_model.json"):
        shutil.copy(MODEL / f, folder)
    (folder / name).write_text(content)
    with pytest.raises(InputError, match=f"{name}: {message}"):
        rheograph.load_model(folder)


# ---- degenerate configurations ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def model_and_snapshot():
    import rheograph

    snaps = read_snapshots(RUN_N400)
    return rheograph.load_model("N400_phi0.76"), snaps, len(snaps) - 1


def predict(model_and_snapshot, positions):
    model, snaps, k = model_and_snapshot
    return model.predict(
        positions, snaps.radii, (snaps.lx, snaps.ly), snaps.le_offset[k], stress=snaps.stress, phi=snaps.phi,
        **PHYSICAL,
    )  # fmt: skip


@pytest.mark.parametrize("separation", [0.0, 1e-9, 0.5, 0.999])
def test_particles_one_inside_another_are_refused_naming_the_pair(model_and_snapshot, separation):
    """Two particles at one position made the one-solve divide by zero; nearly so, it predicted from
    nonsense.  A centre within another particle (distance <= the larger radius, here 1) is refused."""
    _, snaps, k = model_and_snapshot
    positions = snaps.positions[k].copy()
    positions[7] = positions[3] + [separation, 0.0]
    with pytest.raises(
        InputError, match=r"model.predict, snapshot 0: particles 3 and 7 .* one centre within"
    ):
        predict(model_and_snapshot, positions)


def test_positions_in_other_units_are_flagged_with_finite_output_and_no_solve_viscosity(model_and_snapshot):
    """Positions scaled by 0.9 (a units slip the area fraction check does not see: the radii and box
    are unchanged) overlap by up to 0.28 a: flagged, every prediction and spread finite, and the one-solve,
    whose shear rate runs against the stress there, reports no viscosity instead of a negative one."""
    _, snaps, k = model_and_snapshot
    table = predict(model_and_snapshot, snaps.positions[k] * 0.9)
    assert table["in_domain"][0] == 0
    for name in ("eta", "pressure", "z_mu"):
        assert np.isfinite(table[f"{name}_pred"]).all() and np.isfinite(table[f"{name}_pred_std"]).all()
    assert (
        np.isnan(table["eta_solve"][0])
        and "the one-solve gives no viscosity" in table["notes"][0]
        and "this snapshot: eta_r = " in table["notes"][0]
    )


def test_a_reason_with_a_value_per_snapshot_is_warned_once(model_and_snapshot, capsys):
    """Snapshots whose one-solve gives no viscosity each keep their value in their note; the warning
    names the reason once, with how many snapshots it concerns, not once per value."""
    model, snaps, k = model_and_snapshot
    table = model.predict(
        np.stack([snaps.positions[k] * 0.9, snaps.positions[k - 1] * 0.9]), snaps.radii,
        (snaps.lx, snaps.ly), snaps.le_offset[[k, k - 1]], stress=snaps.stress, phi=snaps.phi, **PHYSICAL,
    )  # fmt: skip
    warning = capsys.readouterr().err
    assert np.isnan(table["eta_solve"]).all()
    assert len({note.split("this snapshot: ")[1] for note in table["notes"]}) == 2  # two values
    assert warning.count("the one-solve gives no viscosity") == 1 and "this snapshot" not in warning
    assert "edge features ['contact_normal'" in warning  # other reasons whole
    assert np.isfinite(table["pressure_spring"]).all() and np.isfinite(table["z_mu_counted"]).all()


def test_ensemble_spread_of_huge_predictions_stays_finite():
    from rheograph.learn.predict import ensemble_mean_std

    values = np.array([[1e200, 1.0], [3e200, 3.0]])
    mean, std = ensemble_mean_std(values)
    np.testing.assert_allclose(mean, [2e200, 2.0])
    np.testing.assert_allclose(std, [1e200, 1.0])


def test_a_prediction_that_is_no_finite_number_is_refused_naming_the_snapshot(
    model_and_snapshot, monkeypatch
):
    """Inputs far enough outside a model's training can make its output overflow (a float32 network read
    out through sinh): never written, refused with the snapshot and why its inputs lie outside."""
    import rheograph.learn.predict as predict_module

    real = predict_module.predict_dataset

    def overflowing(module, graphs, batch_size, device=None):
        pred, true, meta = real(module, graphs, batch_size, device=device)
        pred[0, 0] = np.inf
        return pred, true, meta

    monkeypatch.setattr(predict_module, "predict_dataset", overflowing)
    _, snaps, k = model_and_snapshot
    with pytest.raises(
        InputError, match=r"snapshot\(s\) \[0\] is not a finite number.*\(snapshot 0: edge features"
    ):
        predict(model_and_snapshot, snaps.positions[k] * 0.9)
