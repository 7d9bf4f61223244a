"""Thin the snapshots of finished runs to a coarser spacing, so that they can be extended at it.

    python -m rheograph.runs.respace 'data/paper/multirun/N2000_phi0.7_*/trajectory.h5' --interval 0.2
    python simulate.py ... sim.snapshot_interval=0.2 sim.strain=5      # then extend them

A run is deterministic and its snapshots do not act on the dynamics, so a run respaced to a whole
multiple of its spacing and extended holds the snapshots, time series and checkpoint of a run made at
that spacing from the start (``rheograph.io.hdf5.respace_snapshots``): measured decorrelation strains
longer than the first spacing are fixed without simulating the first strains again.  The dropped
snapshots are gone from the file (commit or copy it first if you need them).
"""

from __future__ import annotations

import argparse
import glob

from rheograph.errors import InputError, one_line_errors
from rheograph.io.hdf5 import respace_snapshots


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="+", help="trajectory files or glob patterns")
    ap.add_argument("--interval", type=float, required=True, help="new snapshot spacing in strain")
    args = ap.parse_args(argv)
    unmatched = [pattern for pattern in args.files if not glob.glob(pattern)]
    if unmatched:
        raise InputError(f"files: {unmatched} match no trajectory file")
    files = sorted({f for pattern in args.files for f in glob.glob(pattern)})
    for path in files:  # every file checked before any is rewritten: a batch is respaced whole or not at all
        respace_snapshots(path, args.interval, dry_run=True)
    for path in files:
        before, kept = respace_snapshots(path, args.interval)
        print(f"{path}: kept {kept} of {before} snapshots (every {args.interval:g} strain)")


if __name__ == "__main__":
    with one_line_errors("python -m rheograph.runs.respace"):
        main()
