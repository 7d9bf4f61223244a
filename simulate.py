"""Simulate one state point (or a grid with -m).  See README.md and conf/simulate.yaml."""

import os
import sys

# one thread per simulation (state points run in parallel, not the linear algebra inside one): CHOLMOD's
# OpenMP only honours OMP_THREAD_LIMIT, read when libgomp loads, i.e. before the imports below
os.environ.setdefault("OMP_THREAD_LIMIT", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import hydra  # noqa: E402
from omegaconf import DictConfig  # noqa: E402

from rheograph.cli import register_resolvers, simulate_main  # noqa: E402
from rheograph.io.hdf5 import TrajectoryFileError  # noqa: E402
from rheograph.sim.params import ParameterError  # noqa: E402

register_resolvers()


@hydra.main(version_base="1.3", config_path="conf", config_name="simulate")
def main(cfg: DictConfig) -> None:
    try:
        simulate_main(cfg)
    except (ParameterError, TrajectoryFileError) as err:  # the user's input: one line, no traceback
        sys.exit(f"simulate.py: {err}")


if __name__ == "__main__":
    main()
