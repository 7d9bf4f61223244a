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
from pathlib import Path

import h5py

from rheograph.io.hdf5 import PRODUCER, read_run_info

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


def index_files(path: str | Path) -> list[str]:
    """Usable trajectory files listed in an index written by :func:`build_index`."""
    index = json.loads(Path(path).read_text())
    if index.get("format") != "rheograph-index-1":
        raise ValueError(f"{path}: not a rheograph index")
    return [e["path"] for e in index["runs"] if e["status"] in USABLE]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("directories", nargs="+")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    index = build_index(args.directories)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(index, indent=1))
    usable = sum(e["status"] in USABLE for e in index["runs"])
    print(f"{len(index['runs'])} runs ({usable} usable), {len(index['skipped'])} skipped -> {args.out}")
    for s in index["skipped"]:
        print(f"  skipped {s['path']}: {s['reason']}")


if __name__ == "__main__":
    main()
