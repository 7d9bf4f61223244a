"""Snapshots from anywhere: rheograph trajectories, bare configuration files and LF_DEM runs, read into
one in-memory form (``Snapshots``) that graph building and prediction take.

Three kinds of source (``read_snapshots`` tells them apart by their content and name):

* a **rheograph trajectory** (HDF5 with ``/snapshots``, docs/data_format.md), finished, jammed, still
  being written (then its copy as of the last checkpoint is read) or stripped of its time series; 2D, or
  3D (root attribute ``dim`` 3: positions (S, N, 3) and the cube edge ``lz``);
* a **bare snapshot file** (``.npz``, or HDF5 with the same keys as datasets or root attributes):
  ``positions`` (S, N, 2) or (N, 2) [a], ``radii`` (N,) [a], ``box`` (2,) = (Lx, Ly) [a], ``le_offset``
  (S,) or a scalar [a] (x-shift of the periodic image above, y + Ly), ``stress`` (σ/σ0), ``phi``, and the
  physical parameters ``PHYSICAL_PARAMS`` named as the ``sim.*`` keys; optional ``strain``, ``eta_r``,
  ``pressure``, ``z_mu`` (S,), ``position_noise`` [a] and ``disp_max``.  A 3D one has positions
  (S, N, 3) or (N, 3) (x flow, y gradient, z vorticity), ``box`` (3,) = (Lx, Ly, Lz) and ``phi`` the
  volume fraction; its optional ``dim`` (2 or 3) must agree; its optional ``axial_noise`` [a] is the
  precision along a confocal microscope's optical axis (the model's ``graph.optical_axis``), with
  ``position_noise`` then the in-plane one; optional ``radii_nominal`` (0 or 1): 1 declares the radii
  each particle's species' nominal radius (sizes spread, unmeasured) and ``phi`` the sample's measured
  fraction, which the radii then need give only to within ``NOMINAL_PHI_TOLERANCE`` (such snapshots are
  read with radii estimated from the configurations, ``rheograph.graphs.radii_estimate``);
* an **LF_DEM run**: its ``par_*.dat`` (plain or ``.gz``), see ``rheograph.io.lfdem``.

Positions are wrapped into rheograph's box [-Lx/2, Lx/2) x [-Ly/2, Ly/2) with the Lees–Edwards images
(a uniform shift of all positions does not change the rheology of a sheared periodic box).  Nothing is
filled in: a parameter the source does not carry stays absent, and whoever needs it (the graph builder, a
model) names it.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import logging
import math
from pathlib import Path

import h5py
import numpy as np

from rheograph.errors import InputError
from rheograph.io.configurations import (
    DAMAGED_FILE_ERRORS,
    PHYSICAL_PARAMS,
    TARGET_KEYS,
    Snapshots,
    check_configurations,
    check_geometry,
    size_ratio,
    wrap_into_box,
    wrap_into_box3d,
)
from rheograph.io.hdf5 import (
    SCHEMA_VERSION,
    TrajectoryFileError,
    file_dim,
    jammed_snapshots,
    last_checkpoint_copy,
    read_run_info,
    readable_path,
)
from rheograph.io.lfdem import read_lfdem
from rheograph.sim.radii import TRUNCATION as RADII_TRUNCATION

log = logging.getLogger("rheograph")

# of them, those a bare file must carry (critical_load is the unit of force, 1 by definition, and the size
# ratio is read off the radii)
BARE_REQUIRED_PARAMS = ("mu", "kn_coefficient", "kt_ratio", "delta", "lub_max_gap")
# every key a bare snapshot file may hold (module docstring); dt_max and lagged_step_control, the rest of
# the step a source was made with, are recorded by write_bare beside disp_max
BARE_KEYS = (
    "positions", "radii", "box", "le_offset", "stress", "phi", *PHYSICAL_PARAMS, "strain", *TARGET_KEYS,
    "position_noise", "axial_noise", "disp_max", "dt_max", "lagged_step_control", "dim", "radii_nominal",
)  # fmt: skip
# what a bare file whose stated phi disagrees with its radii is told, besides checking the box and units
NOMINAL_REMEDY = (
    "; if the radii are the species' nominal ones (particles spread in size, unmeasured) and phi is the "
    "measured fraction, declare them: key radii_nominal = 1, or predict.py --radii estimated-mean "
    "(docs/imaging.md)"
)
KIND_NAMES = {"rheograph": "a rheograph trajectory", "bare": "a bare snapshot file", "lfdem": "an LF_DEM run"}


# ---- rheograph trajectories ------------------------------------------------------------------------
def _open_trajectory(path: Path) -> tuple[h5py.File, Path]:
    """The file, or where a simulation still holds it (HDF5 file lock), its copy as of the last
    checkpoint (consistent on disk: written right after a flush)."""
    try:
        readable = readable_path(path)
        return h5py.File(readable, "r"), readable
    except OSError as exc:
        raise InputError(
            f"{path}: cannot be opened as HDF5 ({exc}); if it is truncated or corrupt, move it aside and "
            "rerun that state point"
        ) from exc


def smallest_radius_band(params: dict, where: str):
    """What a trajectory's smallest radius may be (``check_geometry``'s ``smallest``), from the radii
    its run drew: exactly 1 for two exact species; within the truncated spread below 1 for spread radii
    (``sim.radii=polydisperse``: a is the small species' nominal radius); not checked for a run's radii
    file, which defines a itself."""
    kind = params.get("radii", "bidisperse")
    if kind == "polydisperse":
        spread = _scalar(params, "polydispersity", where)
        return (1.0 - RADII_TRUNCATION * spread, 1.0)
    return None if kind == "file" else (1.0, 1.0)


def read_trajectory(path: str | Path) -> Snapshots:
    """The snapshots of a rheograph-layout trajectory (``/snapshots``, ``/radii``, root ``params``)."""
    path = Path(path)
    h5, opened = _open_trajectory(path)
    with h5:
        version = h5.attrs.get("schema_version")
        if version is not None and int(version) != SCHEMA_VERSION:
            raise InputError(f"{path}: trajectory schema {int(version)}, this version reads {SCHEMA_VERSION}")
        for key in ("radii", "snapshots/positions", "snapshots/le_offset"):
            if key not in h5:
                raise InputError(f"{path}: no /{key}: not a trajectory (docs/data_format.md)")
        try:
            params = json.loads(h5.attrs["params"])
        except (KeyError, ValueError, TypeError) as exc:
            raise InputError(f"{path}: no readable root attribute 'params' (JSON of the sim.* keys)") from exc
        if not isinstance(params, dict):
            raise InputError(f"{path}: its root attribute 'params' is not a JSON object of the sim.* keys")
        for key in ("stress", "phi"):
            if key not in params:
                raise InputError(f"{path}: its params lack '{key}' (the state point): add it to the file")
        dim = file_dim(h5)
        for key in ("lx", "ly", "lz") if dim == 3 else ("lx", "ly"):
            if key not in h5.attrs:
                raise InputError(f"{path}: no root attribute '{key}' (box length [a])")
        lx, ly = float(h5.attrs["lx"]), float(h5.attrs["ly"])
        lz = float(h5.attrs["lz"]) if dim == 3 else None
        radii = _numbers({"radii": h5["radii"][()]}, "radii", str(path))
        sn = h5["snapshots"]
        count = sn["positions"].shape[0]
        if opened != path or str(h5.attrs.get("status", "")) == "running":
            # rows a running file appended after its last checkpoint may be half written
            counters = json.loads(h5["checkpoint"].attrs["counters"]) if "checkpoint" in h5 else {}
            count = min(count, int(counters.get("snapshots", count)))

        def rows(name):  # the first count rows of a dataset of /snapshots, as numbers
            if name not in sn:
                return np.full(count, np.nan)
            return _numbers({name: sn[name][:count]}, name, str(path))

        positions, offsets, strain = rows("positions"), rows("le_offset"), rows("strain")
        targets = np.stack([rows(name) for name in ("viscosity", "pressure", "z_mu")], axis=1)
        status = str(h5.attrs.get("status", ""))
        if "timeseries/strain" in h5:
            jammed = jammed_snapshots(
                status, strain, h5["timeseries/strain"][()], params.get("jam_intervals", 10)
            )
        else:  # without the time series only the arrested packing the run ended on is known jammed
            jammed = np.zeros(count, dtype=bool)
            if status == "jammed" and count:
                jammed[-1] = True
        contacts = None
        names = ("contact_offset", "contact_pairs", "contact_state", "contact_stretch")
        if all(name in sn for name in names):
            offset = sn["contact_offset"][()]
            pairs, states, stretches = (
                sn["contact_pairs"][()],
                sn["contact_state"][()],
                sn["contact_stretch"][()],
            )
            contacts = [
                (
                    pairs[offset[k] : offset[k + 1]],
                    states[offset[k] : offset[k + 1]],
                    stretches[offset[k] : offset[k + 1]],
                )
                for k in range(min(count, offset.size - 1))
            ]
    phi, stress = _scalar(params, "phi", str(path)), _scalar(params, "stress", str(path))
    check_geometry(str(path), radii, lx, ly, phi, lz, smallest_radius_band(params, str(path)))
    check_configurations(str(path), positions, radii, offsets, strain, targets, dim)
    physical = {k: _scalar(params, k, f"{path}: params") for k in PHYSICAL_PARAMS if k in params}
    numerics = {k: params[k] for k in ("disp_max", "dt_max", "lagged_step_control") if k in params}
    return Snapshots(
        source=str(path),
        kind="rheograph",
        positions=positions,  # the simulator writes them wrapped
        radii=radii,
        lx=lx,
        ly=ly,
        le_offset=offsets,
        strain=np.asarray(strain, dtype=np.float64),
        stress=stress,
        phi=phi,
        params=physical,
        targets=targets,
        jammed=jammed,
        numerics=numerics,
        contacts=contacts,
        status=status,
        lz=lz,
    )


# ---- bare snapshot files ---------------------------------------------------------------------------
def _bare_values(path: Path) -> dict:
    if path.suffix == ".npz":
        try:
            with np.load(path, allow_pickle=False) as data:
                return {key: data[key] for key in data.files}
        except (OSError, ValueError) as exc:
            raise InputError(f"{path}: not a readable .npz file ({exc})") from exc
    with h5py.File(path, "r") as h5:
        values = {key: h5.attrs[key] for key in h5.attrs}
        values.update({key: h5[key][()] for key in h5 if isinstance(h5[key], h5py.Dataset)})
        return values


def _numbers(values: dict, key: str, where: str) -> np.ndarray:
    """``values[key]`` as float64 numbers; a complex, text or other non-numeric value is refused by name
    (numpy would drop an imaginary part with only a warning)."""
    value = values[key]
    if np.iscomplexobj(value):
        raise InputError(f"{where}: '{key}' must be real numbers, found complex ones")
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{where}: '{key}' must be numbers, found {np.asarray(value).dtype}") from exc


def _scalar(values: dict, key: str, where: str) -> float:
    numbers = _numbers(values, key, where)
    if numbers.size != 1:
        raise InputError(f"{where}: '{key}' must be one number, found {numbers.size}")
    value = float(numbers.reshape(()))
    if not math.isfinite(value):
        raise InputError(f"{where}: '{key}' = {value} is not finite")
    return value


def read_bare(path: str | Path, params: dict | None = None, radii_nominal: bool = False) -> Snapshots:
    """A bare snapshot file (module docstring lists its keys); ``params``: physical parameters given
    beside the file, which supply or replace its own; ``radii_nominal``: the caller declares the file's
    radii nominal (as its key ``radii_nominal`` = 1 does)."""
    values = {**_bare_values(Path(path)), **(params or {})}
    return snapshots_from_values(values, str(path), kind="bare", radii_nominal=radii_nominal)


def unknown_keys_warning(keys, where: str) -> str | None:
    """The warning for keys of a bare snapshot file that it has no use for (a misspelt optional key
    would otherwise be ignored without a word), each with the closest known key; None when all are
    known."""
    unknown = sorted(set(keys) - set(BARE_KEYS))
    if not unknown:
        return None
    named = []
    for key in unknown:
        close = difflib.get_close_matches(key, BARE_KEYS, n=1)
        named.append(f"{key!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    return (
        f"{where}: key(s) {', '.join(named)} ignored: a bare snapshot file's keys are {list(BARE_KEYS)} "
        "(docs/data_format.md)"
    )


def snapshots_from_values(
    values: dict, where: str, kind: str = "bare", radii_nominal: bool = False
) -> Snapshots:
    """``Snapshots`` from the keys of a bare snapshot file (module docstring), checked; ``where`` names
    the source in messages.  Keys it does not know are named in a warning (``unknown_keys_warning``).
    ``radii_nominal``: the radii are declared nominal by the caller (else only by the key of that name)."""
    warning = unknown_keys_warning(values, where)
    if warning:
        log.warning("%s", warning)
    # the stress may be unknown (a positions-only model reads none): NaN then, refused by every model
    # that needs it (rheograph.graphs.dataset.snapshot_graphs)
    required = ("positions", "radii", "box", "le_offset", "phi", *BARE_REQUIRED_PARAMS)
    missing = [key for key in required if key not in values]
    if missing:
        raise InputError(
            f"{where}: missing key(s) {missing}; a bare snapshot file needs {list(required)} "
            "(docs/data_format.md, 'Bare snapshot files')"
            + (
                "; physical parameters may instead be given beside it (predict.py --param KEY=VALUE, "
                "keyword arguments of model.predict)"
                if set(missing) <= set(PHYSICAL_PARAMS)
                else ""
            )
        )
    positions = _numbers(values, "positions", where)
    if positions.ndim == 2:
        positions = positions[None]
    radii = _numbers(values, "radii", where).reshape(-1)
    box = _numbers(values, "box", where).reshape(-1)
    if box.size not in (2, 3):
        raise InputError(f"{where}: box must be (Lx, Ly), or (Lx, Ly, Lz) in 3D, found {box.size} value(s)")
    dim = box.size
    if values.get("dim") is not None and _scalar(values, "dim", where) != dim:
        raise InputError(
            f"{where}: dim = {_scalar(values, 'dim', where):g} but the box has {dim} edges (2D: (Lx, Ly), "
            "3D: (Lx, Ly, Lz))"
        )
    if positions.ndim != 3 or positions.shape[1:] != (radii.size, dim):
        raise InputError(
            f"{where}: positions must be (S, N, {dim}) or (N, {dim}) with N = {radii.size} (the radii) "
            f"for a box of {dim} edges, found {positions.shape}"
        )
    if not np.all(np.isfinite(positions)):
        raise InputError(f"{where}: positions contain non-finite values")
    n_snap = positions.shape[0]
    lx, ly = float(box[0]), float(box[1])
    lz = float(box[2]) if dim == 3 else None
    offsets = _numbers(values, "le_offset", where).reshape(-1)
    if offsets.size == 1:
        offsets = np.full(n_snap, offsets[0])
    if offsets.size != n_snap or not np.all(np.isfinite(offsets)):
        raise InputError(f"{where}: le_offset must be one number or (S,) = ({n_snap},) finite numbers")
    phi = _scalar(values, "phi", where)
    stress = _scalar(values, "stress", where) if values.get("stress") is not None else float("nan")
    if stress <= 0:
        raise InputError(f"{where}: stress = {stress:g} must be > 0 (σ/σ0)")
    if values.get("radii_nominal") is not None:
        declared = _scalar(values, "radii_nominal", where)
        if declared not in (0.0, 1.0):
            raise InputError(
                f"{where}: radii_nominal = {declared:g}: allowed 0 or 1 (1: the radii are each species' "
                "nominal radius and phi the measured fraction, docs/data_format.md)"
            )
        radii_nominal = radii_nominal or declared == 1.0
    remedy = NOMINAL_REMEDY if kind == "bare" else ""
    check_geometry(where, radii, lx, ly, phi, lz, nominal=radii_nominal, remedy=remedy)
    params = {key: _scalar(values, key, where) for key in PHYSICAL_PARAMS if key in values}
    measured_ratio = size_ratio(radii)
    if "size_ratio" in params and not math.isclose(params["size_ratio"], measured_ratio, rel_tol=1e-5):
        raise InputError(
            f"{where}: size_ratio = {params['size_ratio']:g} but the radii give {measured_ratio:g}"
        )
    params["size_ratio"] = measured_ratio
    if params.setdefault("critical_load", 1.0) != 1.0:
        raise InputError(f"{where}: critical_load must be 1 (F_CL is the unit of force and stress)")

    def series(key):
        if key not in values:
            return np.full(n_snap, np.nan)
        out = _numbers(values, key, where).reshape(-1)
        if out.size != n_snap:
            raise InputError(f"{where}: '{key}' needs one value per snapshot ({n_snap}), found {out.size}")
        return out

    strain, targets = series("strain"), np.stack([series(key) for key in TARGET_KEYS], axis=1)
    if np.isinf(strain).any() or np.isinf(targets).any():
        raise InputError(
            f"{where}: the strain or the targets ({', '.join(TARGET_KEYS)}) contain infinite values"
        )
    noise = _scalar(values, "position_noise", where) if values.get("position_noise") is not None else None
    if noise is not None and noise < 0:
        raise InputError(f"{where}: position_noise = {noise:g} must be >= 0 (units of a)")
    axial = _scalar(values, "axial_noise", where) if values.get("axial_noise") is not None else None
    if axial is not None and (axial < 0 or lz is None or noise is None):
        raise InputError(
            f"{where}: axial_noise = {axial:g} is the precision along the optical axis of a 3D snapshot, "
            "beside its in-plane position_noise: allowed >= 0 (units of a), with position_noise, in 3D"
        )
    numerics = {"disp_max": _scalar(values, "disp_max", where)} if "disp_max" in values else {}
    return Snapshots(
        source=where,
        kind=kind,
        positions=np.stack(
            [
                wrap_into_box(p, lx, ly, o) if lz is None else wrap_into_box3d(p, lx, ly, lz, o)
                for p, o in zip(positions, offsets)
            ]
        ),
        radii=radii,
        lx=lx,
        ly=ly,
        le_offset=offsets,
        strain=strain,
        stress=stress,
        phi=phi,
        params=params,
        targets=targets,
        jammed=np.zeros(n_snap, dtype=bool),
        numerics=numerics,
        position_noise=noise,
        lz=lz,
        axial_noise=axial,
        radii_nominal=bool(radii_nominal),
    )


def write_bare(path: str | Path, snapshots: Snapshots) -> None:
    """Write ``snapshots`` as a bare ``.npz`` file (for exchanging configurations; targets where known)."""
    values = {
        "positions": snapshots.positions,
        "radii": snapshots.radii,
        "box": np.array([snapshots.lx, snapshots.ly, *(() if snapshots.lz is None else (snapshots.lz,))]),
        "le_offset": snapshots.le_offset,
        "stress": snapshots.stress,
        "phi": snapshots.phi,
        "strain": snapshots.strain,
        **({} if snapshots.position_noise is None else {"position_noise": snapshots.position_noise}),
        **({} if snapshots.axial_noise is None else {"axial_noise": snapshots.axial_noise}),
        **({"radii_nominal": 1} if snapshots.radii_nominal else {}),
        **{k: v for k, v in snapshots.params.items()},
        **{key: snapshots.targets[:, k] for k, key in enumerate(TARGET_KEYS)},
        **snapshots.numerics,
    }
    np.savez(path, **values)


# ---- dispatch --------------------------------------------------------------------------------------
def source_kind(path: str | Path) -> str:
    """``rheograph``, ``bare`` or ``lfdem`` for a snapshot source (by its name and content)."""
    path = Path(path)
    name = path.name
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if name.startswith("par_") and (name.endswith(".dat") or name.endswith(".dat.gz")):
        return "lfdem"
    if path.suffix == ".npz":
        return "bare"
    if h5py.is_hdf5(path):
        try:
            with h5py.File(path, "r") as h5:
                return "rheograph" if "snapshots" in h5 else "bare"
        # held by a running simulation (only trajectories are written that way), or damaged past its
        # superblock (HDF5's RuntimeError): the trajectory reader names what is wrong
        except (OSError, RuntimeError):
            return "rheograph"

    if last_checkpoint_copy(path).exists():  # damaged mid-write; its copy is readable
        return "rheograph"
    raise InputError(
        f"{path}: not a snapshot source: expected a rheograph trajectory (.h5), a bare snapshot file "
        "(.npz or HDF5 with positions, radii, box, ...) or an LF_DEM par_*.dat[.gz]"
    )


def read_snapshots(
    path: str | Path,
    lfdem_params: str | Path | None = None,
    params: dict | None = None,
    radii_nominal: bool = False,
) -> Snapshots:
    """The snapshots of any source (module docstring); ``lfdem_params``: LF_DEM's parameter file, for
    LF_DEM runs (``rheograph.io.lfdem.read_lfdem``); ``params``: physical parameters (``sim.*`` names)
    given beside the source, which supply or replace those it carries; ``radii_nominal``: the caller
    declares a bare file's radii the species' nominal ones and its phi measured (as the file's key
    ``radii_nominal`` = 1 does; a trajectory's or LF_DEM run's radii are the ones it simulated, and its phi
    is checked against them as ever)."""
    unknown = sorted(set(params or {}) - set(PHYSICAL_PARAMS))
    if unknown:
        raise InputError(f"{path}: unknown physical parameter(s) {unknown}; they are {list(PHYSICAL_PARAMS)}")
    snaps = _read_source(path, lfdem_params, params or {}, radii_nominal)
    if params:
        snaps.params = {**snaps.params, **params}
    return snaps


def _read_source(
    path: str | Path, lfdem_params: str | Path | None, params: dict, radii_nominal: bool
) -> Snapshots:
    kind = source_kind(path)
    if kind != "lfdem" and lfdem_params is not None:
        raise InputError(f"{path}: an LF_DEM parameter file was given, but this is not an LF_DEM par_*.dat")
    try:
        if kind == "lfdem":
            return read_lfdem(path, lfdem_params)
        return read_trajectory(path) if kind == "rheograph" else read_bare(path, params, radii_nominal)
    except InputError:
        raise
    except DAMAGED_FILE_ERRORS as exc:
        raise InputError(
            f"{path}: cannot be read as {KIND_NAMES[kind]} ({type(exc).__name__}: {exc}); is it truncated "
            "or of another format?"
        ) from exc


def data_fingerprint(paths) -> str:
    """Hash of what trajectory files hold — parameters, status, strain and steps reached — not of where
    they lie or when they were copied: equal for a clone of the same data; different once a file is added
    or removed, a run extended, or a state point resimulated with other parameters (a resimulation with
    the same parameters to the same strain in the same number of steps is not told apart: changed dynamics
    change the step count)."""
    identities = []
    for path in paths:
        if source_kind(path) != "rheograph":  # a bare file or an LF_DEM run: what it holds is its bytes
            identities.append(hashlib.sha1(Path(path).read_bytes()).hexdigest())
            continue
        try:
            info = read_run_info(path)
        except (OSError, KeyError, ValueError, TypeError) as exc:  # ValueError: params not JSON
            raise TrajectoryFileError(
                f"{path}: cannot be read ({exc}); if a simulation is still writing it, wait or train on a "
                "sweep index of finished runs; if it is truncated or corrupt, move it aside and rerun that "
                "state point"
            ) from exc
        identities.append(
            json.dumps([info[k] for k in ("params", "status", "strain", "steps")], sort_keys=True)
        )
    return hashlib.sha1("\n".join(sorted(identities)).encode()).hexdigest()[:16]
