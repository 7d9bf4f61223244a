"""Property tests: every reader of untrusted files — bare snapshot files (.npz), rheograph trajectories
(.h5), LF_DEM runs (par_*.dat, .dat.gz) and model folders (card.json, error_model.json, fold*.pt) — given
a truncated, bit-flipped or wrong-typed copy of a small valid file either returns valid data (finite
numbers of the right shapes) or raises ``InputError`` with one line naming the file; never another
exception, a non-finite number or a read that crawls (each example has a 20 s deadline; reads take
milliseconds, the first one of a test also imports torch).

Bounded for the default suite (all of them together take about 12 s of CPU) and reproducible
(``derandomize``: the same examples on every run).  A longer, randomised search:
``HYPOTHESIS_PROFILE=long pytest tests/test_fuzz_readers.py`` (50x the examples, new ones each run).
"""

import gzip
import io
import json
import math
import os
import shutil
import warnings
from datetime import timedelta
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rheograph.errors import InputError
from rheograph.io.configurations import Snapshots
from rheograph.io.snapshots import read_snapshots, write_bare

ROOT = Path(__file__).resolve().parents[1]
LFDEM = ROOT / "tests" / "data" / "lfdem_run_small"
PAR = LFDEM / "par_conf_params_stress10cl_shear.dat"
MODEL = ROOT / "src" / "rheograph" / "models" / "N400_phi0.76"

