"""Trajectory files: one HDF5 file per state point (schema in docs/data_format.md).

Layout (schema_version 1; D = 2, or 3 in a 3D run's file, which says so in its attrs dim and lz):
  /                attrs: schema_version, producer, status, params (each SimParams field), lx, ly
                   (3D: also dim = 3, lz)
  /radii           (N,) particle radii [a]
  /timeseries/*    one row per output step (resizable 1-D or (rows, 3) datasets; (rows, 6) in 3D, which
                   also has the normal stress differences n1, n2)
  /snapshots/*     one entry per snapshot: positions (S, N, D), scalars, and the contact list flattened
                   with contact_offset (S + 1,) indexing contact_pairs (M, 2), contact_state,
                   contact_stretch (M, D)
  /checkpoint/*    the SimState needed to resume bit-for-bit, plus the row counts it is consistent with
  /summary         attrs: steady-state means and standard errors (written when the run ends)

Rows written after the last checkpoint are dropped on resume and recomputed (the dynamics are
deterministic), so an interrupted run loses and duplicates nothing.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import shutil
from pathlib import Path

import h5py
import numpy as np

from rheograph.errors import InputError, NoRoomError, hdf5_write_found_no_room
from rheograph.sim.integrator import SimState
from rheograph.sim.integrator3d import SimState3D
from rheograph.sim.params import SimParams
from rheograph.sim.params3d import params_from_mapping

log = logging.getLogger("rheograph")

SCHEMA_VERSION = 1
PRODUCER = "rheograph"

TIMESERIES_SCALARS = (
    "time",
    "strain",
    "shear_rate",
    "viscosity",
    "pressure",
    "z_mu",
    "z",
    "max_overlap",
    "max_stretch",
    "dt",
    "steps",
    "jammed",
)
TIMESERIES_TENSORS = ("stress", "stress_lubrication", "stress_contact", "stress_solvent")
# 3D only: the normal stress differences N1 = sigma_xx - sigma_yy, N2 = sigma_yy - sigma_zz [sigma0]
# (in 2D sigma_zz = 0 by convention, so N2 would be no measurement)
TIMESERIES_SCALARS_3D = (*TIMESERIES_SCALARS, "n1", "n2")
# stored components of the symmetric stress tensors (upper triangle)
TENSOR_COMPONENTS = {
    2: "xx, xy, yy (sigma_zz = 0); stresses in sigma0",
    3: "xx, xy, xz, yy, yz, zz; stresses in sigma0",
}
SNAPSHOT_SCALARS = ("time", "strain", "le_offset", "shear_rate", "viscosity", "pressure", "z_mu", "z")
# parameters that may change between invocations of the same run (they do not alter the physics)
RESUMABLE_PARAMS = {"strain", "max_wall_seconds", "checkpoint_wall_seconds", "jam_intervals"}


# Raw while running, compact at rest.  A file being appended to stays uncompressed: a SIGKILL between
# flushes can leave a compressed chunk half written, which then fails to decode when the run resumes (the
# SIGKILL test found it), while a raw chunk keeps its checkpointed rows intact.  A finished file is
# rewritten with gzip + byte shuffle and, for the three datasets that make up most of it, storage sized
# to the physics (AT_REST, docs/dataset.md "Storage"):
# * snapshot positions quantised to 1e-7 a (HDF5 scale-offset, 7 decimals; error <= 5e-8 a): contacts
#   are decided by overlaps of ~1e-4-1e-3 a, so a stored gap moves by <= 1e-7 a, 1e-4-1e-3 of an overlap;
#   float32 would give 3e-6 a at coordinates of ~50 a (N = 2000), a few % of a small overlap;
# * tangential spring stretches as float32 (relative 6e-8; they are ~1e-5-1e-3 a);
# * contact pair indices as int32.
# Halves a file again after gzip (2.3 -> 1.1 MB at N = 2000).  The checkpoint stays exact (float64,
# lossless): it is what a run resumes or is extended from; time series and targets are lossless.
COMPRESSION = dict(compression="gzip", compression_opts=4, shuffle=True)
WRITER_DTYPES = {  # what a running file holds
    "snapshots/positions": np.float64,
    "snapshots/contact_stretch": np.float64,
    "snapshots/contact_pairs": np.int64,
}
POSITION_DECIMALS = 7
AT_REST = {
    "snapshots/positions": dict(dtype=np.float64, scaleoffset=POSITION_DECIMALS),
    "snapshots/contact_stretch": dict(dtype=np.float32),
    "snapshots/contact_pairs": dict(dtype=np.int32),
}


class TrajectoryFileError(InputError):
    """A trajectory file is corrupt, foreign, or belongs to another state point."""


class DamagedTrajectoryError(TrajectoryFileError):
    """A trajectory file that cannot be read back (truncated, half-written metadata, checkpoint missing)."""


class TrajectoryWriteError(NoRoomError):
    """Writing a trajectory failed (disk full, quota, file-size limit): the run stopped; says what a rerun
    resumes from — the file, closed cleanly, or its last-checkpoint copy where closing failed too."""

    def __init__(self, path: Path, cause: OSError):
        copy = last_checkpoint_copy(path)
        where = (
            f"a rerun resumes from the copy as of its last checkpoint, {copy.name}"
            if copy.exists()
            else "the file is whole as of its last checkpoint"
        )
        super().__init__(
            f"writing {path} failed ({cause}): is the disk full or a quota reached? The run stopped; "
            f"{where}: free space and rerun the same command to resume"
        )
        self.__cause__ = cause


def last_checkpoint_copy(path: str | Path) -> Path:
    """Where a running trajectory keeps a copy of itself as of its last checkpoint
    (``<name>.last-checkpoint``, not ``*.h5``: no glob of trajectories picks it up).  HDF5 rewrites its
    metadata in place, so a write that fails half-way (disk full, quota, a kill during the flush) can leave
    the file itself unreadable; a resume then falls back to this copy.  Removed when the file is closed
    cleanly."""
    path = Path(path)
    return path.with_name(path.name + ".last-checkpoint")


def readable_path(path: str | Path) -> Path:
    """``path``, or, while a simulation holds its HDF5 lock, its copy as of the last checkpoint (consistent
    on disk: written right after a flush).  Other failures to open it raise OSError."""
    path = Path(path)
    try:
        with h5py.File(path, "r"):
            return path
    except OSError as exc:
        copy = last_checkpoint_copy(path)
        if "lock" in str(exc).lower() and copy.exists():
            return copy
        raise


def _unused_name(path: Path) -> Path:
    """``path``, or ``path.1``, ``path.2``, ...: the first that does not exist."""
    candidate, n = path, 0
    while candidate.exists():
        n += 1
        candidate = path.with_name(f"{path.name}.{n}")
    return candidate


def file_dim(h5: h5py.File) -> int:
    """Space dimension of an open trajectory file: its attribute ``dim``, absent (2) in 2D files."""
    return int(h5.attrs.get("dim", 2))


def timeseries_scalars(dim: int) -> tuple[str, ...]:
    """The scalar time-series columns of a ``dim``-dimensional run."""
    return TIMESERIES_SCALARS_3D if dim == 3 else TIMESERIES_SCALARS


def _append(ds: h5py.Dataset, values) -> None:
    values = np.asarray(values, dtype=ds.dtype)
    n = ds.shape[0]
    ds.resize(n + values.shape[0], axis=0)
    ds[n:] = values


class TrajectoryFile:
    """Writer/reader of one state point's trajectory file."""

    def __init__(self, path: str | Path, params: SimParams):
        self.path = Path(path)
        self.params = params
        self.h5: h5py.File | None = None

    # ---- opening -----------------------------------------------------------------------------
    @contextlib.contextmanager
    def _creation_lock(self):
        """Held while a new file is made: of two processes started at the same moment on one state point,
        the second is refused by name instead of failing inside HDF5 on the first one's half-made file.
        The lock (``flock`` on ``<name>.creating``) goes with the process, also when it is killed."""
        lock = self.path.with_name(self.path.name + ".creating")
        try:
            handle = open(lock, "a")
        except OSError as exc:
            raise TrajectoryFileError(
                f"cannot create {lock} ({exc.strerror}): choose a writable output folder (output_root=<dir>)"
            ) from exc
        with handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                raise TrajectoryFileError(
                    f"{self.path} is being created by another process: is this state point already running?"
                ) from exc
            try:
                if self.path.exists():  # made meanwhile by a process that started at the same moment
                    raise TrajectoryFileError(
                        f"{self.path} was created by another process meanwhile: is this state point "
                        "already running?"
                    )
                yield
            finally:
                lock.unlink(missing_ok=True)  # while still held: a later process finds the file made

    def open_new(self, state: SimState) -> None:
        with self._creation_lock():
            self._create(state)

    def _create(self, state: SimState) -> None:
        tmp = self.path.with_suffix(self.path.suffix + ".tmp")
        try:
            h5 = h5py.File(tmp, "w")
        except OSError as exc:
            raise TrajectoryFileError(
                f"cannot create {tmp} ({exc}): choose a writable output folder (output_root=<dir>)"
            ) from exc
        with h5:
            h5.attrs["schema_version"] = SCHEMA_VERSION
            h5.attrs["producer"] = PRODUCER
            h5.attrs["status"] = "running"
            # the default path's parameters as before rate control and radii existed (``stored_dict``)
            stored = self.params.stored_dict()
            h5.attrs["params"] = json.dumps(stored)
            for key, value in stored.items():
                h5.attrs[f"param_{key}"] = value
            h5.attrs["lx"] = state.lx
            h5.attrs["ly"] = state.ly
            dim = self.params.DIM
            if dim == 3:  # 2D files stay as they were written before 3D existed: no dim means 2
                h5.attrs["dim"] = dim
                h5.attrs["lz"] = state.lz
            h5.create_dataset("radii", data=state.radii)
            n = state.radii.shape[0]
            components = dim * (dim + 1) // 2
            ts = h5.create_group("timeseries")
            for name in timeseries_scalars(dim):
                dtype = np.int64 if name == "steps" else (np.bool_ if name == "jammed" else np.float64)
                ts.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dtype, chunks=(1024,))
            for name in TIMESERIES_TENSORS:
                ts.create_dataset(
                    name,
                    shape=(0, components),
                    maxshape=(None, components),
                    dtype=np.float64,
                    chunks=(1024, components),
                )
            ts.attrs["tensor_components"] = TENSOR_COMPONENTS[dim]
            sn = h5.create_group("snapshots")
            for name in SNAPSHOT_SCALARS:
                sn.create_dataset(name, shape=(0,), maxshape=(None,), dtype=np.float64, chunks=(64,))
            sn.create_dataset(
                "positions",
                shape=(0, n, dim),
                maxshape=(None, n, dim),
                dtype=WRITER_DTYPES["snapshots/positions"],
                chunks=(1, n, dim),
            )
            sn.create_dataset(
                "contact_offset",
                data=np.zeros(1, dtype=np.int64),
                maxshape=(None,),
                chunks=(64,),
            )
            sn.create_dataset(
                "contact_pairs",
                shape=(0, 2),
                maxshape=(None, 2),
                dtype=WRITER_DTYPES["snapshots/contact_pairs"],
                chunks=(1024, 2),
            )
            sn.create_dataset("contact_state", shape=(0,), maxshape=(None,), dtype=np.int8, chunks=(1024,))
            sn.create_dataset(
                "contact_stretch",
                shape=(0, dim),
                maxshape=(None, dim),
                dtype=WRITER_DTYPES["snapshots/contact_stretch"],
                chunks=(1024, dim),
            )
        self.h5 = h5py.File(tmp, "r+")
        self.write_checkpoint(state, {})
        self.h5.close()
        tmp.replace(self.path)  # the file appears only once it is a valid trajectory with a checkpoint
        try:
            self.h5 = h5py.File(self.path, "r+")
        except OSError as exc:  # another process, started at the same moment, opened it first
            if "unable to lock file" not in str(exc).lower():
                raise
            raise TrajectoryFileError(
                f"{self.path} was opened by another process meanwhile: is this state point already running?"
            ) from exc

    def open_existing(self) -> tuple[SimState, dict]:
        """Open for resuming; verify the file and return (state, runner counters) from the checkpoint.
        A file that cannot be read back is replaced by its last-checkpoint copy where one exists (the
        damaged file kept beside it as ``<name>.damaged``)."""
        try:
            return self._open_existing()
        except DamagedTrajectoryError as exc:
            copy = last_checkpoint_copy(self.path)
            if not copy.exists():
                raise
            with open(copy, "rb") as held:
                try:  # one restorer at a time
                    fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except OSError:
                    raise TrajectoryFileError(
                        f"{self.path} is being restored from {copy.name} by another process: is this state "
                        "point already running?"
                    ) from exc
                try:  # restored (and opened) meanwhile by another process?
                    return self._open_existing()
                except DamagedTrajectoryError:
                    pass
                damaged = _unused_name(self.path.with_name(self.path.name + ".damaged"))
                tmp = self.path.with_name(self.path.name + ".restoring")
                shutil.copyfile(copy, tmp)  # the copy itself stays until this invocation closes cleanly
                os.link(self.path, damaged)  # the file exists at every moment: damaged, then restored
                os.replace(tmp, self.path)
                log.warning(
                    "%s could not be read back (%s): resuming from its copy as of the last checkpoint "
                    "(%s); the damaged file is kept as %s (delete it once the run is through)",
                    self.path, exc, copy.name, damaged.name,
                )  # fmt: skip
                return self._open_existing()

    def _open_existing(self) -> tuple[SimState, dict]:
        try:
            h5 = h5py.File(self.path, "r+")
        except OSError as exc:
            message = str(exc).lower()
            # match HDF5's own phrases: "sblock->base_addr" in a truncation report also contains "lock"
            if "unable to lock file" in message:
                raise TrajectoryFileError(
                    f"{self.path} is open in another process (HDF5 file lock): is this state point "
                    "already running?"
                ) from exc
            if "truncated file" in message:
                raise DamagedTrajectoryError(
                    f"{self.path} is truncated ({exc}): it was not modified; move it aside (e.g. to "
                    f"{self.path.name}.corrupt) and rerun to simulate this state point afresh"
                ) from exc
            raise DamagedTrajectoryError(
                f"{self.path}: not a readable HDF5 file ({exc}); it was not modified; move it aside and rerun"
            ) from exc
        try:
            return self._resume_from(h5)
        except TrajectoryFileError:
            raise
        except (OSError, KeyError, RuntimeError, ValueError) as exc:  # metadata damaged past the superblock
            raise DamagedTrajectoryError(
                f"{self.path} cannot be read back ({exc}); move it aside and rerun"
            ) from exc

    def _resume_from(self, h5: h5py.File) -> tuple[SimState, dict]:
        """Check an opened file and set it up to continue from its checkpoint; closed on any failure."""
        try:
            if h5.attrs.get("producer") != PRODUCER:
                raise TrajectoryFileError(f"{self.path}: not a rheograph trajectory file; move it away")
            will_step = "checkpoint" in h5 and float(h5["checkpoint"].attrs["strain"]) < self.params.strain
            if will_step and h5["snapshots/positions"].compression is not None:
                h5.close()  # a finished file is extended: raw again before appending (see COMPRESSION)
                rewrite(self.path, compressed=False)
                h5 = h5py.File(self.path, "r+")
            if "checkpoint" not in h5 and "checkpoint_new" in h5:  # interrupted between delete and move
                h5.move("checkpoint_new", "checkpoint")
            if "checkpoint" not in h5:
                raise DamagedTrajectoryError(f"{self.path}: the checkpoint is missing; move the file away")
            version = int(h5.attrs.get("schema_version", -1))
            if version != SCHEMA_VERSION:
                raise TrajectoryFileError(
                    f"{self.path}: schema_version {version}, this rheograph writes {SCHEMA_VERSION}"
                )
            stored = json.loads(h5.attrs["params"])
            if not isinstance(stored, dict):
                raise DamagedTrajectoryError(f"{self.path}: its params are not a JSON object; move it away")
            mine = self.params.to_dict()
            differ = params_that_differ(stored, self.params)
            if differ:
                requested = {"dim": self.params.DIM, **mine}
                defaults = type(self.params).defaults()  # of a parameter the file was written without
                detail = ", ".join(
                    f"{k}: file {stored.get(k, 2 if k == 'dim' else defaults.get(k))!r} vs requested "
                    f"{requested[k]!r}"
                    for k in differ
                )
                raise TrajectoryFileError(f"{self.path} belongs to another state point ({detail})")
            cp = h5["checkpoint"]
            if "positions" not in cp:
                raise DamagedTrajectoryError(f"{self.path}: checkpoint is incomplete; move the file away")
            state = _state_from_checkpoint(cp)
            counters = json.loads(cp.attrs["counters"])
            # drop rows written after the checkpoint: they will be recomputed identically
            for name in timeseries_scalars(file_dim(h5)) + TIMESERIES_TENSORS:
                h5["timeseries"][name].resize(counters["rows"], axis=0)
            sn = h5["snapshots"]
            for name in (*SNAPSHOT_SCALARS, "positions"):
                sn[name].resize(counters["snapshots"], axis=0)
            sn["contact_offset"].resize(counters["snapshots"] + 1, axis=0)
            n_contacts = int(sn["contact_offset"][-1])
            for name in ("contact_pairs", "contact_state", "contact_stretch"):
                sn[name].resize(n_contacts, axis=0)
            h5.attrs["status"] = "running"
            # resumable parameters (strain, wall limits) may have changed; stored as a new file stores them
            stored = self.params.stored_dict()
            h5.attrs["params"] = json.dumps(stored)
            for key, value in stored.items():
                h5.attrs[f"param_{key}"] = value
            self.h5 = h5
            return state, counters
        except BaseException:
            with contextlib.suppress(Exception):
                h5.close()
            raise

    # ---- writing ------------------------------------------------------------------------------
    def append_row(self, row: dict) -> None:
        ts = self.h5["timeseries"]
        for name in timeseries_scalars(self.params.DIM):
            _append(ts[name], [row[name]])
        for name in TIMESERIES_TENSORS:
            _append(ts[name], [row[name]])

    def append_snapshot(self, snap: dict) -> None:
        sn = self.h5["snapshots"]
        for name in SNAPSHOT_SCALARS:
            _append(sn[name], [snap[name]])
        _append(sn["positions"], snap["positions"][None])
        _append(sn["contact_pairs"], snap["contact_pairs"])
        _append(sn["contact_state"], snap["contact_state"])
        _append(sn["contact_stretch"], snap["contact_stretch"])
        _append(sn["contact_offset"], [sn["contact_pairs"].shape[0]])

    def write_checkpoint(self, state: SimState | SimState3D, counters: dict) -> None:
        counters = {
            "rows": self.h5["timeseries"]["time"].shape[0],
            "snapshots": self.h5["snapshots"]["time"].shape[0],
            **{k: v for k, v in counters.items() if k not in ("rows", "snapshots")},
        }
        # write a complete new group, then swap it in: an interruption leaves the old or the new
        # checkpoint, never a mixture
        if "checkpoint_new" in self.h5:
            del self.h5["checkpoint_new"]
        cp = self.h5.create_group("checkpoint_new")
        for name in state.ARRAYS:
            cp.create_dataset(name, data=getattr(state, name))
        for name in state.SCALARS:
            cp.attrs[name] = getattr(state, name)
        cp.attrs["counters"] = json.dumps(counters)
        self.h5.flush()
        if "checkpoint" in self.h5:
            del self.h5["checkpoint"]
        self.h5.move("checkpoint_new", "checkpoint")
        self.h5.flush()
        self._copy_as_last_checkpoint()

    def _copy_as_last_checkpoint(self) -> None:
        """Copy the file, consistent on disk right after a flush, to ``last_checkpoint_copy`` (through a
        temporary file: an interrupted copy leaves the previous one).  The copy needs as much free space
        as the file, so on a filling disk it fails first, while the file itself is still whole: the run
        then stops at this checkpoint instead of writing on into a full disk."""
        copy = last_checkpoint_copy(self.path)
        tmp = copy.with_name(copy.name + ".tmp")
        try:
            shutil.copyfile(self.h5.filename, tmp)
            os.replace(tmp, copy)
        except OSError:
            tmp.unlink(missing_ok=True)
            raise

    def record_solver(self, name: str) -> None:
        """The linear solver of the latest invocation (``rheograph.sim.solver``)."""
        self.h5.attrs["solver"] = name

    def finish(self, status: str, summary: dict) -> None:
        self.h5.attrs["status"] = status
        grp = self.h5.require_group("summary")
        for key, value in summary.items():
            grp.attrs[key] = value
        self.h5.flush()

    def close(self) -> None:
        """Close; a clean close leaves a consistent file, so its last-checkpoint copy goes.  If HDF5 cannot
        write the file's last metadata (disk full), the copy stays for the resume."""
        if self.h5 is not None:
            h5, self.h5 = self.h5, None
            h5.close()
            last_checkpoint_copy(self.path).unlink(missing_ok=True)


