"""The index of a sweep's trajectory files (one per job): what ``python -m rheograph.runs.sweep_index``
writes and training (``data.files=<dir>/index.json``) and the dataset card read.

An index lists every rheograph trajectory under some directories with its parameters, status, strain and
snapshot count, paths relative to the index file; training reads the listed files whose status is in
``USABLE`` (completed, or jammed: its snapshots are valid configurations).  Foreign or unreadable .h5
files are listed as skipped, with the reason.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py

from rheograph.errors import InputError
from rheograph.io.configurations import DAMAGED_FILE_ERRORS
from rheograph.io.hdf5 import PRODUCER, read_run_info
from rheograph.io.json_files import read_json

USABLE = ("completed", "jammed")


def build_index(directories) -> dict:
    """Index of every rheograph trajectory (``*.h5``) under ``directories``; absolute paths (relative ones
    are written by :func:`write_index`)."""
    entries, skipped = [], []
    for directory in directories:
        for path in sorted(Path(directory).rglob("*.h5")):
            try:
                with h5py.File(path, "r") as h5:
                    if h5.attrs.get("producer") != PRODUCER:
                        raise ValueError("not a rheograph trajectory")
                    n_snapshots = int(h5["snapshots/time"].shape[0])
                info = read_run_info(path)
            except DAMAGED_FILE_ERRORS as exc:  # foreign, locked by a running simulation, or damaged
                skipped.append({"path": str(path), "reason": str(exc)})
                continue
            entries.append(
                {
                    "path": str(path.resolve()),
                    "status": info["status"],
                    "strain": info["strain"],
                    "snapshots": n_snapshots,
                    "params": info["params"],
                    "summary": {k: float(v) for k, v in info["summary"].items()},
                }
            )
    return {"format": "rheograph-index-1", "runs": entries, "skipped": skipped}


def write_index(index: dict, path: str | Path) -> None:
    """Write ``index`` with paths relative to the index file, so that a committed index stays valid in
    any clone."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    base = path.parent.resolve()
    relative = {
        **index,
        "runs": [{**e, "path": os.path.relpath(e["path"], base)} for e in index["runs"]],
        "skipped": [{**e, "path": os.path.relpath(e["path"], base)} for e in index["skipped"]],
    }
    path.write_text(json.dumps(relative, indent=1))


def read_index(path: str | Path) -> dict:
    """An index written by :func:`write_index`, its paths resolved against the index's directory."""
    path = Path(path)
    index = read_json(path, "rheograph index")
    if not isinstance(index, dict) or index.get("format") != "rheograph-index-1":
        raise InputError(f"{path}: not a rheograph index")
    for entry in index["runs"]:
        entry["path"] = str((path.parent / entry["path"]).resolve())
    return index


def index_files(path: str | Path) -> list[str]:
    """Usable trajectory files listed in an index written by :func:`write_index`."""
    return [e["path"] for e in read_index(path)["runs"] if e["status"] in USABLE]
