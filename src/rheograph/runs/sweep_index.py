"""Index the trajectory files of a sweep (one file per job) for training and bookkeeping.

    python -m rheograph.runs.sweep_index outputs/simulate/multirun --out data/index.json

The index (``rheograph.io.index``) lists every rheograph trajectory under the given directories with its
parameters, status, strain and snapshot count; ``data.files=data/index.json`` trains on the listed files
whose status is completed (or jammed, whose snapshots are valid configurations).  Foreign or unreadable
.h5 files are reported and skipped.  A 3D run's entry says so in its parameters (``dim`` 3; 2D runs carry
no ``dim``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rheograph.errors import InputError, one_line_errors
from rheograph.io.hdf5 import file_is_compact, rewrite
from rheograph.io.index import USABLE, build_index, write_index


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("directories", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument(
        "--compress",
        action="store_true",
        help="rewrite every trajectory that no simulation is writing into the compact at-rest layout "
        "(rheograph.io.hdf5.AT_REST): finished runs, and interrupted ones before they are committed "
        "(~4x smaller; a resume writes them raw again first)",
    )
    args = ap.parse_args(argv)
    missing = [d for d in args.directories if not Path(d).is_dir()]
    if missing:
        raise InputError(f"directory {missing[0]} does not exist")
    index = build_index(args.directories)
    if args.compress:
        saved = 0
        for entry in index["runs"]:
            try:
                if file_is_compact(entry["path"]):
                    continue
                before, after = rewrite(entry["path"], compressed=True)
            except OSError as exc:  # being written by a running simulation (HDF5 file lock)
                print(f"  not compacted {entry['path']}: {exc}")
                continue
            saved += before - after
        print(f"compacted: {saved / 1e6:.1f} MB saved")
    write_index(index, args.out)
    usable = sum(e["status"] in USABLE for e in index["runs"])
    three_d = sum(e["params"].get("dim", 2) == 3 for e in index["runs"])
    of_them = f", {three_d} of them 3D" if three_d else ""
    print(
        f"{len(index['runs'])} runs ({usable} usable{of_them}), {len(index['skipped'])} skipped -> {args.out}"
    )
    for s in index["skipped"]:
        print(f"  skipped {s['path']}: {s['reason']}")


if __name__ == "__main__":
    with one_line_errors("python -m rheograph.runs.sweep_index"):
        main()