def read_timeseries(path: str | Path) -> dict:
    with h5py.File(path, "r") as h5:
        return {name: h5["timeseries"][name][()] for name in h5["timeseries"]}


def read_snapshot_table(path: str | Path, keys) -> dict:
    """The per-snapshot columns ``keys`` of a trajectory's ``/snapshots`` (strain, eta_r, pressure, ...),
    each (S,), read only."""
    with h5py.File(path, "r") as h5:
        return {key: h5["snapshots"][key][()] for key in keys}


def is_trajectory(path: str | Path) -> bool:
    """Whether ``path`` is a rheograph trajectory file (HDF5 written by this package); False for anything
    else, or a file that cannot be opened."""
    try:
        with h5py.File(path, "r") as h5:
            return h5.attrs.get("producer") == PRODUCER
    except OSError:
        return False


def file_is_compact(path: str | Path) -> bool:
    """Whether the trajectory file at ``path`` has the at-rest layout (``is_compact``)."""
    with h5py.File(path, "r") as h5:
        return is_compact(h5)


def params_that_differ(stored: dict, params: SimParams) -> list[str]:
    """Names of the parameters of ``params`` that differ from those ``stored`` in a trajectory file, other
    than RESUMABLE_PARAMS: a file of another state point.  A parameter added after the file was written
    had its default value there; ``dim`` is compared too (a 2D file stores none: 2)."""
    defaults, mine = type(params).defaults(), params.to_dict()
    differ = {k for k in mine if k not in RESUMABLE_PARAMS and stored.get(k, defaults[k]) != mine[k]}
    if stored.get("dim", 2) != params.DIM:
        differ.add("dim")
    return sorted(differ)


