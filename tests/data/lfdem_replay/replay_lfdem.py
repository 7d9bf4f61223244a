#!/usr/bin/env python3
"""A stand-in for the LF_DEM binary in tests: called as LF_DEM is (``-s <sigma>cl conf.dat params.txt``),
it replays the committed output of real LF_DEM runs (commit 00fa7cc0) from ``conf.dat`` of this folder,
N = 100, phi = 0.76, sigma/sigma0 = 10, disp_max 2e-3, to the strains 0.01, 0.02, 0.04 (the folders
``end<strain>``): it copies that run's data_*.dat and t_*.dat into the working directory.  A
configuration other than the committed one, or another end strain, is refused as LF_DEM would not have
produced these files for it."""

import re
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv):
    if len(argv) != 4 or argv[0] != "-s" or argv[1] != "10cl":
        sys.exit(f"replay_lfdem: replays a run at -s 10cl only, called with {argv}")
    conf, params = Path(argv[2]), Path(argv[3])
    if conf.read_bytes() != (HERE / "conf.dat").read_bytes():
        sys.exit("replay_lfdem: not the configuration the replayed runs started from")
    end = re.search(r"time_end = ([0-9.eE+-]+)h;", params.read_text())
    source = HERE / f"end{float(end.group(1)):g}" if end else None
    if source is None or not source.is_dir():
        sys.exit(f"replay_lfdem: no replayed run to time_end {end.group(1) if end else '?'}")
    for path in source.iterdir():
        shutil.copy(path, Path.cwd() / path.name)


if __name__ == "__main__":
    main(sys.argv[1:])
