"""Simulate one state point (or a grid with -m).  See README.md and conf/simulate.yaml."""

import os

# one thread per simulation (state points run in parallel, not the linear algebra inside one): CHOLMOD's
# OpenMP only honours OMP_THREAD_LIMIT, read when libgomp loads, i.e. before the imports below
os.environ.setdefault("OMP_THREAD_LIMIT", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import hydra  # noqa: E402
from omegaconf import DictConfig  # noqa: E402

from rheograph.cli.hydra_apps import register_resolvers, simulate_main  # noqa: E402
from rheograph.errors import one_line_errors, run_hydra_app  # noqa: E402

register_resolvers()


@hydra.main(version_base="1.3", config_path="conf", config_name="simulate")
def main(cfg: DictConfig) -> None:
    with one_line_errors("simulate.py"):
        simulate_main(cfg)


if __name__ == "__main__":
    run_hydra_app(main, "simulate.py")