_COMMON = dict(
    deadline=timedelta(seconds=20),
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
settings.register_profile("ci", derandomize=True, **_COMMON)
settings.register_profile("long", derandomize=False, **_COMMON)
LONG = os.environ.get("HYPOTHESIS_PROFILE") == "long"
settings.load_profile("long" if LONG else "ci")


def examples(n: int) -> settings:
    return settings(max_examples=50 * n if LONG else n)


# ---- damage --------------------------------------------------------------------------------------
@st.composite
def damaged(draw, data: bytes) -> bytes:
    """``data`` cut short, with bits flipped, or with a stretch overwritten by random bytes."""
    kind = draw(st.sampled_from(["cut", "flip", "overwrite"]))
    if kind == "cut":
        return data[: draw(st.integers(0, len(data) - 1))]
    out = bytearray(data)
    if kind == "flip":
        for _ in range(draw(st.integers(1, 8))):
            out[draw(st.integers(0, len(out) - 1))] ^= 1 << draw(st.integers(0, 7))
        return bytes(out)
    start = draw(st.integers(0, len(out) - 1))
    patch = draw(st.binary(min_size=1, max_size=64))
    out[start : start + len(patch)] = patch
    return bytes(out[: len(data)])


def assert_valid_or_one_line(read, path: Path):
    """``read(path)`` returns valid data or raises a one-line InputError naming ``path``."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)  # an overflow or invalid value while reading
            result = read(path)
    except InputError as exc:
        text = str(exc)
        assert "\n" not in text and path.name in text, text
        return None
    return result


def assert_valid_snapshots(snaps: Snapshots):
    s, n = len(snaps), snaps.n_particles
    assert snaps.positions.shape == (s, n, 2) and np.isfinite(snaps.positions).all()
    assert snaps.radii.shape == (n,) and np.isfinite(snaps.radii).all() and snaps.radii.min() > 0
    assert math.isfinite(snaps.lx) and math.isfinite(snaps.ly) and snaps.lx > 0 and snaps.ly > 0
    assert snaps.le_offset.shape == (s,) and np.isfinite(snaps.le_offset).all()
    assert math.isfinite(snaps.phi) and not math.isinf(snaps.stress)
    # strain and targets: a number or NaN (unknown), never infinite
    assert snaps.strain.shape == (s,) and not np.isinf(snaps.strain).any()
    assert snaps.targets.shape == (s, 3) and not np.isinf(snaps.targets).any()
    for value in snaps.params.values():
        assert math.isfinite(float(value))


# ---- small valid files ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def lfdem_snapshots():
    return read_snapshots(PAR)


@pytest.fixture(scope="module")
def bare_bytes(lfdem_snapshots, tmp_path_factory) -> bytes:
    """A bare snapshot file of two N = 100 configurations of the LF_DEM fixture (~8 kB)."""
    snaps = lfdem_snapshots
    two = Snapshots(**{**snaps.__dict__, "positions": snaps.positions[:2], "le_offset": snaps.le_offset[:2]})
    two.strain, two.targets, two.jammed = snaps.strain[:2], snaps.targets[:2], snaps.jammed[:2]
    path = tmp_path_factory.mktemp("bare") / "s.npz"
    write_bare(path, two)
    return path.read_bytes()


def write_trajectory(path: Path, snaps: Snapshots, params: str | None = None) -> None:
    """A rheograph-layout trajectory (the datasets and attributes the reader takes) of ``snaps``."""
    with h5py.File(path, "w") as h5:
        h5.attrs["params"] = params or json.dumps({"phi": snaps.phi, "stress": snaps.stress, **snaps.params})
        h5.attrs["lx"], h5.attrs["ly"] = snaps.lx, snaps.ly
        h5.attrs["status"] = "completed"
        h5["radii"] = snaps.radii
        h5["snapshots/positions"] = snaps.positions[:2]
        h5["snapshots/le_offset"] = snaps.le_offset[:2]
        h5["snapshots/strain"] = snaps.strain[:2]
        h5["snapshots/viscosity"] = snaps.targets[:2, 0]


@pytest.fixture(scope="module")
def trajectory_bytes(lfdem_snapshots, tmp_path_factory) -> bytes:
    path = tmp_path_factory.mktemp("trajectory") / "t.h5"
    write_trajectory(path, lfdem_snapshots)
    return path.read_bytes()


@pytest.fixture(scope="module")
def par_text() -> str:
    """The LF_DEM fixture run cut to its first three configurations (~27 kB)."""
    text = PAR.read_text()
    blocks = text.split("# cumulated strain")
    return "# cumulated strain".join(blocks[:4])


def lfdem_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "run"
    folder.mkdir(exist_ok=True)
    shutil.copy(LFDEM / "input_conf_params_stress10cl_shear.dat", folder)
    return folder


# ---- bare snapshot files -------------------------------------------------------------------------
@examples(60)
@given(data=st.data())
def test_a_damaged_bare_snapshot_file_reads_valid_or_is_one_line(bare_bytes, tmp_path, data):
    path = tmp_path / "s.npz"
    path.write_bytes(data.draw(damaged(bare_bytes)))
    snaps = assert_valid_or_one_line(read_snapshots, path)
    if snaps is not None:
        assert_valid_snapshots(snaps)


WRONG_VALUES = st.sampled_from(
    [
        np.array("text"),
        np.array(["1", "x"]),
        np.zeros(0),
        np.zeros((3, 0)),
        np.array(np.nan),
        np.array([np.inf, 1.0]),
        np.array(1e308),
        np.array(-1.0),
        np.array([True, False]),
        np.ones(5, dtype=complex),
        np.ones((2, 100, 3)),
        np.arange(7, dtype=np.int8),
    ]
)


@examples(60)
@given(data=st.data())
def test_a_bare_snapshot_file_with_wrong_typed_values_reads_valid_or_is_one_line(bare_bytes, tmp_path, data):
    with np.load(io.BytesIO(bare_bytes)) as npz:
        values = {key: npz[key] for key in npz.files}
    for key in data.draw(st.lists(st.sampled_from(sorted(values)), min_size=1, max_size=3, unique=True)):
        values[key] = data.draw(WRONG_VALUES)
    path = tmp_path / "s.npz"
    np.savez(path, **values)
    snaps = assert_valid_or_one_line(read_snapshots, path)
    if snaps is not None:
        assert_valid_snapshots(snaps)


# ---- rheograph trajectories ----------------------------------------------------------------------
@examples(60)
@given(data=st.data())
def test_a_damaged_trajectory_reads_valid_or_is_one_line(trajectory_bytes, tmp_path, data):
    path = tmp_path / "t.h5"
    path.write_bytes(data.draw(damaged(trajectory_bytes)))
    snaps = assert_valid_or_one_line(read_snapshots, path)
    if snaps is not None:
        assert_valid_snapshots(snaps)


def poisoned(array: np.ndarray):
    """``array`` with one entry made NaN, infinite or huge."""
    flat = array.astype(np.float64).reshape(-1)
    return st.tuples(st.integers(0, flat.size - 1), st.sampled_from([np.nan, np.inf, -np.inf, 1e300])).map(
        lambda change: np.where(np.arange(flat.size) == change[0], change[1], flat).reshape(array.shape)
    )


JSON = st.recursive(
    st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3),
    max_leaves=8,
)


def trajectory_params(snaps: Snapshots) -> dict:
    return {"phi": snaps.phi, "stress": snaps.stress, **snaps.params}


@examples(30)
@given(data=st.data())
def test_a_trajectory_with_wrong_typed_params_reads_valid_or_is_one_line(lfdem_snapshots, tmp_path, data):
    good = trajectory_params(lfdem_snapshots)
    params = data.draw(
        st.one_of(
            st.text(max_size=20),  # not JSON, or JSON of another kind
            JSON.map(json.dumps),
            with_one_value_replaced(good).map(json.dumps),
        ).filter(lambda text: "\x00" not in text)  # HDF5 cannot store it in a string attribute
    )
    path = tmp_path / "t.h5"
    write_trajectory(path, lfdem_snapshots, params)
    snaps = assert_valid_or_one_line(read_snapshots, path)
    if snaps is not None:
        assert_valid_snapshots(snaps)


@examples(40)
@given(data=st.data())
def test_a_trajectory_with_wrong_typed_datasets_reads_valid_or_is_one_line(lfdem_snapshots, tmp_path, data):
    path = tmp_path / "t.h5"
    write_trajectory(path, lfdem_snapshots, json.dumps(trajectory_params(lfdem_snapshots)))
    replaced = data.draw(
        st.lists(
            st.sampled_from(
                [
                    "radii",
                    "snapshots/positions",
                    "snapshots/le_offset",
                    "snapshots/strain",
                    "snapshots/viscosity",
                ]
            ),
            min_size=1,
            max_size=2,
            unique=True,
        )
    )
    with h5py.File(path, "r+") as h5:
        for key in replaced:
            value = data.draw(st.one_of(WRONG_VALUES, poisoned(h5[key][()])))
            del h5[key]
            if value.dtype.kind == "U":
                h5[key] = value.astype(object).astype(bytes)
            else:
                h5[key] = value
    snaps = assert_valid_or_one_line(read_snapshots, path)
    if snaps is not None:
        assert_valid_snapshots(snaps)


# ---- LF_DEM runs ---------------------------------------------------------------------------------
@examples(40)
@given(data=st.data())
def test_a_damaged_lfdem_run_reads_valid_or_is_one_line(par_text, tmp_path, data):
    path = lfdem_folder(tmp_path) / PAR.name
    path.write_bytes(data.draw(damaged(par_text.encode())))
    snaps = assert_valid_or_one_line(read_snapshots, path)
    if snaps is not None:
        assert_valid_snapshots(snaps)


@examples(40)
@given(data=st.data())
def test_a_damaged_gzip_lfdem_run_reads_valid_or_is_one_line(par_text, tmp_path, data):
    path = lfdem_folder(tmp_path) / (PAR.name + ".gz")
    path.write_bytes(data.draw(damaged(gzip.compress(par_text.encode(), mtime=0))))
    snaps = assert_valid_or_one_line(read_snapshots, path)
    if snaps is not None:
        assert_valid_snapshots(snaps)


# ---- model folders -------------------------------------------------------------------------------
def json_paths(document, prefix=()) -> list[tuple]:
    """The path (keys and indices) of every value in a JSON ``document``, at any depth."""
    if not isinstance(document, dict | list):
        return []
    children = document.items() if isinstance(document, dict) else enumerate(document)
    return [p for key, value in children for p in [(*prefix, key), *json_paths(value, (*prefix, key))]]


def with_one_value_replaced(document, under=()):
    """``document`` (JSON) with one value at any depth (under the top-level keys ``under``, if given) —
    a whole entry, one element of a list — replaced by random JSON."""
    paths = [p for p in json_paths(document) if not under or p[0] in under]

    def replace(path, value):
        out = json.loads(json.dumps(document))
        node = out
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
        return out

    return st.tuples(st.sampled_from(paths), JSON).map(lambda change: replace(*change))


def damaged_json(path: Path, under=()):
    """The bytes of JSON file ``path`` damaged, replaced by JSON of another shape, or with one value
    replaced."""
    original = path.read_bytes()
    return st.one_of(
        damaged(original),
        JSON.map(lambda v: json.dumps(v).encode()),
        with_one_value_replaced(json.loads(original), under).map(lambda d: json.dumps(d).encode()),
    )


@examples(40)
@given(data=st.data())
def test_a_damaged_model_card_reads_valid_or_is_one_line(tmp_path, data):
    from rheograph.learn.registry import read_card

    # what predictions read of a card: its domain and position noise
    (tmp_path / "card.json").write_bytes(
        data.draw(damaged_json(MODEL / "card.json", ("domain", "position_noise")))
    )
    card = assert_valid_or_one_line(lambda p: read_card([p.with_name("fold0.pt")]), tmp_path / "card.json")
    if card is not None:
        domain, noise = card["domain"], card["position_noise"]
        noise = noise if isinstance(noise, list) else [noise]
        for values in (domain["phi"], domain["stress"], domain["n_particles"], noise):
            assert all(isinstance(v, int | float) and math.isfinite(v) for v in values)
        assert len(domain["phi"]) == len(domain["stress"]) == 2


@examples(40)
@given(data=st.data())
def test_a_damaged_error_model_reads_valid_or_is_one_line(tmp_path, data):
    from rheograph.learn.error_model import predicted_error, read_error_model

    (tmp_path / "error_model.json").write_bytes(data.draw(damaged_json(MODEL / "error_model.json")))
    model = assert_valid_or_one_line(lambda p: read_error_model(p.parent), tmp_path / "error_model.json")
    if model is not None:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a log of a stress <= 0, an interpolation through inf
            bars = predicted_error(model, [1.0, 10.0], [0.76, 0.76])
        assert not np.isinf(bars).any() and (np.nan_to_num(bars) >= 0).all()


@examples(25)
@given(data=st.data())
def test_a_damaged_model_bundle_loads_or_is_one_line(tmp_path, data):
    from rheograph.learn.bundle import load_bundle

    path = tmp_path / "fold0.pt"
    path.write_bytes(data.draw(damaged((MODEL / "fold0.pt").read_bytes())))
    assert_valid_or_one_line(load_bundle, path)