def read_params(path: str | Path) -> dict:
    """The simulation parameters (``SimParams.to_dict``) a trajectory file was written with."""
    with h5py.File(path, "r") as h5:
        return json.loads(h5.attrs["params"])


def read_checkpoint(path: str | Path) -> tuple[SimParams, SimState | SimState3D]:
    """The parameters and the exact state at the checkpoint of a trajectory file, read only (the file is
    left as it is: for analyses that continue a run without extending it); 3D states for 3D files."""
    with h5py.File(path, "r") as h5:
        if "checkpoint" not in h5 or "positions" not in h5["checkpoint"]:
            raise TrajectoryFileError(f"{path}: no checkpoint")
        return params_from_mapping(json.loads(h5.attrs["params"])), _state_from_checkpoint(h5["checkpoint"])


def _state_from_checkpoint(cp: h5py.Group) -> SimState | SimState3D:
    """The state saved in a checkpoint group; a 3D one in a 3D file."""
    cls = SimState3D if file_dim(cp.file) == 3 else SimState
    state = cls(
        **{name: cp[name][()] for name in cls.ARRAYS},
        **{name: cp.attrs[name] for name in cls.SCALARS if name in cp.attrs},
    )
    state.steps = int(state.steps)
    return state


def read_run_info(path: str | Path) -> dict:
    """Status, parameters, summary, progress (strain and steps at the checkpoint) and space dimension of a
    trajectory file, read only."""
    with h5py.File(path, "r") as h5:
        return {
            "dim": file_dim(h5),
            "status": str(h5.attrs["status"]),
            "params": json.loads(h5.attrs["params"]),
            "summary": dict(h5["summary"].attrs) if "summary" in h5 else {},
            "strain": float(h5["checkpoint"].attrs["strain"]),
            "steps": int(h5["checkpoint"].attrs["steps"]),
            "solver": h5.attrs.get("solver"),  # None in files written before the backend was recorded
        }


