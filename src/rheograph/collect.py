"""Index the trajectory files of a sweep (one file per job) for training and bookkeeping.

    python -m rheograph.collect outputs/simulate/multirun --out data/index.json

The index lists every rheograph trajectory under the given directories with its parameters, status,
strain and snapshot count; ``data.files=data/index.json`` trains on the listed files whose status is
completed (or jammed, whose snapshots are valid configurations).  Foreign or unreadable .h5 files are
reported and skipped.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import h5py

from rheograph.errors import InputError, one_line_errors
from rheograph.io.hdf5 import PRODUCER, is_compact, read_run_info, rewrite

USABLE = ("completed", "jammed")


def build_index(directories) -> dict:
    entries, skipped = [], []
    for directory in directories:
        for path in sorted(Path(directory).rglob("*.h5")):
            try:
                with h5py.File(path, "r") as h5:
                    if h5.attrs.get("producer") != PRODUCER:
                        raise ValueError("not a rheograph trajectory")
                    n_snapshots = int(h5["snapshots/time"].shape[0])
                info = read_run_info(path)
            except (OSError, ValueError, KeyError) as exc:
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
    try:
        index = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not a readable rheograph index ({exc})") from exc
    if not isinstance(index, dict) or index.get("format") != "rheograph-index-1":
        raise InputError(f"{path}: not a rheograph index")
    for entry in index["runs"]:
        entry["path"] = str((path.parent / entry["path"]).resolve())
    return index


def index_files(path: str | Path) -> list[str]:
    """Usable trajectory files listed in an index written by :func:`write_index`."""
    return [e["path"] for e in read_index(path)["runs"] if e["status"] in USABLE]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("directories", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument(
        "--compress",
        action="store_true",
        help="rewrite finished runs into the compact at-rest layout (rheograph.io.hdf5.AT_REST) that "
        "files finished by older versions lack",
    )
    args = ap.parse_args(argv)
    missing = [d for d in args.directories if not Path(d).is_dir()]
    if missing:
        raise InputError(f"directory {missing[0]} does not exist")
    index = build_index(args.directories)
    if args.compress:
        saved = 0
        for entry in index["runs"]:
            if entry["status"] in USABLE:
                try:
                    with h5py.File(entry["path"], "r") as h5:
                        if is_compact(h5):
                            continue
                    before, after = rewrite(entry["path"], compressed=True)
                except OSError as exc:  # being written by a running simulation (HDF5 file lock)
                    print(f"  not compacted {entry['path']}: {exc}")
                    continue
                saved += before - after
        print(f"compacted: {saved / 1e6:.1f} MB saved")
    write_index(index, args.out)
    usable = sum(e["status"] in USABLE for e in index["runs"])
    print(f"{len(index['runs'])} runs ({usable} usable), {len(index['skipped'])} skipped -> {args.out}")
    for s in index["skipped"]:
        print(f"  skipped {s['path']}: {s['reason']}")


if __name__ == "__main__":
    with one_line_errors("python -m rheograph.collect"):
        main()
