"""Simulate one state point (or a grid with -m).  See README.md and conf/simulate.yaml."""

import hydra
from omegaconf import DictConfig

from rheograph.cli import register_resolvers, simulate_main

register_resolvers()


@hydra.main(version_base="1.3", config_path="conf", config_name="simulate")
def main(cfg: DictConfig) -> None:
    simulate_main(cfg)


if __name__ == "__main__":
    main()