def is_compact(h5: h5py.File) -> bool:
    """Whether a file has the at-rest layout (AT_REST); raw running files and files compacted before
    AT_REST existed (gzip only) have not."""
    return h5["snapshots/positions"].scaleoffset is not None


def rewrite(path: str | Path, compressed: bool = True, keep_snapshots=None, edit=None) -> tuple[int, int]:
    """Rewrite a trajectory file not being written: compact at rest (``compressed=True``: COMPRESSION on
    every chunked dataset, AT_REST storage for positions, stretches and pairs) or raw with the writer's
    dtypes (``compressed=False``, before a finished run is extended).  Attributes, chunking and the exact
    checkpoint are kept; ``keep_snapshots`` (indices, strictly ascending, below the checkpoint's snapshot
    count) keeps only those snapshots, with their contact lists, and sets that count to theirs;
    ``edit(h5)`` changes the new file before the swap.  Written to a temporary file, flushed to disk and
    swapped in atomically; an interruption leaves the original file and no temporary one.  Returns
    (bytes before, bytes after)."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    with h5py.File(path, "r") as src:
        if src.attrs.get("producer") != PRODUCER:
            raise TrajectoryFileError(f"{path}: not a rheograph trajectory")
        selected = {}
        if keep_snapshots is not None:
            keep = np.asarray(keep_snapshots, dtype=np.int64)
            offset = src["snapshots/contact_offset"][()]
            n_written = offset.size - 1
            if "checkpoint" in src:
                n_written = min(n_written, json.loads(src["checkpoint"].attrs["counters"])["snapshots"])
            if keep.size and (np.any(np.diff(keep) <= 0) or keep[0] < 0 or keep[-1] >= n_written):
                raise InputError(
                    f"keep_snapshots={keep.tolist()} is invalid for {path}: allowed strictly ascending "
                    f"indices in [0, {n_written})"
                )
            rows = np.concatenate([np.arange(offset[k], offset[k + 1]) for k in keep] or [np.zeros(0, int)])
            selected = {f"snapshots/{name}": keep for name in (*SNAPSHOT_SCALARS, "positions")}
            selected.update(
                {f"snapshots/{n}": rows for n in ("contact_pairs", "contact_state", "contact_stretch")}
            )
            counts = offset[keep + 1] - offset[keep]
            new_offset = np.concatenate([[0], np.cumsum(counts)]).astype(offset.dtype)

        def copy(name, obj):
            if isinstance(obj, h5py.Group):
                dst.require_group(name).attrs.update(dict(obj.attrs))
                return
            options = {"dtype": obj.dtype}
            if name in AT_REST:
                options["dtype"] = WRITER_DTYPES[name]
            if obj.chunks and compressed:
                options.update(COMPRESSION, **AT_REST.get(name, {}))
            if name == "snapshots/contact_offset" and keep_snapshots is not None:
                data = new_offset
            else:
                data = obj[()][selected[name]] if name in selected else obj[()]
            out = dst.create_dataset(name, data=data, maxshape=obj.maxshape, chunks=obj.chunks, **options)
            out.attrs.update(dict(obj.attrs))

        try:
            with h5py.File(tmp, "w") as dst:
                dst.attrs.update(dict(src.attrs))
                src.visititems(copy)
                if keep_snapshots is not None and "checkpoint" in dst:
                    counters = json.loads(dst["checkpoint"].attrs["counters"])
                    counters["snapshots"] = int(keep.size)
                    dst["checkpoint"].attrs["counters"] = json.dumps(counters)
                if edit is not None:
                    edit(dst)
            with open(tmp, "rb+") as handle:  # on disk before the swap: a crash keeps one whole file
                os.fsync(handle.fileno())
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            if not hdf5_write_found_no_room(exc):
                raise
            raise InputError(
                f"rewriting {path} failed ({exc}): is the disk full or a quota reached? {path} is "
                "unchanged; free space and rerun"
            ) from exc
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
    before, after = path.stat().st_size, tmp.stat().st_size
    tmp.replace(path)
    return before, after


def respace_snapshots(path: str | Path, interval: float, dry_run: bool = False) -> tuple[int, int]:
    """Thin the snapshots of a run that no simulation is writing to every ``interval`` of strain, so that
    it can be extended at that spacing (``sim.snapshot_interval=interval``, a larger ``sim.strain``) as
    if it had been run at it from the start: ``interval`` must be a whole multiple of the file's
    ``snapshot_interval``; kept is the first snapshot in each ``interval`` of strain — the one a run at
    that spacing takes, since the finer grid passes through every multiple of ``interval``.  The file's
    parameters and checkpoint (snapshot count, next snapshot strain) are updated; the dynamics, time
    series and checkpoint state are untouched.  Snapshots written after the checkpoint are dropped (a
    resume would drop them too).  ``dry_run``: check and count only, change nothing.  Returns (snapshots
    before, kept)."""
    path = Path(path)
    try:
        h5 = h5py.File(path, "r")
    except OSError as exc:  # being written (HDF5 file lock), or not HDF5 at all
        raise TrajectoryFileError(f"{path}: cannot be respaced ({exc}); is a simulation writing it?") from exc
    with h5:
        if h5.attrs.get("producer") != PRODUCER:
            raise TrajectoryFileError(f"{path}: not a rheograph trajectory")
        if "checkpoint" not in h5:
            raise TrajectoryFileError(f"{path}: no checkpoint (resume the run once, then respace it)")
        status = str(h5.attrs["status"])
        params = json.loads(h5.attrs["params"])
        counters = json.loads(h5["checkpoint"].attrs["counters"])
        strain = h5["snapshots/strain"][: counters["snapshots"]]
        compact = is_compact(h5)
    current = float(params["snapshot_interval"])
    ratio = interval / current if interval > 0 else 0.0
    if not (np.isfinite(ratio) and ratio >= 1.0 and abs(ratio - round(ratio)) < 1e-9):
        raise InputError(
            f"interval={interval!r} is invalid for {path}: allowed a whole multiple (>= 1) of its "
            f"snapshot_interval {current:g}"
        )
    if status in ("running", "jammed"):
        raise InputError(
            f"{path} is {status}: respacing is for finished or interrupted flowing runs that will be "
            "extended (a jammed run's arrest snapshot lies off any grid)"
        )
    cell = np.floor(strain / interval + 1e-9)
    keep = np.flatnonzero(np.concatenate([[True], cell[1:] > cell[:-1]])) if strain.size else strain

    if dry_run:
        return int(strain.size), int(len(keep))

    def new_spacing(h5):  # in the rewritten file, before it is swapped in: never half respaced
        params["snapshot_interval"] = float(interval)
        h5.attrs["params"] = json.dumps(params)
        h5.attrs["param_snapshot_interval"] = float(interval)
        new_counters = json.loads(h5["checkpoint"].attrs["counters"])  # snapshot count set by rewrite
        if len(keep):
            new_counters["next_snapshot"] = (np.floor(strain[keep[-1]] / interval + 1e-9) + 1) * interval
        h5["checkpoint"].attrs["counters"] = json.dumps(new_counters)

    rewrite(path, compressed=compact, keep_snapshots=keep, edit=new_spacing)
    return int(strain.size), int(len(keep))


def jammed_snapshots(status: str, snapshot_strain, series_strain, jam_intervals: int) -> np.ndarray:
    """(S,) bool: the snapshots of a run taken after its flow stopped.

    A run ends ``jammed`` when over its last ``jam_intervals`` output intervals -- between its last
    ``jam_intervals`` + 1 rows -- the flow was together slower than the jam viscosity (rheograph.runs.runner);
    the snapshots from the first row of that window on show the arrested packing (its Π and Z_μ are
    targets, its η_r is not), the earlier ones a flowing suspension.  All False for a run that did not
    jam."""
    snapshot_strain = np.asarray(snapshot_strain, dtype=np.float64)
    series_strain = np.asarray(series_strain, dtype=np.float64)
    if status != "jammed" or series_strain.size == 0:
        return np.zeros(snapshot_strain.size, dtype=bool)
    onset = series_strain[max(series_strain.size - 1 - int(jam_intervals), 0)]
    return snapshot_strain >= onset
